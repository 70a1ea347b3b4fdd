"""Tetrahedral meshes of elastomers: the TetMesh pytree, builders, quality, I/O."""

from ._io import MESH_SUFFIXES as MESH_SUFFIXES
from ._io import read_mesh as read_mesh
from ._io import to_pyvista as to_pyvista
from ._io import write_mesh as write_mesh
from ._load import load_tet_mesh as load_tet_mesh
from ._primitives import (
    make_ball as make_ball,
)
from ._primitives import (
    make_box as make_box,
)
from ._primitives import (
    make_spherical_shell as make_spherical_shell,
)
from ._primitives import (
    make_truncated_ellipsoid_surface as make_truncated_ellipsoid_surface,
)
from ._quality import (
    calc_dihedral_angles as calc_dihedral_angles,
)
from ._quality import (
    calc_mesh_quality as calc_mesh_quality,
)
from ._quality import (
    calc_radius_ratios as calc_radius_ratios,
)
from ._seeds import SEED_SENSORS as SEED_SENSORS
from ._seeds import make_seed_mesh as make_seed_mesh
from ._seeds import seed_surface as seed_surface
from ._surface import (
    SURFACE_SUFFIXES as SURFACE_SUFFIXES,
)
from ._surface import (
    check_surface as check_surface,
)
from ._surface import (
    find_self_intersections as find_self_intersections,
)
from ._surface import (
    load_surface as load_surface,
)
from ._tags import Plane as Plane
from ._tags import make_face_tagger as make_face_tagger
from ._tetmesh import (
    CORE as CORE,
)
from ._tetmesh import (
    FREE as FREE,
)
from ._tetmesh import (
    INSULATED as INSULATED,
)
from ._tetmesh import (
    TAG_NAMES as TAG_NAMES,
)
from ._tetmesh import (
    TetMesh as TetMesh,
)
from ._tetmesh import (
    calc_signed_volumes as calc_signed_volumes,
)
from ._tetmesh import (
    extract_boundary_faces as extract_boundary_faces,
)
from ._tetmesh import (
    make_tet_mesh as make_tet_mesh,
)
from ._tetmesh import (
    orient_tets as orient_tets,
)
from ._tetrahedralize import tetrahedralize as tetrahedralize
