"""The lumped press model's solve (host around the pure core of
:mod:`hydrotact.sysid.lumped._lumped`): the shape's starts, the jitted solve from one start,
the site-onset rescans after it, the model's own residuals at a solution, and the fit
of a number of terms from the starts in turn. :mod:`hydrotact.sysid.lumped._press_fit` drives
it over the term counts and reports the result."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._stall import doing
from ..shared import solve_least_squares
from ._lumped import LAG_BOUND, PressLayout, calc_press_jacobian, calc_projection, press_residual_fn
from ._onset_scan import projection_at, scan_site_onsets
from ._press_data import PressLog, site_responses
from ._press_projection import calc_elastic, solve_baselines, solve_linear


def _press_durations(log: PressLog) -> np.ndarray:
    """(P,) each press's duration, s."""
    return np.array([np.ptp(log.times[log.press == p]) for p in range(len(log.onset_start))])


# The shape's starts (factor on the τ grid, Eᵢ/E∞), tried in turn while the fit ends
# far from the noise (starts="auto"), or all of the first N (starts=N). With a law of
# its own per site, an onset can trade against the shape, and the push's active set
# changes in steps: on notebook 02's stage log cut before its gap (2 presses, 40 %
# relaxation), the first start ends at a reduced χ² of 10.8 (τ 2.3 s and 118 s), the
# second at 1.01, at the true shape. Not every minimum is escaped so: with presses of
# varied depths (0.3-0.7 mm) on the test stand-in, the first start ends at 1.38 (τ 2.3
# s and 108 s, below the restart threshold; the other starts end higher), where a start
# at the true shape reaches 0.98.
SHAPE_STARTS = ((1.0, 0.05), (0.3, 0.3), (3.0, 0.3))
RESTART_REDUCED_CHI2 = 1.5  # starts="auto": a fit that ends above this is tried from the next start
RESTART_SAME_MINIMUM = 0.01  # starts="auto": two starts whose χ² differ by less than this fraction ended in one minimum


def _initial_x(layout: PressLayout, logs: list[PressLog], lag: float = 0.0, start: tuple[float, float] = SHAPE_STARTS[0]) -> np.ndarray:
    """The shape's start: the terms' τ spread log-evenly inside [4 sampling steps,
    the median press] (the time scales a press can show), times start[0], each Eᵢ/E∞
    start[1]; onsets at their estimates; lags at the given lag."""
    step = float(np.median(np.concatenate([np.diff(log.times) for log in logs])))
    durations = np.concatenate([_press_durations(log) for log in logs])
    k = layout.num_terms
    on = k if layout.active is None else int(np.sum(np.asarray(layout.active) > 0.0))  # the terms on come first
    taus = np.geomspace(4 * step, max(float(np.median(durations)), 40 * step), on + 2)[1:-1] * start[0]
    taus = np.concatenate([taus, np.full(k - on, taus[-1] if on else 1.0)])  # a term that is off: any finite τ
    parts = [np.log(np.full(k, start[1])), np.log(taus), np.zeros(sum(layout.num_presses))]
    if layout.estimate_lag:
        parts.append(np.full(len(logs), math.atanh(float(lag) / LAG_BOUND)))
    return np.concatenate(parts)


@eqx.filter_jit
def _solve_press(layout, solver, max_steps, x0, args):
    """The jitted solve (compiled once per layout, solver and step cap; reused by
    later fits of logs of the same sizes)."""
    return solve_least_squares(press_residual_fn(layout), x0, args, solver, max_steps=max_steps, throw=False)


POLISH_PASSES = 6  # more active-set passes at the solution, for the model's own χ²


def _own_residuals(datas, bases, contact, amplitudes):
    """The model's own weighted residuals per log (T, C) for the given amplitudes
    (the baseline + max(0, Σ A B) in contact, each log's baseline solved given them,
    over the samples out of contact where it is learned there) and the baselines per
    log (C, D)."""
    residuals, baselines = [], []
    for data, basis, touching in zip(datas, bases, contact):
        elastic = calc_elastic(basis, touching, amplitudes)
        used = (data.weights > 0.0) & (~touching[:, None] if data.drift_from == "unloaded" else True)
        coefficients = solve_baselines(data.baseline, data.observed - elastic, used)
        residuals.append((data.observed - elastic - data.baseline @ coefficients.T) * data.weights)
        baselines.append(coefficients)
    return residuals, baselines


@eqx.filter_jit
def press_outputs(layout, x, args, jacobian):
    """At x: (the weighted residuals per log, baselines, amplitudes) and (with
    `jacobian`; else None for both) the Jacobian and the amplitudes' sensitivity. The
    residuals are the model's own, as `compare` predicts a log: the baseline + max(0,
    Σ A B) in contact, each log's baseline solved given the amplitudes. The solver's
    projection found where the elastic part pushes from the amplitudes of a pass
    before, and where that cut a push off, the law was left free; so the amplitudes
    are those of the projection or of up to POLISH_PASSES further passes (each solved
    where the one before pushes), whichever gives each channel the lowest own χ².
    Without the Jacobian (the term counts `terms="auto"` compares) it compiles in a
    third of the time. `jacobian` has no default: every caller passes it the same
    way, since a default and an explicit True are two entries of the compilation
    cache (a 3-log fit compiled this function twice, 6 s)."""
    datas = args[0]
    if jacobian:
        _, jacobian, amplitudes, bases, contact, sensitivity = calc_press_jacobian(layout, x, args, linear=True)
    else:
        _, _, amplitudes, _, contact, bases = calc_projection(*layout.unpack(x, *args[1:]), datas)
        jacobian = sensitivity = None
    touching = [jnp.broadcast_to(c[:, None], data.observed.shape) for c, data in zip(contact, datas)]

    def polish(_, carry):  # a loop, not unrolled: the passes compile once
        amplitudes, best = carry
        actives = [t & (jnp.einsum("tsj,csj->tc", basis, amplitudes) > 0.0) for t, basis in zip(touching, bases)]
        amplitudes = solve_linear(bases, datas, actives, contact)[1]
        residuals, baselines = _own_residuals(datas, bases, contact, amplitudes)
        better = sum(jnp.sum(r**2, axis=0) for r in residuals) < sum(jnp.sum(r**2, axis=0) for r in best[1])  # (C,)
        best = (
            jnp.where(better[:, None, None], amplitudes, best[0]),
            [jnp.where(better[None, :], r, old) for r, old in zip(residuals, best[1])],
            [jnp.where(better[:, None], b, old) for b, old in zip(baselines, best[2])],
        )
        return amplitudes, best

    best = (amplitudes, *_own_residuals(datas, bases, contact, amplitudes))
    amplitudes, residuals, baselines = jax.lax.fori_loop(0, POLISH_PASSES, polish, (amplitudes, best))[1]
    return (residuals, baselines, amplitudes), jacobian, sensitivity


ONSET_RESCANS = 2  # at most this many site-onset scans (and re-solves) after a start's solve
# A rescan's minimum replaces the solver's only when the model's own χ² falls by more
# than χ²(1)'s 0.1 % point: where the lumped law only approximates a curved skin
# (test_press_fit's stand-in), a site's onset can move 100-300 µm along the valley for
# an own χ² lower by 3.7 (and the solver's by 33) over 6943 residuals, which says
# nothing; the onsets then stay near their estimates from the travel. On a log the
# model fits exactly, the trap a rescan is for costs 44 (test_lumped). In units of the
# residuals' own scatter: times the χ² per residual where that is above 1.
ONSET_RESCAN_MIN_GAIN = 10.83


def _own_chi_square(outputs) -> float:
    return float(sum(jnp.sum(r**2) for r in outputs[0][0]))


def _solver_chi_square(layout, x, args) -> float:
    """The χ² the solver minimised at x (compiled: the scan's projection; run op by op,
    the residual function took 7 of a cold fit's 40 s)."""
    return float(projection_at(layout, x, args)[0])


def _solve_from(layout: PressLayout, solver, max_steps: int, x0, args, jacobian=True):
    """The solve from x0, unscanned: (solution, outputs (:func:`press_outputs`, with
    or without the Jacobian), (own χ², solver's χ²))."""
    solution = _solve_press(layout, solver, max_steps, x0, args)
    outputs = press_outputs(layout, solution.value, args, jacobian)
    return solution, outputs, (_own_chi_square(outputs), _solver_chi_square(layout, solution.value, args))


def solve_press_scanned(layout: PressLayout, solver, max_steps: int, x0, args, solved=None):
    """The solve from x0 (or `solved`, what :func:`_solve_from` returned for it),
    then while a scan of each site's common onset shift (:func:`scan_site_onsets`)
    lowers the solver's χ², a re-solve from the scan's best (at most ONSET_RESCANS
    times), kept when it lowers the model's own χ² by more than
    ONSET_RESCAN_MIN_GAIN (times the χ² per residual, where above 1): a site's onsets
    and its law nearly trade, and the solver alone can end with every press at a
    site early by the same amount.
    Returns (the solution, its outputs (:func:`press_outputs`), (its own χ², the
    solver's χ²))."""
    num_residuals = max(1, sum(int(jnp.sum(data.weights > 0.0)) for data in args[0]))
    solution, outputs, (chi_square, cost) = solved if solved is not None else _solve_from(layout, solver, max_steps, x0, args)
    for _ in range(ONSET_RESCANS):
        doing(f"the lumped fit's onset scan ({args[0][0].num_sites} sites)")
        x, scanned = scan_site_onsets(layout, solution.value, args, scale=max(1.0, chi_square / num_residuals))
        if not scanned < cost * (1.0 - 1e-6):
            break
        rescanned = _solve_press(layout, solver, max_steps, x, args)
        rescanned_outputs = press_outputs(layout, rescanned.value, args, True)
        rescanned_chi_square = _own_chi_square(rescanned_outputs)
        if not rescanned_chi_square < chi_square - ONSET_RESCAN_MIN_GAIN * max(1.0, chi_square / num_residuals):
            break
        solution, outputs, chi_square, cost = rescanned, rescanned_outputs, rescanned_chi_square, _solver_chi_square(layout, rescanned.value, args)
    return solution, outputs, (chi_square, cost)


def fit_terms(num_terms, logs, num_sites, estimate_lag, lag, solver, max_steps, starts, num_used, num_linear, scan=True, padded_to=None):
    """Fit `num_terms` terms from the shape starts in turn, then (with `scan`) scan
    the best one's site onsets (:func:`solve_press_scanned`; once, not after every
    start's solve: the scan judges every site's 25 shifts). Without `scan`, the
    outputs have no Jacobian (None): what a comparison of term counts needs.
    With `padded_to` K ≥ num_terms, the layout holds K terms, the first num_terms on
    (PressLayout.active): every count then runs the same compiled programs.
    starts "auto": the next start is tried while the best own reduced χ² is above
    RESTART_REDUCED_CHI2, unless two starts have ended within RESTART_SAME_MINIMUM of
    each other's χ² (the same minimum from two shapes: what is left is the model's
    misfit, which no start removes; a real log never falls below 1.5); N: the first
    N. The best start is one that converged, if any did, with the lowest own χ².
    Returns (the layout, args, solution, (own χ², solver's χ²), outputs, each start's
    own χ² at the end of its solve, before any scan, in the order tried)."""
    presses = tuple(len(log.onset_start) for log in logs)
    if padded_to is None:
        layout = PressLayout(num_terms, presses, estimate_lag)
    else:
        layout = PressLayout(padded_to, presses, estimate_lag, jnp.asarray(np.arange(padded_to) < num_terms, jnp.float64))
    responds = site_responses(logs, num_sites)
    datas = tuple(log.to_data(num_sites, responds) for log in logs)
    args = (datas, tuple(jnp.asarray(log.onset_start) for log in logs), tuple(jnp.asarray(float(lag)) for _ in logs))
    dof = max(num_used - layout.without_inactive()[0].size - num_linear, 1)
    best = None
    candidates = SHAPE_STARTS if starts == "auto" else SHAPE_STARTS[:starts]
    ends = []
    for start in candidates if num_terms else candidates[:1]:  # no terms, no shape to start
        doing(f"the lumped fit's solve ({num_terms} Prony terms, start {len(ends) + 1} of at most {len(candidates)})")
        solved = _solve_from(layout, solver, max_steps, jnp.asarray(_initial_x(layout, logs, lag, start)), args, jacobian=scan)
        ends.append(float(solved[2][0]))
        # A solve that converged beats one stopped at its step cap (on a flat valley of
        # a term the logs cannot tell, still creeping), then the lower own χ².
        if best is None or (bool(solved[0].converged), -solved[2][0]) > (bool(best[0].converged), -best[2][0]):
            best = solved
        if starts == "auto":
            if best[2][0] / dof < RESTART_REDUCED_CHI2:
                break
            if len(ends) >= 2 and min(abs(a - b) / min(a, b) for k, a in enumerate(ends) for b in ends[:k]) < RESTART_SAME_MINIMUM:
                break
    solution, outputs, chi_squares = solve_press_scanned(layout, solver, max_steps, None, args, solved=best) if scan else best
    return layout, args, solution, chi_squares, outputs, tuple(ends)
