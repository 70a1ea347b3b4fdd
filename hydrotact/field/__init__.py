"""The strain field e and the pressure field p = E e on a tetrahedral mesh."""

from .._defaults import DEFAULT_MODULUS as DEFAULT_MODULUS  # documented in hydrotact/_defaults.py
from ._assembly import (
    StiffnessPattern as StiffnessPattern,
)
from ._assembly import (
    apply_stiffness as apply_stiffness,
)
from ._assembly import (
    calc_stiffness_values as calc_stiffness_values,
)
from ._assembly import (
    calc_tet_gradients as calc_tet_gradients,
)
from ._assembly import (
    make_stiffness_pattern as make_stiffness_pattern,
)
from ._distance import calc_distance_field as calc_distance_field
from ._kinds import StrainFieldKind as StrainFieldKind
from ._pressure import PressureField as PressureField
from ._pressure import make_pressure_field as make_pressure_field
from ._report import PLAUSIBLE_MODULUS_PA as PLAUSIBLE_MODULUS_PA
from ._report import check_modulus as check_modulus
from ._report import solve_field_report as solve_field_report
from ._solve import (
    LaplaceProblem as LaplaceProblem,
)
from ._solve import (
    StrainSolution as StrainSolution,
)
from ._solve import (
    make_laplace_problem as make_laplace_problem,
)
from ._solve import (
    solve_strain as solve_strain,
)
