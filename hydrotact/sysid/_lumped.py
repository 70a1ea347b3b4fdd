"""The lumped model for stage logs where the probe moves between presses (pure).

For a sensor nobody has modelled, each channel c of a log is

    reading_c(t) = offset_c + drift_c · t̃ + Σ_s A_{c,s} · B_{c,s}(t)

with one basis per site s,

    B_{c,s}(t) = [δ(t) > 0] · H(E / E∞, g_c · [site(t) = s])(t),
    g_c(t) = (δ(t) / δ_ref)^{b_c},   δ(t) = (travel(t − lag) − onset_{press(t)})₊,

where H is the hereditary integral (:func:`hydrotact.visco.calc_hereditary_integral`)
with the Prony series' shape (E∞ ≡ 1: only Eᵢ/E∞ and τᵢ are identifiable without a
model of the skin), `travel` the stage's travel towards the skin, `onset_p` the travel
at which press p's contact starts, `b_c` the channel's exponent and `A_{c,s}` its
amplitude at the site (Pa). The residual stress of earlier presses carries into later
ones through H. The basis is masked to the contact (δ > 0) rather than clipped at zero
like :func:`hydrotact.visco.calc_contact_response`, so that the readings stay linear
in the amplitudes; the two differ only where an earlier press's recovery outweighs a
new press's first samples.

The amplitudes, offsets and drifts enter linearly: for given nonlinear parameters
(shape, exponents, onsets, lag) they are solved per channel by weighted least squares
inside the residual (variable projection, Golub and Pereyra), so the outer solver
only sees the few nonlinear parameters, and their Jacobian (by autodiff through the
solve) is the exact one of the projected problem.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._types import Array, Float, Int
from ..visco import Prony, calc_hereditary_integral

DEPTH_SCALE = 1e-3  # m: δ is measured in millimetres in the power law (amplitudes in Pa at 1 mm)
EXPONENT_RANGE = (0.8, 3.0)  # flat punch 1, Hertz 1.5, cone 2; beyond 3 no contact law we know
RIDGE = 1e-12  # relative to the normal matrix' diagonal: keeps an unused site's amplitude at 0


class PressData(eqx.Module):
    """One log for the lumped press model (device arrays).

    **Fields:** `times` (T,) s; `travel` (T,) m; `press` (T,) the press of each
    sample (-1 between presses); `press_site` (P,) the site of each press;
    `observed` (T, C) Pa; `weights` (T, C) 1 / noise, 0 for masked samples;
    `num_sites` (static); `with_drift` (static) whether each channel has a linear drift.
    """

    times: Float[Array, " num_samples"]
    travel: Float[Array, " num_samples"]
    press: Int[Array, " num_samples"]
    press_site: Int[Array, " num_presses"]
    observed: Float[Array, "num_samples num_channels"]
    weights: Float[Array, "num_samples num_channels"]
    num_sites: int = eqx.field(static=True)
    with_drift: bool = eqx.field(static=True)


def bounded(z, low, high):
    """low + (high − low) · sigmoid(z): an unconstrained z onto (low, high)."""
    return low + (high - low) * jax.nn.sigmoid(z)


def calc_depths(data: PressData, onsets, lag):
    """(T,) δ(t) = (travel(t − lag) − onset of the sample's press)₊, 0 between presses."""
    travel = jnp.interp(data.times - lag, data.times, data.travel)
    inside = data.press >= 0
    return jnp.where(inside, jnp.maximum(travel - onsets[jnp.maximum(data.press, 0)], 0.0), 0.0)


def calc_bases(shape: Prony, exponents, depths, data: PressData):
    """(T, C, S) the bases B_{c,s}: per channel the power law of the depth, split by
    site, through the hereditary integral, masked to the contact."""
    positive = depths > 0.0
    log_depth = jnp.log(jnp.where(positive, depths / DEPTH_SCALE, 1.0))
    law = jnp.where(positive[:, None], jnp.exp(log_depth[:, None] * exponents[None, :]), 0.0)  # (T, C)
    site = jnp.where(data.press >= 0, data.press_site[jnp.maximum(data.press, 0)], -1)
    by_site = (site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(law.dtype)  # (T, S)
    inputs = law[:, :, None] * by_site[:, None, :]
    responses = calc_hereditary_integral(shape, data.times, inputs)
    return jnp.where(positive[:, None, None], responses, 0.0)


def _design(bases, data: PressData):
    """(C, T, 1 [+ 1] + S) each channel's design matrix: offset, [drift,] bases."""
    num_samples, num_channels, _ = bases.shape
    columns = [jnp.ones((num_channels, num_samples, 1), bases.dtype)]
    if data.with_drift:
        span = jnp.maximum(data.times[-1] - data.times[0], 1e-300)
        scaled = 2.0 * (data.times - data.times[0]) / span - 1.0
        columns.append(jnp.broadcast_to(scaled[None, :, None], (num_channels, num_samples, 1)))
    columns.append(jnp.transpose(bases, (1, 0, 2)))
    return jnp.concatenate(columns, axis=2)


def solve_linear(bases, data: PressData):
    """The linear parameters given the bases: per channel, weighted least squares
    over [offset, (drift,) amplitudes per site] by the normal equations (a tiny ridge
    keeps a site a channel never sees at 0).

    **Returns:** (coefficients (C, 1 [+ 1] + S), weighted residuals (T, C)).
    """
    design = _design(bases, data)  # (C, T, N)
    weights = data.weights.T  # (C, T)
    weighted = design * weights[:, :, None]
    target = (data.observed.T * weights)[:, :, None]  # (C, T, 1)
    normal = jnp.einsum("ctn,ctm->cnm", weighted, weighted)
    scale = jnp.sqrt(jnp.maximum(jnp.diagonal(normal, axis1=1, axis2=2), 1e-300))  # (C, N)
    scaled = normal / (scale[:, :, None] * scale[:, None, :]) + RIDGE * jnp.eye(normal.shape[1])[None]
    rhs = jnp.einsum("ctn,ctk->cnk", weighted, target)[..., 0] / scale
    coefficients = jnp.linalg.solve(scaled, rhs[..., None])[..., 0] / scale
    residuals = target[..., 0] - jnp.einsum("ctn,cn->ct", weighted, coefficients)
    return coefficients, residuals.T


def calc_press_residuals(shape: Prony, exponents, onsets, lag, data: PressData):
    """Weighted residuals (T, C) of the lumped press model at the given nonlinear
    parameters, the linear ones projected out; and the linear coefficients."""
    bases = calc_bases(shape, exponents, calc_depths(data, onsets, lag), data)
    coefficients, residuals = solve_linear(bases, data)
    return residuals, coefficients


def calc_press_predictions(shape: Prony, exponents, onsets, lag, coefficients, data: PressData):
    """(T, C) the model's readings for given linear coefficients (a held-out log's
    prediction, with the amplitudes of a fit)."""
    bases = calc_bases(shape, exponents, calc_depths(data, onsets, lag), data)
    return jnp.einsum("ctn,cn->tc", _design(bases, data), coefficients)


ONSET_HALF_RANGE = 0.3e-3  # m: a press's onset stays within this of its start value
LAG_BOUND = 0.5  # s: an estimated lag stays within ±this


class PressLayout(eqx.Module):
    """Where the nonlinear parameters sit in x (static): log Eᵢ/E∞ (K), log τᵢ (K),
    the exponents' unbounded coordinates (C), the onsets' (P), and the lag's (1, when
    estimated)."""

    num_terms: int = eqx.field(static=True)
    num_channels: int = eqx.field(static=True)
    num_presses: int = eqx.field(static=True)
    estimate_lag: bool = eqx.field(static=True)

    @property
    def size(self) -> int:
        return 2 * self.num_terms + self.num_channels + self.num_presses + int(self.estimate_lag)

    def unpack(self, x, onset_start, lag):
        """(shape, exponents, onsets, lag) from x."""
        k, c, p = self.num_terms, self.num_channels, self.num_presses
        shape = Prony(jnp.ones((), x.dtype), jnp.exp(x[:k]), jnp.exp(x[k : 2 * k]))
        exponents = bounded(x[2 * k : 2 * k + c], *EXPONENT_RANGE)
        onsets = onset_start + ONSET_HALF_RANGE * jnp.tanh(x[2 * k + c : 2 * k + c + p])
        if self.estimate_lag:
            lag = LAG_BOUND * jnp.tanh(x[-1])
        return shape, exponents, onsets, lag


def press_residual_fn(layout: PressLayout):
    """x, (data, onset_start, lag) -> the flat weighted residuals (for optimistix)."""

    def residuals(x, args):
        data, onset_start, lag = args
        return calc_press_residuals(*layout.unpack(x, onset_start, lag), data)[0].reshape(-1)

    return residuals
