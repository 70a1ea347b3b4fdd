"""The lumped model for stage logs where the probe moves between presses (pure).

For a sensor nobody has modelled, each channel c of a log is

    reading_c(t) = Σ_d β_{c,d} · φ_d(t) + [δ(t) > 0] · max(0, Σ_s Σ_j A_{c,s,j} · B_{s,j}(t))

with a slowly varying baseline (φ_d: a constant, a line, or cubic B-splines with knots
tens of seconds apart for a drifting sensor; per log) and, per site s and power p_j,

    B_{s,j}(t) = H(E / E∞, (δ / δ_ref)^{p_j} · [site(t) = s])(t),
    δ(t) = (travel(t − lag) − onset_{press(t)})₊,

where H is the hereditary integral (:func:`hydrotact.visco.calc_hereditary_integral`)
with the Prony series' shape (E∞ ≡ 1: only Eᵢ/E∞ and τᵢ are identifiable without a
model of the skin), `travel` the stage's travel towards the skin and `onset_p` the
travel at which press p's contact starts. Each channel's elastic law at a site is
thus a sum of powers of the depth, g_{c,s}(δ) = Σ_j A_{c,s,j} (δ/δ_ref)^{p_j} with
p = POWERS (1.5, 2, 2.5, 3). A single power law per channel does not describe
barometers under a curved skin: on the stage-log stand-in (hydrotact.sim,
fingertip4), a reading's local log-log slope runs from ~2.3 near the onset to ~1.4
at 0.9 mm under the press and 3-10 for a barometer a few mm away, and the best
δ^1.5 law per (channel, site) misses the simulated law by 24-49 Pa RMS over
0-0.9 mm, these four powers by 0.5-1.4 Pa (below a barometer's noise). No power
below Hertz's 1.5: with a δ¹ term the law could mimic a shifted onset
((δ − ε)^1.5 ≈ δ^1.5 − 1.5 ε δ^0.5 needs a δ^0.5), and the onsets would go
unidentified.

The memory of H runs on between presses and across sites, as in the forward model
(:func:`hydrotact.visco.calc_contact_response`): the barometer sits in one skin, and
after a relaxed press the skin recovers for seconds (its memory negative), lowering
the next press's reading wherever it is — by ~100 Pa after a 1-3 s rest on the
stand-in. A contact pushes but never pulls, hence the max(0, ·) of the sum. Masking
the bases to their own site or clipping each at 0 drops that recovery (the fit then
finds a relaxation ~40 % too weak); masking without any clipping makes the readings
jump where δ reaches 0, and the solver stalls in the steps.

The amplitudes A (shared by the logs) and the baselines' β (per log) enter linearly:
for given nonlinear parameters (shape, onsets, lags) they are solved per channel by
weighted least squares inside the residual (variable projection, Golub and Pereyra),
so the outer solver only sees the few nonlinear parameters; their Jacobian, the
exact one of the projected problem, is written by hand (:func:`calc_press_jacobian`).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Bool, Float, Int
from ..visco import Prony, calc_kernel_responses_and_derivatives

DEPTH_SCALE = 1e-3  # m: δ is measured in millimetres in the law (amplitudes in Pa at 1 mm)
POWERS = (1.5, 2.0, 2.5, 3.0)  # the law's powers of the depth (from Hertz's 1.5 up: see the docstring)
ACTIVE_PASSES = 2  # solves that find where the elastic part is on, before the last
RIDGE = 1e-12  # relative to the normal matrix' diagonal: keeps an unused site's amplitude at 0


class PressData(eqx.Module):
    """One log for the lumped press model (device arrays; build it with
    :func:`make_press_data`).

    **Fields:** `times` (T,) s; `travel` (T,) m; `press` (T,) the press of each
    sample (-1 between presses); `press_site` (P,) the site of each press (the sites
    are shared by all the logs of a fit); `observed` (T, C) Pa; `weights` (T, C)
    1 / noise, 0 for masked samples; `baseline` (T, D) the basis of each channel's
    slowly varying baseline (offset and drift: a constant, a line, or a cubic
    B-spline); `num_sites` (static) the number of sites of the whole fit. Each
    press's window, the samples its input is not 0 between (its own and one either
    side), concatenated: `window` (W,) their sample indices, `window_press` (W,) and
    `window_restart` (W,) whose window and where one starts; per press
    `window_last` (P,) where its window ends in the concatenation.
    """

    times: Float[Array, " num_samples"]
    travel: Float[Array, " num_samples"]
    press: Int[Array, " num_samples"]
    press_site: Int[Array, " num_presses"]
    observed: Float[Array, "num_samples num_channels"]
    weights: Float[Array, "num_samples num_channels"]
    baseline: Float[Array, "num_samples num_baseline"]
    window: Int[Array, " num_window"]
    window_press: Int[Array, " num_window"]
    window_restart: Bool[Array, " num_window"]
    window_last: Int[Array, " num_presses"]
    num_sites: int = eqx.field(static=True)


def make_press_data(times, travel, press, press_site, observed, weights, baseline, num_sites: int) -> PressData:
    """A :class:`PressData` from host arrays (as its fields), its press windows
    found here: press p's input is 0 outside (first − 1, last + 1) of its samples
    (linear between samples), so its hereditary integral is its window's, then a
    free decay. A press without samples gets a one-sample window of 0 input."""
    press = np.asarray(press)
    num_samples, num_presses = len(press), len(press_site)
    first, length, window, restart = np.zeros(num_presses, np.int64), np.ones(num_presses, np.int64), [], []
    for p in range(num_presses):
        samples = np.flatnonzero(press == p)
        if len(samples):
            first[p] = max(samples[0] - 1, 0)
            length[p] = min(samples[-1] + 1, num_samples - 1) - first[p] + 1
        window.append(np.arange(first[p], first[p] + length[p]))
        restart.append(np.arange(length[p]) == 0)
    window = np.concatenate(window) if window else np.zeros(0, np.int64)
    restart = np.concatenate(restart) if restart else np.zeros(0, bool)
    return PressData(
        jnp.asarray(times), jnp.asarray(travel), jnp.asarray(press), jnp.asarray(press_site), jnp.asarray(observed), jnp.asarray(weights),
        jnp.asarray(baseline), jnp.asarray(window), jnp.asarray(np.repeat(np.arange(num_presses), length)), jnp.asarray(restart),
        jnp.asarray(np.cumsum(length) - 1), num_sites,
    )


def calc_depths(data: PressData, onsets, lag):
    """(T,) δ(t) = (travel(t − lag) − onset of the sample's press)₊, 0 between presses."""
    travel = jnp.interp(data.times - lag, data.times, data.travel)
    inside = data.press >= 0
    return jnp.where(inside, jnp.maximum(travel - onsets[jnp.maximum(data.press, 0)], 0.0), 0.0)


class _Windows(eqx.Module):
    """Each press's hereditary response to its own input, by windows (one log).

    The input of press p is 0 outside its window, so its unit-modulus term
    responses are those of one recursion over the concatenated windows (`inputs`
    (W, C), `responses` (W, K, C), `derivatives` (W, K, C_d) in τ for the first C_d
    columns), then a free decay after the window's last sample: g(t) = g(end) e^{−(t
    − end)/τ} (`decay` (T, P, K), 0 up to the end), whose τ derivative is g'(end)
    e^{−(t − end)/τ} + g(end) (t − end)/τ² e^{−(t − end)/τ} (`decay_tau`). A
    quantity's value at sample t is thus its window values scattered to their
    samples plus `decay` times its values at the ends: O(W + T P K) work and memory,
    against O(T S K C) for the integral of the site-split input.
    """

    inputs: Float[Array, "num_window num_columns"]
    responses: Float[Array, "num_window num_terms num_columns"]
    derivatives: Float[Array, "num_window num_terms num_derived"]
    decay: Float[Array, "num_samples num_presses num_terms"]
    decay_tau: Float[Array, "num_samples num_presses num_terms"]

    def at_ends(self, data: PressData, values):
        """values (W, ...) at each press's last window sample (P, ...)."""
        return values[data.window_last]


def _press_windows(taus, data: PressData, values, num_derivatives: int = 0) -> _Windows:
    """:class:`_Windows` for the per-sample inputs `values` (T, C) (each sample's
    value belongs to its own press), with the τ derivatives of the first
    `num_derivatives` columns."""
    own = data.press[data.window] == data.window_press
    inputs = jnp.where(own[:, None], values[data.window], 0.0)  # (W, C)
    responses, derivatives = calc_kernel_responses_and_derivatives(
        taus, data.times[data.window], inputs, restarts=data.window_restart, with_derivatives=num_derivatives > 0
    )
    end = data.times[data.window[data.window_last]]  # (P,)
    elapsed = data.times[:, None] - end[None, :]  # (T, P)
    after = elapsed > 0.0
    scaled = jnp.where(after, elapsed, 0.0)[:, :, None] / taus[None, None, :]  # (T, P, K)
    decay = jnp.where(after[:, :, None], jnp.exp(-scaled), 0.0)
    derivatives = derivatives[:, :, :num_derivatives] if num_derivatives else jnp.zeros((*responses.shape[:2], 0), responses.dtype)
    return _Windows(inputs, responses, derivatives, decay, decay * scaled / taus[None, None, :])


def _to_sites(data: PressData, window_values, num_samples):
    """(T, S, ...) window values (W, ...) summed onto their samples at their press's site."""
    site = data.press_site[data.window_press]
    return jnp.zeros((num_samples, data.num_sites) + window_values.shape[1:], window_values.dtype).at[data.window, site].add(window_values)


def _press_site(data: PressData, dtype):
    """(P, S) which site each press is at."""
    return (data.press_site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(dtype)


def _site_bases(shape: Prony, inputs, windows: _Windows, data: PressData, num_powers: int):
    """(T, S, J) the bases from the windows of the law's columns (the first J)."""
    moduli = shape.moduli
    num_samples = inputs.shape[0]
    law = jnp.einsum("wkj,k->wj", windows.responses[:, :, :num_powers], moduli)
    ends = windows.at_ends(data, windows.responses[:, :, :num_powers]) * moduli[None, :, None]  # (P, K, J)
    by_site = jnp.einsum("pkj,ps->pksj", ends, _press_site(data, ends.dtype)).reshape(-1, data.num_sites * num_powers)
    tails = (windows.decay.reshape(num_samples, -1) @ by_site).reshape(inputs.shape)
    return shape.long_term_modulus * inputs + _to_sites(data, law, num_samples) + tails


def calc_bases(shape: Prony, depths, data: PressData):
    """(T, S, J) the bases B_{s,j}: the hereditary integrals of the powers of the
    depth, split by site (their memory runs on between presses)."""
    inputs, _, _ = _law_inputs(depths, data)
    windows = _press_windows(shape.taus, data, jnp.sum(inputs, axis=1))
    return _site_bases(shape, inputs, windows, data, inputs.shape[2])


def _assemble(bases, datas, actives):
    """The weighted columns per log [(drift (C, T, D), sites (C, T, S J), target (C,
    T))], the block offsets, and the normal matrix and right-hand side (C, N, N),
    (C, N) of the joint least-squares problem."""
    sizes = [data.baseline.shape[1] for data in datas]
    first = [sum(sizes[:k]) for k in range(len(sizes))]
    num_baseline = sum(sizes)
    _, num_sites, num_powers = bases[0].shape
    num_channels = datas[0].observed.shape[1]
    size = num_baseline + num_sites * num_powers
    normal = jnp.zeros((num_channels, size, size), bases[0].dtype)
    rhs = jnp.zeros((num_channels, size), bases[0].dtype)
    weighted = []
    for k, (basis, data, active) in enumerate(zip(bases, datas, actives)):
        weights = data.weights.T  # (C, T)
        drift = data.baseline[None, :, :] * weights[:, :, None]  # (C, T, D)
        columns = basis.reshape(basis.shape[0], -1)  # (T, S J)
        sites = columns[None, :, :] * (weights * active.T)[:, :, None]  # (C, T, S J)
        target = data.observed.T * weights  # (C, T)
        weighted.append((drift, sites, target))
        low, high = first[k], first[k] + sizes[k]
        normal = normal.at[:, low:high, low:high].set(jnp.einsum("ctd,cte->cde", drift, drift))
        cross = jnp.einsum("ctd,cts->cds", drift, sites)
        normal = normal.at[:, low:high, num_baseline:].set(cross)
        normal = normal.at[:, num_baseline:, low:high].set(jnp.transpose(cross, (0, 2, 1)))
        normal = normal.at[:, num_baseline:, num_baseline:].add(jnp.einsum("cts,ctr->csr", sites, sites))
        rhs = rhs.at[:, low:high].set(jnp.einsum("ctd,ct->cd", drift, target))
        rhs = rhs.at[:, num_baseline:].add(jnp.einsum("cts,ct->cs", sites, target))
    return weighted, (sizes, first, num_baseline), normal, rhs


def _factor(normal):
    """The Jacobi-scaled, ridged normal matrix' LU factors and the scale (C, N)."""
    diagonal = jnp.diagonal(normal, axis1=1, axis2=2)  # 0 for a site no press of the logs reaches
    used = diagonal > 0.0
    scale = jnp.where(used, jnp.sqrt(jnp.where(used, diagonal, 1.0)), 1.0)  # safe to differentiate where 0
    scaled = normal / (scale[:, :, None] * scale[:, None, :]) + RIDGE * jnp.eye(normal.shape[1])[None]
    return jax.vmap(jax.scipy.linalg.lu_factor)(scaled), scale


def _apply_inverse(factors, scale, rhs):
    """N⁻¹ rhs (C, N) with the factors of :func:`_factor`."""
    solve = jax.vmap(lambda lu, piv, b: jax.scipy.linalg.lu_solve((lu, piv), b))
    return solve(*factors, rhs / scale) / scale


def _fitted(weighted, blocks, coefficients):
    """Per log (C, T): Φ g for coefficients g (C, N)."""
    sizes, first, num_baseline = blocks
    return [
        jnp.einsum("ctd,cd->ct", drift, coefficients[:, first[k] : first[k] + sizes[k]]) + jnp.einsum("cts,cs->ct", sites, coefficients[:, num_baseline:])
        for k, (drift, sites, _) in enumerate(weighted)
    ]


def _split(coefficients, blocks, shape):
    sizes, first, num_baseline = blocks
    return [coefficients[:, first[k] : first[k] + sizes[k]] for k in range(len(sizes))], coefficients[:, num_baseline:].reshape(shape)


def solve_linear(bases, datas, actives):
    """The linear parameters given each log's bases: per channel, weighted least
    squares over every log's baseline coefficients and the amplitudes per site and
    power (shared by the logs), by the normal equations assembled block by block
    (Jacobi scaled; a tiny ridge keeps what a channel never sees at 0). `actives`
    per log (T, C): where a channel's elastic part is on (elsewhere it reads its
    baseline).

    **Returns:** (baseline coefficients per log [(C, D_l)], amplitudes (C, S, J),
    weighted residuals per log [(T_l, C)]).
    """
    drifts, amplitudes, residuals, _ = _solve_linear(bases, datas, actives)
    return drifts, amplitudes, residuals


def _solve_linear(bases, datas, actives):
    """:func:`solve_linear`, plus what its derivative reuses: (weighted columns,
    blocks, factors, scale)."""
    weighted, blocks, normal, rhs = _assemble(bases, datas, actives)
    factors, scale = _factor(normal)
    coefficients = _apply_inverse(factors, scale, rhs)
    residuals = [(target - fitted).T for (_, _, target), fitted in zip(weighted, _fitted(weighted, blocks, coefficients))]
    drifts, amplitudes = _split(coefficients, blocks, (normal.shape[0], *bases[0].shape[1:]))
    return drifts, amplitudes, residuals, (weighted, blocks, factors, scale)


def _law_inputs(depths, data: PressData):
    """(T, S, J) the site-split inputs (δ/δ_ref)^p, (T, J) their derivative in δ
    (per m), and (T, S) each sample's site."""
    powers = jnp.asarray(POWERS)
    positive = depths > 0.0
    scaled = jnp.where(positive, depths / DEPTH_SCALE, 1.0)
    law = jnp.where(positive[:, None], scaled[:, None] ** powers[None, :], 0.0)
    slope = jnp.where(positive[:, None], powers[None, :] * scaled[:, None] ** (powers[None, :] - 1.0) / DEPTH_SCALE, 0.0)
    site = jnp.where(data.press >= 0, data.press_site[jnp.maximum(data.press, 0)], -1)
    by_site = (site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(law.dtype)  # (T, S)
    return by_site[:, :, None] * law[:, None, :], slope, by_site


def _log_windows(shape: Prony, onsets, lag, data: PressData, with_lag: bool):
    """One log's bases (T, S, J), the :class:`_Windows` of the columns its
    derivatives need, and the contact (T,). Columns (J each): the law (δ/δ_ref)^p;
    its derivative in the sample's own press's onset, −∂(δ/δ_ref)^p/∂δ (∂δ/∂onset_p
    = −[press p] in contact); with `with_lag`, in the lag, −travel'(t − lag) times
    the same. ∂B/∂log gᵢ = gᵢ hᵢ and ∂B/∂log τᵢ = gᵢ τᵢ ∂hᵢ/∂τᵢ come from the law's
    term responses hᵢ."""
    depths = calc_depths(data, onsets, lag)
    inputs, slope, _ = _law_inputs(depths, data)
    num_samples, _, num_powers = inputs.shape
    columns = [jnp.sum(inputs, axis=1), -slope]  # each sample's own press's values (T, J)
    if with_lag:
        shifted = data.times - lag
        index = jnp.clip(jnp.searchsorted(data.times, shifted, side="right") - 1, 0, num_samples - 2)
        speed = (data.travel[index + 1] - data.travel[index]) / (data.times[index + 1] - data.times[index])
        speed = jnp.where((shifted > data.times[0]) & (shifted < data.times[-1]), speed, 0.0)
        columns.append(-speed[:, None] * slope)
    windows = _press_windows(shape.taus, data, jnp.concatenate(columns, axis=1), num_derivatives=num_powers)
    return _site_bases(shape, inputs, windows, data, num_powers), windows, depths > 0.0


def _shape_directions(shape: Prony, windows: _Windows, data: PressData, amplitudes, on, weighted_residual):
    """Per log, for the directions log gᵢ then log τᵢ (2K): v = −dB·A on the active
    samples (2K, C, T) and dBᵀ r (2K, C, S J), from the law's windows and their ends
    (no (T, S, J) array per direction)."""
    num_channels, num_sites, num_powers = amplitudes.shape
    moduli, taus = shape.moduli, shape.taus
    law, slope = windows.responses[:, :, :num_powers], windows.derivatives  # (W, K, J)
    ends, end_slopes = windows.at_ends(data, law), windows.at_ends(data, slope)  # (P, K, J)
    by_window = amplitudes[:, data.press_site[data.window_press], :]  # (C, W, J)
    by_press = amplitudes[:, data.press_site, :]  # (C, P, J)
    press_site = _press_site(data, law.dtype)
    window_site = press_site[data.window_press]  # (W, S)
    residual_window = weighted_residual[:, data.window]  # (C, W)
    decayed = jnp.einsum("tpk,ct->pkc", windows.decay, weighted_residual)
    decayed_tau = jnp.einsum("tpk,ct->pkc", windows.decay_tau, weighted_residual)

    def at_samples(window_part, tail):  # (K, C, W), (K, C, T) -> (K, C, T)
        return jnp.zeros(tail.shape, tail.dtype).at[:, :, data.window].add(window_part) + tail

    ratio_tail = jnp.einsum("tpk,pkc->kct", windows.decay, jnp.einsum("pkj,cpj->pkc", ends, by_press))
    ratio = at_samples(jnp.einsum("wkj,cwj->kcw", law, by_window), ratio_tail) * moduli[:, None, None]
    ends_tail = jnp.einsum("tpk,pkc->kct", windows.decay, jnp.einsum("pkj,cpj->pkc", end_slopes, by_press))
    tau_tail = ends_tail + jnp.einsum("tpk,pkc->kct", windows.decay_tau, jnp.einsum("pkj,cpj->pkc", ends, by_press))
    tau = at_samples(jnp.einsum("wkj,cwj->kcw", slope, by_window), tau_tail) * (moduli * taus)[:, None, None]
    vectors = -jnp.concatenate([ratio, tau], axis=0) * on[None]
    extra_ratio = jnp.einsum("wkj,cw,ws->kcsj", law, residual_window, window_site) + jnp.einsum("pkj,pkc,ps->kcsj", ends, decayed, press_site)
    extra_tau = (
        jnp.einsum("wkj,cw,ws->kcsj", slope, residual_window, window_site)
        + jnp.einsum("pkj,pkc,ps->kcsj", end_slopes, decayed, press_site)
        + jnp.einsum("pkj,pkc,ps->kcsj", ends, decayed_tau, press_site)
    )
    extra = jnp.concatenate([extra_ratio * moduli[:, None, None, None], extra_tau * (moduli * taus)[:, None, None, None]], axis=0)
    return vectors, extra.reshape(extra.shape[0], num_channels, num_sites * num_powers)


def _column_responses(shape: Prony, windows: _Windows, data: PressData, columns: slice):
    """The hereditary response of the given input columns in each press's window (W,
    J) and at its end per term (P, K, J), moduli applied."""
    within = shape.long_term_modulus * windows.inputs[:, columns] + jnp.einsum("wkj,k->wj", windows.responses[:, :, columns], shape.moduli)
    return within, windows.at_ends(data, windows.responses[:, :, columns]) * shape.moduli[None, :, None]


def _onset_directions(shape: Prony, windows: _Windows, data: PressData, amplitudes, on, weighted_residual, num_powers: int):
    """Per log, each press's onset direction: v (P, C, T) and dBᵀ r (P, C, J) at
    the press's own site (an onset moves only its own press's depth)."""
    within, ends = _column_responses(shape, windows, data, slice(num_powers, 2 * num_powers))
    by_window = amplitudes[:, data.press_site[data.window_press], :]  # (C, W, J)
    by_press = amplitudes[:, data.press_site, :]
    num_presses = ends.shape[0]
    num_samples = on.shape[1]
    window_part = jnp.einsum("wj,cwj->wc", within, by_window)
    at_samples = jnp.zeros((num_presses, num_samples, on.shape[0]), within.dtype).at[data.window_press, data.window].add(window_part)
    tail = jnp.einsum("tpk,pkc->pct", windows.decay, jnp.einsum("pkj,cpj->pkc", ends, by_press))
    vectors = -(jnp.transpose(at_samples, (0, 2, 1)) + tail) * on[None]
    residual_window = weighted_residual[:, data.window].T  # (W, C)
    own = jax.ops.segment_sum(within[:, None, :] * residual_window[:, :, None], data.window_press, num_segments=num_presses)  # (P, C, J)
    decayed = jnp.einsum("tpk,ct->pkc", windows.decay, weighted_residual)
    return vectors, own + jnp.einsum("pkj,pkc->pcj", ends, decayed)


def _lag_direction(shape: Prony, windows: _Windows, data: PressData, amplitudes, on, weighted_residual, num_powers: int):
    """Per log, the lag's direction: v (C, T) and dBᵀ r (C, S J)."""
    num_channels, num_sites, _ = amplitudes.shape
    within, ends = _column_responses(shape, windows, data, slice(2 * num_powers, 3 * num_powers))
    by_window = amplitudes[:, data.press_site[data.window_press], :]
    by_press = amplitudes[:, data.press_site, :]
    window_part = jnp.einsum("wj,cwj->cw", within, by_window)
    tail = jnp.einsum("tpk,pkc->ct", windows.decay, jnp.einsum("pkj,cpj->pkc", ends, by_press))
    vector = -(jnp.zeros(tail.shape, tail.dtype).at[:, data.window].add(window_part) + tail) * on
    press_site = _press_site(data, within.dtype)
    decayed = jnp.einsum("tpk,ct->pkc", windows.decay, weighted_residual)
    extra = jnp.einsum("wj,cw,ws->csj", within, weighted_residual[:, data.window], press_site[data.window_press]) + jnp.einsum("pkj,pkc,ps->csj", ends, decayed, press_site)
    return vector, extra.reshape(num_channels, num_sites * within.shape[1])


def _find_actives(bases, contact, datas):
    """Per log (T, C): where each channel's elastic part is on. The amplitudes are
    solved over the contact, then over where that solution is positive, ACTIVE_PASSES
    times; the set is piecewise constant in the parameters (no derivative)."""
    frozen = [jax.lax.stop_gradient(basis) for basis in bases]
    num_channels = datas[0].observed.shape[1]
    contact = [jnp.broadcast_to(touching[:, None], (touching.shape[0], num_channels)) for touching in contact]
    actives = contact
    for _ in range(ACTIVE_PASSES):
        _, amplitudes, _ = solve_linear(frozen, datas, actives)
        actives = [touching & (jnp.einsum("tsj,csj->tc", basis, amplitudes) > 0.0) for basis, touching in zip(frozen, contact)]
    return actives


def solve_baselines(basis, targets, used):
    """(C, D) each channel's baseline coefficients: least squares of targets (T, C)
    on the basis (T, D) over the `used` samples (T, C) (a 1e-9 ridge, relative to
    the normal matrix' mean diagonal, for a basis function no used sample reaches)."""
    weights = used.astype(basis.dtype)
    normal = jnp.einsum("td,tc,te->cde", basis, weights, basis)
    ridge = 1e-9 * jnp.trace(normal, axis1=1, axis2=2) / basis.shape[1]
    rhs = jnp.einsum("td,tc->cd", basis, weights * targets)
    return jnp.linalg.solve(normal + ridge[:, None, None] * jnp.eye(basis.shape[1])[None], rhs[:, :, None])[:, :, 0]


def calc_press_residuals(shape: Prony, onsets, lags, datas):
    """Weighted residuals of the lumped press model over the logs `datas` (a tuple of
    PressData; `onsets` a tuple of (P_l,) onsets, `lags` of lags, one per log) at the
    given nonlinear parameters, the linear ones projected out.

    A channel's elastic part is max(0, Σ A B) — the forward model's contact, which
    pushes but never pulls, with the memory of earlier presses (negative while the
    skin recovers) carried into later ones at any site. To keep the projection
    linear, the samples where it is on are found in two passes: the amplitudes
    solved over the contact (δ > 0), then again over the samples where that solution
    is positive. The set changes only where the elastic part crosses 0, so the
    residuals stay continuous in the parameters.

    **Returns:** (residuals per log [(T_l, C)], baseline coefficients per log
    [(C, D_l)], amplitudes (C, S, J)).
    """
    bases, contact = [], []
    for data, onset, lag in zip(datas, onsets, lags):
        depths = calc_depths(data, onset, lag)
        bases.append(calc_bases(shape, depths, data))
        contact.append(depths > 0.0)
    drifts, amplitudes, residuals = solve_linear(bases, datas, _find_actives(bases, contact, datas))
    return residuals, drifts, amplitudes


def calc_press_jacobian(layout: "PressLayout", x, args, linear: bool = False):
    """The flat weighted residuals (R,) and their Jacobian (R, M) in x, by hand
    (with `linear`, also the amplitudes (C, S, J) and per log the bases (T, S, J)
    and the contact (T,)).

    Variable projection's derivative (Golub and Pereyra) per direction k:
    v = −dΦ a on the active samples, da = N⁻¹ (Φᵀ v + dΦᵀ r), dr = v − Φ da (exact for
    the normal matrix N = ΦᵀΦ; the ridge is 1e-12 of it), with one solve per
    direction with N's factors. dΦ v and dΦᵀ r come from one recursion over the
    press windows (:func:`_log_windows`) and the free decays after them, never as a
    (T, S, J) array per direction; an onset moves only its own press's column: the
    whole Jacobian costs a few narrow recursions and M solves of the small normal
    matrix, not M passes of forward mode through the integrals and the
    factorisation.
    """
    datas, starts, given_lags = args
    shape, onsets, lags = layout.unpack(x, starts, given_lags)
    k = layout.num_terms
    pieces = [_log_windows(shape, onset, jnp.asarray(lag, x.dtype), data, layout.estimate_lag) for data, onset, lag in zip(datas, onsets, lags)]
    bases = [piece[0] for piece in pieces]
    actives = _find_actives(bases, [piece[2] for piece in pieces], datas)
    _, amplitudes, residuals, (weighted, blocks, factors, scale) = _solve_linear(bases, datas, actives)
    size = layout.size
    num_channels, num_sites, num_powers = amplitudes.shape
    first_onset = 2 * k
    first_lag = 2 * k + sum(layout.num_presses)
    vectors, extra = [], jnp.zeros((size, num_channels, num_sites * num_powers), x.dtype)
    for log, ((_, windows, _), data, active, residual) in enumerate(zip(pieces, datas, actives, residuals)):
        on = (data.weights * active).T  # (C, T)
        weighted_residual = on * residual.T
        num_presses = layout.num_presses[log]
        vector = jnp.zeros((size, num_channels, on.shape[1]), x.dtype)
        shape_vectors, shape_extra = _shape_directions(shape, windows, data, amplitudes, on, weighted_residual)
        vector = vector.at[: 2 * k].set(shape_vectors)
        extra = extra.at[: 2 * k].add(shape_extra)
        # chain rule through x: exp for the shape (in the directions already), tanh for onsets and lag
        onset_scale = ONSET_HALF_RANGE * (1.0 - jnp.tanh(x[first_onset : first_onset + num_presses]) ** 2)
        onset_vectors, by_press = _onset_directions(shape, windows, data, amplitudes, on, weighted_residual, num_powers)
        vector = vector.at[first_onset : first_onset + num_presses].set(onset_vectors * onset_scale[:, None, None])
        press_site = _press_site(data, x.dtype)  # (P, S)
        by_press = by_press * onset_scale[:, None, None]
        extra = extra.at[first_onset : first_onset + num_presses].add((by_press[:, :, None, :] * press_site[:, None, :, None]).reshape(num_presses, num_channels, -1))
        if layout.estimate_lag:
            lag_scale = LAG_BOUND * (1.0 - jnp.tanh(x[first_lag + log]) ** 2)
            lag_vector, lag_extra = _lag_direction(shape, windows, data, amplitudes, on, weighted_residual, num_powers)
            vector = vector.at[first_lag + log].set(lag_vector * lag_scale)
            extra = extra.at[first_lag + log].add(lag_extra * lag_scale)
        vectors.append(vector)
        first_onset += num_presses
    sizes, first, num_baseline = blocks
    rhs = jnp.zeros((size, num_channels, num_baseline + num_sites * num_powers), x.dtype)
    for log, ((drift, sites, _), vector) in enumerate(zip(weighted, vectors)):
        rhs = rhs.at[:, :, first[log] : first[log] + sizes[log]].set(jnp.einsum("ctd,mct->mcd", drift, vector))
        rhs = rhs.at[:, :, num_baseline:].add(jnp.einsum("cts,mct->mcs", sites, vector))
    rhs = rhs.at[:, :, num_baseline:].add(extra)
    step = jax.vmap(_apply_inverse, in_axes=(None, None, 0))(factors, scale, rhs)  # (M, C, N)
    columns = []
    for log, ((drift, sites, _), vector) in enumerate(zip(weighted, vectors)):
        fitted = jnp.einsum("ctd,mcd->mct", drift, step[:, :, first[log] : first[log] + sizes[log]]) + jnp.einsum("cts,mcs->mct", sites, step[:, :, num_baseline:])
        columns.append(jnp.transpose(vector - fitted, (2, 1, 0)).reshape(-1, size))
    value, jacobian = jnp.concatenate([r.reshape(-1) for r in residuals]), jnp.concatenate(columns, axis=0)
    return (value, jacobian, amplitudes, bases, [piece[2] for piece in pieces]) if linear else (value, jacobian)


def calc_press_predictions(shape: Prony, onsets, lag, baseline_coefficients, amplitudes, data: PressData):
    """(T, C) one log's readings for given linear parameters (baseline (C, D),
    amplitudes (C, S, J)): the baseline plus max(0, Σ A B) in contact."""
    depths = calc_depths(data, onsets, lag)
    elastic = jnp.einsum("tsj,csj->tc", calc_bases(shape, depths, data), amplitudes)
    return data.baseline @ baseline_coefficients.T + jnp.where((depths > 0.0)[:, None], jnp.maximum(elastic, 0.0), 0.0)


ONSET_HALF_RANGE = 0.5e-3  # m: a press's onset stays within this of its start value
LAG_BOUND = 0.5  # s: an estimated lag stays within ±this


class PressLayout(eqx.Module):
    """Where the nonlinear parameters sit in x (static): log Eᵢ/E∞ (K), log τᵢ (K),
    each log's onsets' unbounded coordinates (P_l), and each log's lag's (1 per log,
    when estimated)."""

    num_terms: int = eqx.field(static=True)
    num_presses: tuple[int, ...] = eqx.field(static=True)
    estimate_lag: bool = eqx.field(static=True)

    @property
    def size(self) -> int:
        return 2 * self.num_terms + sum(self.num_presses) + len(self.num_presses) * int(self.estimate_lag)

    def unpack(self, x, onset_starts, lags):
        """(shape, onsets per log, lags per log) from x; `onset_starts` the centres of
        the onsets' ranges, `lags` the lags when they are not estimated."""
        k = self.num_terms
        shape = Prony(jnp.ones((), x.dtype), jnp.exp(x[:k]), jnp.exp(x[k : 2 * k]))
        first = 2 * k
        onsets = []
        for count, start in zip(self.num_presses, onset_starts):
            onsets.append(start + ONSET_HALF_RANGE * jnp.tanh(x[first : first + count]))
            first += count
        if self.estimate_lag:
            lags = tuple(LAG_BOUND * jnp.tanh(x[first + log]) for log in range(len(self.num_presses)))
        return shape, tuple(onsets), tuple(lags)


def press_residual_fn(layout: PressLayout):
    """x, (datas, onset_starts, lags) -> the flat weighted residuals (for optimistix),
    differentiated in x by :func:`calc_press_jacobian` (not in the data)."""

    @jax.custom_jvp
    def residuals(x, args):
        datas, onset_starts, lags = args
        per_log = calc_press_residuals(*layout.unpack(x, onset_starts, lags), datas)[0]
        return jnp.concatenate([r.reshape(-1) for r in per_log])

    @residuals.defjvp
    def _residuals_jvp(primals, tangents):
        x, args = primals
        value, jacobian = calc_press_jacobian(layout, x, args)
        return value, jacobian @ tangents[0]

    return residuals
