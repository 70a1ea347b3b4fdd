"""The strain field e and the pressure field p = E e on a tetrahedral mesh."""

from .._defaults import DEFAULT_MODULUS as DEFAULT_MODULUS  # documented in hydrotact/_defaults.py
from ._assembly import (
    StiffnessPattern as StiffnessPattern,
    apply_stiffness as apply_stiffness,
    calc_stiffness_values as calc_stiffness_values,
    calc_tet_gradients as calc_tet_gradients,
    make_stiffness_pattern as make_stiffness_pattern,
)
from ._distance import calc_distance_field as calc_distance_field
from ._kinds import StrainFieldKind as StrainFieldKind
from ._pressure import PressureField as PressureField, make_pressure_field as make_pressure_field
from ._report import PLAUSIBLE_MODULUS_PA as PLAUSIBLE_MODULUS_PA, check_modulus as check_modulus, solve_field_report as solve_field_report
from ._solve import (
    LaplaceProblem as LaplaceProblem,
    StrainSolution as StrainSolution,
    make_laplace_problem as make_laplace_problem,
    solve_strain as solve_strain,
)
