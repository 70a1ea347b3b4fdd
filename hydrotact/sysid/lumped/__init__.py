"""The lumped press model: fit the relaxation's shape (Eᵢ/E∞, τᵢ) and each channel's
law at each press site to stage logs whose probe moves between presses, with no model
of the skin (:func:`fit_press_logs`), write its material and report
(:func:`write_press_fit_outputs`), and predict held-out logs from it
(:func:`compare_fit`). The model, its assumptions and its outputs: docs/fit.md."""

from ._compare import Comparison as Comparison, compare_fit as compare_fit, compare_log as compare_log, read_fit as read_fit
from ._press_data import parse_drift as parse_drift
from ._press_fit import MAX_TERMS as MAX_TERMS, LumpedFit as LumpedFit, Parameter as Parameter, PressFit as PressFit, fit_press_logs as fit_press_logs, parse_starts as parse_starts
from ._press_report import write_press_fit_outputs as write_press_fit_outputs
from ._presses import Presses as Presses, find_log_presses as find_log_presses, find_presses as find_presses, group_sites as group_sites
