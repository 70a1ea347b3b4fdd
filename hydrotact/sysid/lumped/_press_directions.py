"""The press fit's Jacobian directions, per log (pure): for each nonlinear parameter,
−dB·A on the active samples and dBᵀ r, contracted from the press windows and their
free decays (:class:`._press_windows.PressWindows`), never as a (T, S, J) array per
direction. :func:`._lumped.calc_press_jacobian` projects them (Golub and Pereyra).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..._types import Array
from ...visco import Prony
from ._press_windows import PressData, PressWindows, press_site_matrix


class LogTerms(NamedTuple):
    """What every direction of one log uses, computed once per Jacobian: `on` (C, T)
    the weights on the active samples, `amplitudes` (C, S, J) and per window sample
    (C, W, J) and per press (C, P, J), `press_site` (P, S), the weighted residual
    (C, T) and at the window samples (C, W), and its decayed sums per press (P, K,
    C)."""

    on: Array
    amplitudes: Array
    by_window: Array
    by_press: Array
    press_site: Array
    weighted_residual: Array
    residual_window: Array
    decayed: Array


def make_log_terms(windows: PressWindows, data: PressData, amplitudes, on, residual) -> LogTerms:
    """:class:`LogTerms` of one log from its windows, amplitudes (C, S, J), active
    weights `on` (C, T) and projected residuals (T, C)."""
    weighted_residual = on * residual.T
    return LogTerms(
        on, amplitudes, amplitudes[:, data.press_site[data.window_press], :], amplitudes[:, data.press_site, :], press_site_matrix(data, amplitudes.dtype),
        weighted_residual, weighted_residual[:, data.window], jnp.einsum("tpk,ct->pkc", windows.decay, weighted_residual),
    )


def shape_directions(shape: Prony, windows: PressWindows, data: PressData, terms: LogTerms):
    """Per log, for the directions log gᵢ then log τᵢ (2K): v = −dB·A on the active
    samples (2K, C, T) and dBᵀ r (2K, C, S J), from the law's windows and their ends
    (no (T, S, J) array per direction)."""
    num_channels, num_sites, num_powers = terms.amplitudes.shape
    moduli, taus = shape.moduli, shape.taus
    law, slope = windows.responses[:, :, :num_powers], windows.derivatives  # (W, K, J)
    ends, end_slopes = windows.at_ends(data, law), windows.at_ends(data, slope)  # (P, K, J)
    by_window, by_press, press_site, residual_window, decayed = terms.by_window, terms.by_press, terms.press_site, terms.residual_window, terms.decayed
    window_site = press_site[data.window_press]  # (W, S)
    decayed_tau = jnp.einsum("tpk,ct->pkc", windows.decay_tau, terms.weighted_residual)

    def at_samples(window_part, tail):  # (K, C, W), (K, C, T) -> (K, C, T)
        return jnp.zeros(tail.shape, tail.dtype).at[:, :, data.window].add(window_part) + tail

    ratio_tail = jnp.einsum("tpk,pkc->kct", windows.decay, jnp.einsum("pkj,cpj->pkc", ends, by_press))
    ratio = at_samples(jnp.einsum("wkj,cwj->kcw", law, by_window), ratio_tail) * moduli[:, None, None]
    ends_tail = jnp.einsum("tpk,pkc->kct", windows.decay, jnp.einsum("pkj,cpj->pkc", end_slopes, by_press))
    tau_tail = ends_tail + jnp.einsum("tpk,pkc->kct", windows.decay_tau, jnp.einsum("pkj,cpj->pkc", ends, by_press))
    tau = at_samples(jnp.einsum("wkj,cwj->kcw", slope, by_window), tau_tail) * (moduli * taus)[:, None, None]
    vectors = -jnp.concatenate([ratio, tau], axis=0) * terms.on[None]
    extra_ratio = jnp.einsum("wkj,cw,ws->kcsj", law, residual_window, window_site) + jnp.einsum("pkj,pkc,ps->kcsj", ends, decayed, press_site)
    extra_tau = (
        jnp.einsum("wkj,cw,ws->kcsj", slope, residual_window, window_site)
        + jnp.einsum("pkj,pkc,ps->kcsj", end_slopes, decayed, press_site)
        + jnp.einsum("pkj,pkc,ps->kcsj", ends, decayed_tau, press_site)
    )
    extra = jnp.concatenate([extra_ratio * moduli[:, None, None, None], extra_tau * (moduli * taus)[:, None, None, None]], axis=0)
    return vectors, extra.reshape(extra.shape[0], num_channels, num_sites * num_powers)


def _column_responses(shape: Prony, windows: PressWindows, data: PressData, columns: slice):
    """The hereditary response of the given input columns in each press's window (W,
    J) and at its end per term (P, K, J), moduli applied."""
    within = shape.long_term_modulus * windows.inputs[:, columns] + jnp.einsum("wkj,k->wj", windows.responses[:, :, columns], shape.moduli)
    return within, windows.at_ends(data, windows.responses[:, :, columns]) * shape.moduli[None, :, None]


def onset_directions(shape: Prony, windows: PressWindows, data: PressData, terms: LogTerms):
    """Per log, each press's onset direction: v (P, C, T) and dBᵀ r (P, C, J) at
    the press's own site (an onset moves only its own press's depth)."""
    num_powers = terms.amplitudes.shape[2]
    within, ends = _column_responses(shape, windows, data, slice(num_powers, 2 * num_powers))
    num_presses = ends.shape[0]
    num_channels, num_samples = terms.on.shape
    window_part = jnp.einsum("wj,cwj->wc", within, terms.by_window)
    at_samples = jnp.zeros((num_presses, num_samples, num_channels), within.dtype).at[data.window_press, data.window].add(window_part)
    tail = jnp.einsum("tpk,pkc->pct", windows.decay, jnp.einsum("pkj,cpj->pkc", ends, terms.by_press))
    vectors = -(jnp.transpose(at_samples, (0, 2, 1)) + tail) * terms.on[None]
    own = jax.ops.segment_sum(within[:, None, :] * terms.residual_window.T[:, :, None], data.window_press, num_segments=num_presses)  # (P, C, J)
    return vectors, own + jnp.einsum("pkj,pkc->pcj", ends, terms.decayed)


def lag_direction(shape: Prony, windows: PressWindows, data: PressData, terms: LogTerms):
    """Per log, the lag's direction: v (C, T) and dBᵀ r (C, S J)."""
    num_channels, num_sites, num_powers = terms.amplitudes.shape
    within, ends = _column_responses(shape, windows, data, slice(2 * num_powers, 3 * num_powers))
    window_part = jnp.einsum("wj,cwj->cw", within, terms.by_window)
    tail = jnp.einsum("tpk,pkc->ct", windows.decay, jnp.einsum("pkj,cpj->pkc", ends, terms.by_press))
    vector = -(jnp.zeros(tail.shape, tail.dtype).at[:, data.window].add(window_part) + tail) * terms.on
    press_site = terms.press_site
    extra = jnp.einsum("wj,cw,ws->csj", within, terms.residual_window, press_site[data.window_press]) + jnp.einsum("pkj,pkc,ps->csj", ends, terms.decayed, press_site)
    return vector, extra.reshape(num_channels, num_sites * within.shape[1])
