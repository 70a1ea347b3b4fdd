"""What the two ways of fitting share, in one public place: the simulator fit
(:mod:`hydrotact.sysid`) and the lumped press model (:mod:`hydrotact.sysid.lumped`)
read logs, choose and run solvers, judge what the logs identify, warn on a poor χ²
and write their outputs the same way. The lumped package imports these from here and
nothing private from its parent."""

from ._comparison import (
    HOLD_TOLERANCE as HOLD_TOLERANCE,
    HOMES as HOMES,
    Comparison as Comparison,
    parse_tare as parse_tare,
    summarise_comparison as summarise_comparison,
    tare_baseline as tare_baseline,
    write_comparisons as write_comparisons,
)
from ._drift import drift_basis as drift_basis, parse_drift as parse_drift
from ._fit import CHI_SQUARE_WARNING as CHI_SQUARE_WARNING, identify_time as identify_time
from ._fit_logs import read_logs as read_logs
from ._problem import file_digest as file_digest
from ._report import write_outputs as write_outputs
from ._solve import (
    LevenbergMarquardt as LevenbergMarquardt,
    make_solver as make_solver,
    solve_least_squares as solve_least_squares,
    solver_name as solver_name,
)
