"""A log's drifting baseline as a linear basis, shared by the simulator fit (with a
rig) and the lumped press model: a constant, a line, or cubic B-splines with knots a
given number of seconds apart."""

import math

import numpy as np

from .._errors import HydrotactError


def drift_basis(times, drift) -> np.ndarray:
    """(T, D) the baseline basis of a log: drift "none" (a constant), "linear", or a
    knot spacing in s (cubic B-splines over the log, at least one interval)."""
    times = np.asarray(times, dtype=np.float64)
    span = max(float(times[-1] - times[0]), 1e-12)
    scaled = (times - times[0]) / span
    if drift == "none":
        return np.ones((len(times), 1))
    if drift == "linear":
        return np.column_stack([np.ones_like(scaled), 2.0 * scaled - 1.0])
    from scipy.interpolate import BSpline

    intervals = max(1, math.ceil(span / float(drift)))
    knots = np.concatenate([[0.0] * 3, np.linspace(0.0, 1.0, intervals + 1), [1.0] * 3])
    return BSpline.design_matrix(np.clip(scaled, 0.0, 1.0), knots, 3).toarray()


def parse_drift(text):
    """'none', 'linear' or a knot spacing in seconds (a positive number)."""
    if text in ("none", "linear"):
        return text
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise HydrotactError(f"--drift: expected none, linear or a knot spacing in seconds, got {text!r}") from None
    if not value > 0.0 or not math.isfinite(value):
        raise HydrotactError(f"--drift: the knot spacing must be a positive number of seconds, got {text!r}")
    return value
