"""System identification: fit the elastomer's Prony material, channel gains and
offsets to barometer logs, with uncertainties and a report. Two ways: the simulator
fit (here) and the lumped press model for stage logs (:mod:`.lumped`, re-exported);
what they share is public in :mod:`.shared`."""

from ._fit import (
    MAX_AUTO_TERMS as MAX_AUTO_TERMS,
    Estimate as Estimate,
    FitResult as FitResult,
    fit_auto as fit_auto,
    fit_parameters as fit_parameters,
    fit_problem as fit_problem,
    make_initial_guess as make_initial_guess,
)
from ._fit_logs import SimulatorFit as SimulatorFit, fit_logs as fit_logs, parse_terms as parse_terms, read_logs as read_logs
from ._model import ParameterLayout as ParameterLayout, calc_predictions as calc_predictions, calc_residuals as calc_residuals
from ._problem import FitProblem as FitProblem, LogArrays as LogArrays, make_fit_problem as make_fit_problem
from ._relaxation import RelaxationFit as RelaxationFit, fit_relaxation_curve as fit_relaxation_curve
from ._report import (
    calc_relaxation_band as calc_relaxation_band,
    make_fit_material as make_fit_material,
    make_report as make_report,
    write_fit_outputs as write_fit_outputs,
)
from ._rig_compare import compare_fit as compare_fit, compare_rig_log as compare_rig_log, label_rig_log as label_rig_log
from ._solve import (
    SOLVERS as SOLVERS,
    BoundedLBFGSB as BoundedLBFGSB,
    GaussNewtonArmijo as GaussNewtonArmijo,
    LeastSquaresSolution as LeastSquaresSolution,
    make_solver as make_solver,
    solve_least_squares as solve_least_squares,
    solver_name as solver_name,
)
from .lumped import (
    Comparison as Comparison,
    LumpedFit as LumpedFit,
    Parameter as Parameter,
    Presses as Presses,
    PressFit as PressFit,
    compare_log as compare_log,
    find_log_presses as find_log_presses,
    find_presses as find_presses,
    fit_press_logs as fit_press_logs,
    group_sites as group_sites,
    parse_drift as parse_drift,
    parse_starts as parse_starts,
    read_fit as read_fit,
    write_press_fit_outputs as write_press_fit_outputs,
)
