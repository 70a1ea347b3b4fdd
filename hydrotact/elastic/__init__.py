"""Linear elasticity of the elastomer and what barometers cast in it read.

Quadratic tets with one pressure per tet (the mixed P2-P0 element: no locking for
nearly incompressible silicone), the faces bonded to the board fixed, solved by
preconditioned CG (lineax) with the implicit adjoint; each barometer's receptive field
by reciprocity (one adjoint solve per barometer), against which contact tractions are
integrated exactly.
"""

from ._barometers import (
    DEFAULT_PORT_RADIUS as DEFAULT_PORT_RADIUS,
    BarometerPorts as BarometerPorts,
    ElasticReading as ElasticReading,
    FieldDerivatives as FieldDerivatives,
    ReceptiveFields as ReceptiveFields,
    calc_elastic_readings as calc_elastic_readings,
    calc_field_derivatives as calc_field_derivatives,
    calc_polygon_node_integrals as calc_polygon_node_integrals,
    calc_port_readings as calc_port_readings,
    calc_port_weights as calc_port_weights,
    calc_receptive_fields as calc_receptive_fields,
    calc_surface_loads as calc_surface_loads,
    make_barometer_ports as make_barometer_ports,
)
from ._cache import make_field_derivatives as make_field_derivatives, make_receptive_fields as make_receptive_fields
from ._cavity import (
    AIR_MODULUS as AIR_MODULUS,
    CavityFields as CavityFields,
    calc_air_factor as calc_air_factor,
    calc_cavity_fields as calc_cavity_fields,
    calc_cavity_loads as calc_cavity_loads,
    calc_cavity_volume as calc_cavity_volume,
    find_cavity_faces as find_cavity_faces,
)
from ._loads import (
    FaceQuadrature as FaceQuadrature,
    calc_barycentric as calc_barycentric,
    calc_body_loads as calc_body_loads,
    calc_face_loads as calc_face_loads,
    calc_point_loads as calc_point_loads,
    find_face_tets as find_face_tets,
    make_face_quadrature as make_face_quadrature,
)
from ._multigrid import (
    MultigridPreconditioner as MultigridPreconditioner,
    make_multigrid_preconditioner as make_multigrid_preconditioner,
)
from ._problem import (
    ElasticProblem as ElasticProblem,
    ElasticSolution as ElasticSolution,
    calc_lame as calc_lame,
    calc_stiffness_blocks as calc_stiffness_blocks,
    calc_stress as calc_stress,
    check_poisson_ratio as check_poisson_ratio,
    make_elastic_problem as make_elastic_problem,
    solve_elasticity as solve_elasticity,
)
from ._quadratic import (
    BlockPattern as BlockPattern,
    calc_shape_functions as calc_shape_functions,
    calc_shape_gradients as calc_shape_gradients,
    make_quadratic_nodes as make_quadratic_nodes,
)
