"""System identification: fit the elastomer's Prony material, channel gains and
offsets to barometer logs, with uncertainties and a report."""

from ._compare import Comparison as Comparison
from ._compare import compare_fit as compare_fit
from ._compare import compare_log as compare_log
from ._compare import read_fit as read_fit
from ._fit import (
    MAX_AUTO_TERMS as MAX_AUTO_TERMS,
)
from ._fit import (
    Estimate as Estimate,
)
from ._fit import (
    FitResult as FitResult,
)
from ._fit import (
    fit_auto as fit_auto,
)
from ._fit import (
    fit_parameters as fit_parameters,
)
from ._fit import (
    fit_problem as fit_problem,
)
from ._fit import (
    make_initial_guess as make_initial_guess,
)
from ._fit_logs import fit_logs as fit_logs
from ._fit_logs import parse_terms as parse_terms
from ._fit_logs import read_logs as read_logs
from ._model import ParameterLayout as ParameterLayout
from ._model import calc_predictions as calc_predictions
from ._model import calc_residuals as calc_residuals
from ._press_data import parse_drift as parse_drift
from ._press_fit import Parameter as Parameter
from ._press_fit import PressFit as PressFit
from ._press_fit import fit_press_logs as fit_press_logs
from ._press_fit import parse_starts as parse_starts
from ._press_report import write_press_fit_outputs as write_press_fit_outputs
from ._presses import (
    Presses as Presses,
)
from ._presses import (
    find_log_presses as find_log_presses,
)
from ._presses import (
    find_presses as find_presses,
)
from ._presses import (
    group_sites as group_sites,
)
from ._problem import FitProblem as FitProblem
from ._problem import LogArrays as LogArrays
from ._problem import make_fit_problem as make_fit_problem
from ._relaxation import RelaxationFit as RelaxationFit
from ._relaxation import fit_relaxation_curve as fit_relaxation_curve
from ._report import (
    calc_relaxation_band as calc_relaxation_band,
)
from ._report import (
    make_fit_material as make_fit_material,
)
from ._report import (
    make_report as make_report,
)
from ._report import (
    write_fit_outputs as write_fit_outputs,
)
from ._solve import (
    SOLVERS as SOLVERS,
)
from ._solve import (
    BoundedLBFGSB as BoundedLBFGSB,
)
from ._solve import (
    GaussNewtonArmijo as GaussNewtonArmijo,
)
from ._solve import (
    LeastSquaresSolution as LeastSquaresSolution,
)
from ._solve import (
    make_solver as make_solver,
)
from ._solve import (
    solve_least_squares as solve_least_squares,
)
from ._solve import (
    solver_name as solver_name,
)
