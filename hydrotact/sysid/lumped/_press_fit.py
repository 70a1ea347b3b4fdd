"""Fitting the lumped press model to stage logs (host driver around the pure core of
:mod:`hydrotact.sysid.lumped._lumped`).

:func:`fit_press_logs` takes logs of one sensor pressed by a stage (the travel in an
indentation column, the site in position columns) and fits, jointly over the logs:

- shared: the relaxation shape (Eᵢ/E∞, τᵢ) and each channel's elastic law at each
  site (amplitudes of powers of the depth, see :mod:`hydrotact.sysid.lumped._lumped`; fixed
  at 0 where the channel moves less than SITE_RESPONSE_SNR noise stds in every press
  at the site) — sites are stage positions, matched across logs;
- per log: each press's contact onset (within ±0.5 mm of its first estimate), the
  lag of the pressures behind the stage (given, or estimated with `estimate_lag`),
  and each channel's baseline (a constant, a line, or cubic B-splines with knots
  `drift` seconds apart: real baselines drift by kPa within a file).

Samples a barometer clipped (at the part's limits, or flat at a channel's maximum)
are masked (weight 0), not refused. Each channel's noise is estimated from its own
samples and weights its residuals, so the reduced χ² is ≈ 1 for a model that
describes the data. Channels that respond to no press, and logs with no press or no
responding channel, are skipped, each with a :class:`HydrotactWarning`.

The result reports each parameter with its standard error and whether the data
identify it: a parameter pinned at its bound, a time constant outside
[sampling step / 10, 10 × the longest log], or one whose standard error exceeds its
value is *not identified* — its value is the solver's last word, not a measurement.
"""

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import HydrotactError, warn
from ..shared import CHI_SQUARE_WARNING, LevenbergMarquardt, identify_time, make_solver, solver_name
from ._lumped import LAG_BOUND, ONSET_HALF_RANGE
from ._press_data import DRIFT_KNOT_S, prepare_press_logs
from ._press_solve import SHAPE_STARTS, fit_terms, press_outputs, solve_press_scanned
from ._press_windows import POWERS
from ._presses import POSITION_COLUMNS, PRESS_THRESHOLD

# Levenberg-Marquardt's xtol for the press model (the solver's default is 1e-6):
# its χ² has kinks (a channel's elastic part switches on where it crosses 0), and
# once the solve reaches one, the trust region shrinks a quarter at a time through
# a dozen rejected steps to creep a few units of χ² along it. On the three
# full-size stand-in logs (78,000 χ²), 1e-4 ends after 36 steps instead of 47 (6 s
# of a 66 s cold command line), the model's own χ² 4.2 lower and the solver's 4.2
# higher; the parameters settle to 1e-4 (1 + ‖x‖∞) in log τ, log Eᵢ/E∞ and the
# onsets' tanh coordinates (≤ 0.2 µm), far inside their standard errors (τ 1.4-7
# %, onsets ~10 µm).
PRESS_XTOL = 1e-4
MAX_TERMS = 3  # Prony terms the lumped model tries with terms="auto"


@dataclasses.dataclass(frozen=True)
class Parameter:
    """A fitted value with its standard error and whether the data identify it
    (`note` says why not)."""

    value: float
    std: float
    identified: bool = True
    note: str = ""

    def to_json(self) -> dict:
        out = {"value": float(self.value), "std": float(self.std), "identified": bool(self.identified)}
        if self.note:
            out["note"] = self.note
        return out


@dataclasses.dataclass(frozen=True)
class PressFit:
    """A lumped press fit.

    **Fields:** `ratios`, `taus` [Parameter] per Prony term (Eᵢ/E∞ and τᵢ, sorted by
    τ); `amplitudes` (C, S, J) Pa at 1 mm per power of the law; `sites` (S, k)
    stage positions, m; `site_onsets` (S,) the mean fitted onset per site (m of
    travel); `onsets` per log (P_l,) m; `onset_stds` per log; `lags` per log
    [Parameter]; `baselines` per log (C, D); `channels` fitted; `skipped` {name:
    reason} for channels and logs left out; `logs` the PressLogs; `residuals` per log
    (T, C) weighted (0 where masked); `chi_square` the model's own (as `compare`
    predicts), `solver_chi_square` the projection's the solver minimised (which finds
    where the push max(0, ·) is on from a pass before; the two differ by where the
    push starts or ends at the final amplitudes), `dof`, `converged`, `num_steps`,
    `solver`, `drift`, `drift_from` (where the baselines were learned), `warnings` [str]; `num_terms`; `start_chi_squares` the own χ² each
    shape start tried ended at (see SHAPE_STARTS), in order, before the onset scan of
    the best, and `num_starts` their count; `law_covariance` the covariance of
    the channel law's parameters (see :func:`_law_covariance`), for `compare`'s
    prediction band.
    """

    ratios: list
    taus: list
    amplitudes: np.ndarray
    sites: np.ndarray
    site_onsets: np.ndarray
    onsets: list
    onset_stds: list
    lags: list
    baselines: list
    channels: tuple
    skipped: dict
    logs: list
    residuals: list
    chi_square: float
    solver_chi_square: float
    dof: int
    converged: bool
    num_steps: int
    solver: str
    drift: object
    warnings: list
    num_terms: int
    position_columns: tuple
    indentation: str
    estimate_lag: bool
    start_chi_squares: tuple = ()
    law_covariance: dict | None = None
    drift_from: str = "all"

    @property
    def num_starts(self) -> int:
        return max(len(self.start_chi_squares), 1)

    @property
    def reduced_chi_square(self) -> float:
        return self.chi_square / max(self.dof, 1)

    def predictions(self) -> list:
        """(T, C) the model's readings per log, Pa (observed − residual × noise)."""
        return [log.observed - residual * log.noise[None, :] for log, residual in zip(self.logs, self.residuals)]


@dataclasses.dataclass(frozen=True)
class LumpedFit:
    """The lumped press model as :func:`hydrotact.sysid.fit_logs`'s `method`
    (settings only; the command line's `fit --lumped`): the logs' `sensor` where
    their metadata names none; the travel column `indentation`, the stage's
    `position_columns`, `drift`, `drift_from`, `lag`, `estimate_lag`,
    `saturation_pa`, the press `threshold` and the shape `starts`, as for
    :func:`fit_press_logs`."""

    sensor: str | None = None
    indentation: str = "indentation"
    position_columns: tuple[str, ...] = POSITION_COLUMNS
    drift: float | str = DRIFT_KNOT_S
    drift_from: str = "all"
    lag: float = 0.0
    estimate_lag: bool = False
    saturation_pa: float | None = None
    threshold: float = PRESS_THRESHOLD
    starts: int | str = "auto"

    def press_options(self) -> dict:
        """fit_press_logs's keyword arguments from these settings."""
        return {field.name: getattr(self, field.name) for field in dataclasses.fields(self) if field.name != "sensor"}


def parse_starts(text) -> int | str:
    """--starts: 'auto' or a number of shape starts (1 to len(SHAPE_STARTS))."""
    if str(text) == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or not 1 <= value <= len(SHAPE_STARTS):
        raise HydrotactError(f"--starts: expected auto or 1 to {len(SHAPE_STARTS)} starts, got {text!r}")
    return value


def fit_press_logs(
    logs, sources=None, *, terms="auto", indentation="indentation", position_columns=POSITION_COLUMNS, drift=DRIFT_KNOT_S,
    lag=0.0, estimate_lag=False, saturation_pa=None, threshold=PRESS_THRESHOLD, solver=None, max_steps=400, starts="auto",
    drift_from="all",
) -> PressFit:
    """Fit the lumped press model jointly to stage logs (see the module's docstring).

    **Arguments:** `logs` BarometerLogs of one sensor; `sources` their names for
    messages; `terms` Prony terms (0-3) or "auto" (lowest BIC over 1-3); `indentation`
    the stage travel column; `position_columns` the stage position columns (those a
    log lacks are ignored: then one site per press); `drift` "none", "linear" or the
    baseline spline's knot spacing, s; `drift_from` "all" (the baseline fitted jointly
    with the laws) or "unloaded" (from the samples out of contact alone: it cannot
    take up any relaxation; see DRIFT_FROM); `lag` the pressures' lag behind the stage, s
    (the start when `estimate_lag`); `saturation_pa` the upper reading limit (default:
    the log's part's, for absolute logs of a known sensor); `threshold` the press
    threshold (fraction of the travel's range); `solver` a least-squares solver
    object, used as given, or name (default Levenberg-Marquardt, stepping to
    PRESS_XTOL); `max_steps`; `starts` the relaxation
    shapes to start from (SHAPE_STARTS): "auto" tries the next while the fit ends at
    a reduced χ² above RESTART_REDUCED_CHI2, a number N the first N, and the lowest
    χ² is kept. The skipped channels and logs, and what may mislead (a poor χ²,
    parameters the logs cannot identify), are issued as :class:`HydrotactWarning`.

    **Returns:** a :class:`PressFit`.
    """
    with jax.enable_x64(True):  # absolute readings (~1e5 Pa) to a Pa, and normal equations: float64
        return _fit_press_logs(
            logs, sources, terms=terms, indentation=indentation, position_columns=position_columns, drift=drift, lag=lag,
            estimate_lag=estimate_lag, saturation_pa=saturation_pa, threshold=threshold, solver=solver, max_steps=max_steps, starts=starts,
            drift_from=drift_from,
        )


def _fit_press_logs(logs, sources, *, terms, indentation, position_columns, drift, lag, estimate_lag, saturation_pa, threshold, solver, max_steps, starts, drift_from):
    sources = list(sources) if sources is not None else [f"log {k + 1}" for k in range(len(logs))]
    if not logs:
        raise HydrotactError("no logs given")
    if terms != "auto" and not (isinstance(terms, int) and 0 <= terms <= MAX_TERMS):
        raise HydrotactError(f"--terms: a lumped fit takes 0 to {MAX_TERMS} Prony terms or auto, got {terms!r}")
    if not (isinstance(max_steps, int) and max_steps >= 1):
        raise HydrotactError(f"--max-steps: expected a positive whole number of steps, got {max_steps!r}")
    if starts != "auto" and not (isinstance(starts, int) and 1 <= starts <= len(SHAPE_STARTS)):
        raise HydrotactError(f"--starts: expected auto or 1 to {len(SHAPE_STARTS)} starts, got {starts!r}")
    if not abs(float(lag)) < LAG_BOUND:
        raise HydrotactError(f"--lag: expected a lag within ±{LAG_BOUND:g} s, got {lag!r}")
    named = solver is None or isinstance(solver, str)
    solver = make_solver(solver or "lm") if named else solver
    # A solver chosen by name steps with the press model's xtol; the report names it as chosen.
    stepping = eqx.tree_at(lambda s: s.xtol, solver, PRESS_XTOL) if named and isinstance(solver, LevenbergMarquardt) else solver
    prepared, channels, sites, skipped = prepare_press_logs(
        logs, sources, indentation=indentation, position_columns=position_columns, drift=drift, lag=lag, saturation_pa=saturation_pa,
        threshold=threshold, drift_from=drift_from,
    )
    num_used = int(sum(log.mask.sum() for log in prepared))
    num_linear = (sum(log.baseline.shape[1] for log in prepared) + len(sites) * len(POWERS)) * len(channels)
    counts = range(1, MAX_TERMS + 1) if terms == "auto" else [terms]
    best = None
    for count in counts:
        # With auto, each count's fit is compared unscanned and only the chosen one's
        # onsets are scanned (a scan is a third of a cold fit). On the full-size
        # stand-in the scan lowers the own χ² of 1, 2 and 3 terms by 34, 0 and 143
        # (of 24,000-30,000), the BIC steps between the counts are 5,400 and 530.
        # The counts' fits share one compiled program (MAX_TERMS terms, those past
        # the count off): compiling each count's was ~6 s of a cold fit's 50.
        layout, args, solution, chi_squares, outputs, ends = fit_terms(
            count, prepared, len(sites), estimate_lag, lag, stepping, max_steps, starts, num_used, num_linear, scan=len(counts) == 1,
            padded_to=MAX_TERMS if len(counts) > 1 else None,
        )
        bic = chi_squares[0] + (layout.without_inactive()[0].size + num_linear) * math.log(num_used)
        if best is None or bic < best[0]:
            best = (bic, count, layout, args, solution, chi_squares, outputs, ends)
    _, count, layout, args, solution, chi_squares, outputs, ends = best
    if len(counts) > 1:
        outputs = press_outputs(layout, solution.value, args, True)  # with the Jacobian
        solution, outputs, chi_squares = solve_press_scanned(layout, stepping, max_steps, None, args, solved=(solution, outputs, chi_squares))
        layout, solution, outputs = _without_inactive(layout, solution, outputs)
    return _summarise(
        layout, args, solution, chi_squares, outputs, prepared, channels, sites, skipped, num_used, num_linear, solver, drift, estimate_lag, position_columns, indentation,
        start_chi_squares=ends,
    )


def _without_inactive(layout, solution, outputs):
    """The layout, solution and outputs of a padded fit (PressLayout.active) in the
    layout of the terms that are on: their entries of x, the Jacobian's columns and
    the amplitudes' derivatives (the others are 0)."""
    small, keep = layout.without_inactive()
    (residuals, baselines, amplitudes), jacobian, sensitivity = outputs
    solution = eqx.tree_at(lambda s: s.value, solution, solution.value[keep])
    sensitivity = eqx.tree_at(lambda s: s.steps, sensitivity, sensitivity.steps[keep])
    return small, solution, ((residuals, baselines, amplitudes), jacobian[:, keep], sensitivity)


def _summarise(
    layout, args, solution, chi_squares, outputs, logs, channels, sites, skipped, num_used, num_linear, solver, drift, estimate_lag, position_columns, indentation,
    *, start_chi_squares,
) -> PressFit:
    x = solution.value
    chi_square, solver_chi_square = chi_squares
    (residuals, baselines, amplitudes), jacobian, sensitivity = outputs
    jacobian = np.asarray(jacobian)
    dof = max(num_used - layout.size - num_linear, 1)
    scale = max(chi_square / dof, 1.0)
    normal = jacobian.T @ jacobian
    covariance = np.linalg.pinv(normal) * scale
    std_x = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    x = np.asarray(x)
    _, onsets, lags = layout.unpack(jnp.asarray(x), *args[1:])
    k = layout.num_terms
    step = float(np.median(np.concatenate([np.diff(log.times) for log in logs])))
    span = max(float(log.times[-1] - log.times[0]) for log in logs)
    order = np.argsort(x[k : 2 * k])
    ratios, taus = [], []
    for i in order:
        ratio, ratio_std = math.exp(x[i]), math.exp(x[i]) * std_x[i]
        tau, tau_std = math.exp(x[k + i]), math.exp(x[k + i]) * std_x[k + i]
        ok, note = identify_time(tau, tau_std, step, span)
        ratios.append(Parameter(ratio, ratio_std, ok and ratio_std < ratio, note or ("" if ratio_std < ratio else "standard error larger than the value")))
        taus.append(Parameter(tau, tau_std, ok, note))
    first = 2 * k
    onset_values, onset_stds = [], []
    for log, onset in zip(logs, onsets):
        count = len(log.onset_start)
        z = x[first : first + count]
        onset_values.append(np.asarray(onset))
        onset_stds.append(ONSET_HALF_RANGE * (1 - np.tanh(z) ** 2) * std_x[first : first + count])
        pinned = np.abs(np.tanh(z)) > 0.999
        if pinned.any():
            warn(f"{log.source}: {int(pinned.sum())} press onsets at their bound (±{ONSET_HALF_RANGE * 1e3:g} mm of the first estimate): not identified")
        first += count
    lag_params = []
    for j, lag in enumerate(lags):
        if estimate_lag:
            z = x[first + j]
            std = LAG_BOUND * (1 - math.tanh(z) ** 2) * std_x[first + j]
            pinned = abs(math.tanh(z)) > 0.999
            lag_params.append(Parameter(float(lag), float(std), not pinned, f"at its bound (±{LAG_BOUND:g} s)" if pinned else ""))
        else:
            lag_params.append(Parameter(float(lag), 0.0, True, "given"))
    site_onsets = np.full(len(sites), np.nan)
    for s in range(len(sites)):
        values = [float(onset[p]) for log, onset in zip(logs, onset_values) for p in np.flatnonzero(log.press_site == s)]
        if values:
            site_onsets[s] = float(np.mean(values))
    # Sites no press of a fitted log reached (only a skipped log's) have no onset: left out of the result.
    seen = np.isfinite(site_onsets)
    renumber = np.cumsum(seen) - 1
    logs = [dataclasses.replace(log, press_site=renumber[log.press_site]) for log in logs]
    sites, site_onsets, amplitudes = sites[seen], site_onsets[seen], np.asarray(amplitudes)[:, seen, :]
    law_covariance = _law_covariance(covariance, sensitivity, scale, layout, x, logs, order, seen)
    messages = []
    converged = bool(solution.converged)
    if not converged:
        messages.append(f"the {solver_name(solver)} solver stopped before converging ({int(solution.num_steps)} steps; raise --max-steps); the numbers are its last iterate")
    reduced = chi_square / dof
    if reduced > CHI_SQUARE_WARNING:
        messages.append(f"reduced χ² {reduced:.3g}: the model misses the data by more than their noise (RMS residual {math.sqrt(reduced):.2g} noise stds); check the drift, the lag and the masks")
    unidentified = [f"τ{i + 1}" for i, t in enumerate(taus) if not t.identified] + [f"E{i + 1}/E∞" for i, r in enumerate(ratios) if not r.identified]
    unidentified += [f"lag of {log.source}" for log, lag in zip(logs, lag_params) if not lag.identified]
    if unidentified:
        messages.append(f"not identified by these logs: {', '.join(unidentified)} (see the report)")
    for message in messages:
        warn(message)
    return PressFit(
        ratios=ratios, taus=taus, amplitudes=np.asarray(amplitudes), sites=sites,
        site_onsets=site_onsets, onsets=onset_values, onset_stds=onset_stds, lags=lag_params, baselines=[np.asarray(b) for b in baselines],
        channels=channels, skipped=skipped, logs=logs, residuals=[np.asarray(r) for r in residuals], chi_square=chi_square,
        solver_chi_square=solver_chi_square, dof=dof,
        converged=converged, num_steps=int(solution.num_steps), solver=solver_name(solver), drift=drift, warnings=messages, num_terms=k,
        position_columns=tuple(position_columns), indentation=indentation, estimate_lag=estimate_lag, start_chi_squares=start_chi_squares,
        law_covariance=law_covariance, drift_from=logs[0].drift_from,
    )


def _law_covariance(covariance, sensitivity, scale, layout, x, logs, order, seen) -> dict:
    """The covariance of what `compare` predicts with: q = (log Eᵢ/E∞, log τᵢ in τ's
    order, each site's onset (the mean of its presses'), the lag (the mean of the
    logs')) and each channel's amplitudes A_c (S J). From the fit's covariance of x,
    Cₓ (scaled by the reduced χ² where it exceeds 1), q = L x to first order, and the
    amplitudes by the projection's Schur complement (see LinearSensitivity).

    **Returns:** {"qq": (Q, Q), "qa": (C, Q, S J), "aa": (C, S J, S J)} (Q = 2K + S + 1), in
    the units of q (1 for the log shape, m, s) and Pa."""
    k = layout.num_terms
    num_sites = int(seen.sum())
    transform = np.zeros((2 * k + num_sites + 1, len(x)))
    for row, i in enumerate(order):
        transform[row, i] = 1.0
        transform[k + row, k + i] = 1.0
    first = 2 * k
    counts = np.bincount(np.concatenate([log.press_site for log in logs]), minlength=num_sites)
    for log in logs:
        for p, site in enumerate(log.press_site):
            transform[2 * k + site, first + p] = ONSET_HALF_RANGE * (1 - math.tanh(x[first + p]) ** 2) / counts[site]
        first += len(log.press_site)
    if layout.estimate_lag:
        for j in range(len(logs)):
            transform[-1, first + j] = LAG_BOUND * (1 - math.tanh(x[first + j]) ** 2) / len(logs)
    num_channels, num_linear = np.asarray(sensitivity.inverse).shape[:2]
    num_powers = num_linear // len(seen)
    kept = np.repeat(seen, num_powers)
    steps = np.asarray(sensitivity.steps)[:, :, kept]  # (M, C, S J)
    inverse = np.asarray(sensitivity.inverse)[:, kept][:, :, kept] * scale
    return {
        "qq": transform @ covariance @ transform.T,
        "qa": np.einsum("qm,mn,ncs->cqs", transform, covariance, steps),
        "aa": inverse + np.einsum("mcs,mn,nct->cst", steps, covariance, steps),
    }
