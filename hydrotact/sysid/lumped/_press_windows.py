"""The lumped press model's data and bases (pure): a log's arrays with each press's
window, the law's site-split inputs, and their hereditary integrals by press windows.

The model itself is described in :mod:`._lumped`; this module computes its bases
B_{s,j}(t) and the windows the Jacobian's directions are built from.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._types import Array, Bool, Float, Int
from ...visco import Prony, calc_kernel_responses_and_derivatives

DEPTH_SCALE = 1e-3  # m: δ is measured in millimetres in the law (amplitudes in Pa at 1 mm)
POWERS = (1.5, 2.0, 2.5, 3.0)  # the law's powers of the depth (from Hertz's 1.5 up: see hydrotact.sysid.lumped._lumped)
# How a law goes on past the deepest depth it was fitted to: the power of the depth a
# sphere's contact force grows with in the hydroelastic model (Hertz's is 1.5). Past
# a held-out press's reach, 1.5 and 2 predicted the test stand-in's 0.6 mm presses
# from a fit of its 0.35 mm ones to 24-43 and 21-34 Pa and the MTL strip's 6 mm log from
# its 5 mm ones to 1,123 and 1,040 Pa pooled (1 and 3: 2,298 and 1,409 Pa; the fitted
# powers at any depth: 25-110 Pa and 5,054 Pa).
CONTINUATION_POWER = 2.0


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
    `window_last` (P,) where its window ends in the concatenation. `responds` (C, S)
    where a channel's law is fitted (elsewhere it is 0; the same for all the logs of
    a fit). `drift_from` (static) "all": each baseline is fitted jointly with the
    amplitudes over every sample; "unloaded": from the samples out of contact alone.
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
    responds: Bool[Array, "num_channels num_sites"]
    num_sites: int = eqx.field(static=True)
    drift_from: str = eqx.field(static=True, default="all")


def make_press_data(times, travel, press, press_site, observed, weights, baseline, num_sites: int, responds=None, drift_from="all") -> PressData:
    """A :class:`PressData` from host arrays (as its fields; `responds` all True
    unless given), its press windows found here: press p's input is 0 outside (first − 1, last + 1) of its samples
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
        jnp.asarray(np.cumsum(length) - 1),
        jnp.asarray(np.ones((np.shape(observed)[1], num_sites), bool) if responds is None else np.asarray(responds, bool)), num_sites,
        drift_from,
    )


def calc_depths(data: PressData, onsets, lag):
    """(T,) δ(t) = (travel(t − lag) − onset of the sample's press)₊, 0 between presses."""
    travel = jnp.interp(data.times - lag, data.times, data.travel)
    inside = data.press >= 0
    return jnp.where(inside, jnp.maximum(travel - onsets[jnp.maximum(data.press, 0)], 0.0), 0.0)


class PressWindows(eqx.Module):
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


def _press_windows(taus, data: PressData, values, num_derivatives: int = 0, decay=None) -> PressWindows:
    """:class:`PressWindows` for the per-sample inputs `values` (T, C) (each sample's
    value belongs to its own press), with the τ derivatives of the first
    `num_derivatives` columns; `decay` the windows' (:func:`window_decay`) where the
    caller has it (then `decay_tau` is not computed: None)."""
    own = data.press[data.window] == data.window_press
    inputs = jnp.where(own[:, None], values[data.window], 0.0)  # (W, C)
    responses, derivatives = calc_kernel_responses_and_derivatives(
        taus, data.times[data.window], inputs, restarts=data.window_restart, with_derivatives=num_derivatives > 0
    )
    derivatives = derivatives[:, :, :num_derivatives] if num_derivatives else jnp.zeros((*responses.shape[:2], 0), responses.dtype)
    if decay is not None:
        return PressWindows(inputs, responses, derivatives, decay, None)
    decay, scaled = window_decay(taus, data)
    return PressWindows(inputs, responses, derivatives, decay, decay * scaled / taus[None, None, :])


def window_decay(taus, data: PressData):
    """(T, P, K) each term's free decay after each press's window, e^{−(t − end)/τ}
    (0 up to the end), and (t − end)₊/τ: they depend on the relaxation's τ and the
    windows, not on the onsets or the inputs."""
    end = data.times[data.window[data.window_last]]  # (P,)
    elapsed = data.times[:, None] - end[None, :]  # (T, P)
    after = elapsed > 0.0
    scaled = jnp.where(after, elapsed, 0.0)[:, :, None] / taus[None, None, :]  # (T, P, K)
    return jnp.where(after[:, :, None], jnp.exp(-scaled), 0.0), scaled


def _to_sites(data: PressData, window_values, num_samples):
    """(T, S, ...) window values (W, ...) summed onto their samples at their press's site."""
    site = data.press_site[data.window_press]
    return jnp.zeros((num_samples, data.num_sites) + window_values.shape[1:], window_values.dtype).at[data.window, site].add(window_values)


def press_site_matrix(data: PressData, dtype):
    """(P, S) which site each press is at."""
    return (data.press_site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(dtype)


def _site_bases(shape: Prony, inputs, windows: PressWindows, data: PressData, num_powers: int):
    """(T, S, J) the bases from the windows of the law's columns (the first J)."""
    moduli = shape.moduli
    num_samples = inputs.shape[0]
    law = jnp.einsum("wkj,k->wj", windows.responses[:, :, :num_powers], moduli)
    ends = windows.at_ends(data, windows.responses[:, :, :num_powers]) * moduli[None, :, None]  # (P, K, J)
    by_site = jnp.einsum("pkj,ps->pksj", ends, press_site_matrix(data, ends.dtype)).reshape(-1, data.num_sites * num_powers)
    tails = (windows.decay.reshape(num_samples, -1) @ by_site).reshape(inputs.shape)
    return shape.long_term_modulus * inputs + _to_sites(data, law, num_samples) + tails


def calc_bases(shape: Prony, depths, data: PressData, reach=None):
    """(T, S, J) the bases B_{s,j}: the hereditary integrals of the powers of the
    depth, split by site (their memory runs on between presses); with `reach` (S,),
    of the powers continued past it (see :func:`_law_inputs`)."""
    inputs, _, _ = _law_inputs(depths, data, reach)
    windows = _press_windows(shape.taus, data, jnp.sum(inputs, axis=1))
    return _site_bases(shape, inputs, windows, data, inputs.shape[2])


def calc_site_bases(shape: Prony, depths, data: PressData, site, decay):
    """(T, J) one site's bases, ``calc_bases(shape, depths, data)[:, site]``, given the
    windows' `decay` (:func:`window_decay`, for shape's τ): a scan of one site's
    onsets computes the decay once, and each shift only that site's hereditary
    integrals (J columns, the tails J, not S J)."""
    inputs, _, _ = _law_inputs(depths, data)
    own = inputs[:, site, :]  # (T, J): 0 outside the site's presses
    num_samples, num_powers = own.shape
    windows = _press_windows(shape.taus, data, own, decay=decay)
    law = jnp.einsum("wkj,k->wj", windows.responses, shape.moduli)
    ends = windows.at_ends(data, windows.responses) * shape.moduli[None, :, None]  # (P, K, J)
    tails = decay.reshape(num_samples, -1) @ ends.reshape(-1, num_powers)
    return shape.long_term_modulus * own + jnp.zeros((num_samples, num_powers), own.dtype).at[data.window].add(law) + tails


def _law_inputs(depths, data: PressData, reach=None):
    """(T, S, J) the site-split inputs (δ/δ_ref)^p, (T, J) their derivative in δ
    (per m), and (T, S) each sample's site.

    With `reach` (S,), the deepest depth each site's law was fitted to (a held-out
    log's presses may go deeper), each input continues past its site's reach δ_m as
    its value there scaled as a contact force grows, (δ_m/δ_ref)^p (δ/δ_m)^p_c
    (p_c = CONTINUATION_POWER): a law whose reading at δ_m is a hold's, the best
    measured of its values, goes on with the sign it has there, whatever its fitted
    powers do past their range (sums of powers of both signs, they go anywhere) or
    their slope at its end (a tangent there follows the loading ramp's last samples,
    and on the test stand-in extrapolated worse). The slope returned is the fit's
    (no reach)."""
    powers = jnp.asarray(POWERS)
    positive = depths > 0.0
    site = jnp.where(data.press >= 0, data.press_site[jnp.maximum(data.press, 0)], -1)
    by_site = (site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(depths.dtype)  # (T, S)
    scaled = jnp.where(positive, depths / DEPTH_SCALE, 1.0)
    slope = jnp.where(positive[:, None], powers[None, :] * scaled[:, None] ** (powers[None, :] - 1.0) / DEPTH_SCALE, 0.0)
    if reach is None:
        law = scaled[:, None] ** powers[None, :]
    else:
        limit = by_site @ reach  # (T,) the reach of each sample's site (0 between presses)
        beyond = positive & (depths > limit) & (limit > 0.0)
        held = jnp.where(beyond, limit / DEPTH_SCALE, scaled)
        ratio = jnp.where(beyond, depths / jnp.where(beyond, limit, 1.0), 1.0)
        law = held[:, None] ** powers[None, :] * (ratio**CONTINUATION_POWER)[:, None]
    law = jnp.where(positive[:, None], law, 0.0)
    return by_site[:, :, None] * law[:, None, :], slope, by_site


def log_windows(shape: Prony, onsets, lag, data: PressData, with_lag: bool):
    """One log's bases (T, S, J), the :class:`PressWindows` of the columns its
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
