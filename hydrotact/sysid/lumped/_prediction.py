"""A lumped press fit's channel law as the model of a held-out log (`hydrotact compare`):
its prediction for given amplitudes and home shift, the estimate of the stage's home
shift (a grid, then Levenberg-Marquardt), and the variances of the prediction band
that come from the tare and from the fit's parameters. See :mod:`._compare`."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...visco import Prony
from ..shared import make_solver, solve_least_squares
from ._lumped import ONSET_HALF_RANGE
from ._press_projection import calc_elastic, solve_baselines
from ._press_windows import PressData, calc_bases, calc_depths

UNLIMITED_REACH_M = 1.0  # a law's reach where the fit recorded none: no stage press goes a metre deep
HOME_GRID = 41  # shifts over ±ONSET_HALF_RANGE tried before the home shift is polished


def _law_prony(document) -> Prony:
    terms = document["prony_terms"]
    return Prony(
        jnp.asarray(float(document["long_term_modulus_Pa"]["value"])),
        jnp.asarray([float(t["modulus_Pa"]["value"]) for t in terms]),
        jnp.asarray([float(t["tau_s"]["value"]) for t in terms]),
    )


class _LawModel(eqx.Module):
    """A log's elastic part as a function of the law's parameters q (log Eᵢ/E∞, log
    τᵢ, the sites' onsets, the lag: the order of the fit's covariance), the
    amplitudes (C, S, J) and a shift of every onset (the home's); each site's law
    continued past its `reach` (S,) as :func:`._press_windows._law_inputs` says.
    Build it with :func:`_make_law_model`."""

    data: PressData
    q: jax.Array
    press_onsets: jax.Array
    site_ids: jax.Array
    reach: jax.Array
    long_term: float = eqx.field(static=True)
    num_terms: int = eqx.field(static=True)

    def elastic(self, q, amplitudes, shift, with_bases=False):
        k, num_sites = self.num_terms, self.data.num_sites
        shape = Prony(jnp.asarray(self.long_term), self.long_term * jnp.exp(q[:k]), jnp.exp(q[k : 2 * k]))
        # A fitted log's own onsets (or the sites'), moved as q moves its sites' onsets.
        onsets = self.press_onsets + (q[2 * k : 2 * k + num_sites] - self.q[2 * k : 2 * k + num_sites])[self.site_ids] + shift
        depths = calc_depths(self.data, onsets, q[-1])
        bases = calc_bases(shape, depths, self.data, self.reach)
        elastic = calc_elastic(bases, depths > 0.0, amplitudes)
        return (elastic, bases, depths > 0.0) if with_bases else elastic


def _make_law_model(document, data, press_onsets, site_ids, lag) -> _LawModel:
    """The model of a log (`data`) from a fit's material document; a site without a
    recorded reach (a fit written before it) keeps its law as fitted at any depth."""
    prony = _law_prony(document)
    long_term = float(prony.long_term_modulus)
    sites = document["channel_law"]["sites"]
    site_onsets = jnp.asarray([site["onset_m"] for site in sites], dtype=jnp.float64)
    reach = jnp.asarray([site.get("reach_m", UNLIMITED_REACH_M) for site in sites], dtype=jnp.float64)
    q = jnp.concatenate([jnp.log(prony.moduli / long_term), jnp.log(prony.taus), site_onsets, jnp.asarray([lag], dtype=jnp.float64)])
    return _LawModel(data, q, jnp.asarray(press_onsets, dtype=jnp.float64), jnp.asarray(site_ids), reach, long_term, len(prony.taus))


@eqx.filter_jit
def _predict(model, amplitudes, shift):
    """At the fit's q: the elastic part (T, C), the bases (T, S, J), the contact (T,),
    and the derivatives of the elastic part in q (T, C, Q) and in the shift (T, C)."""
    elastic, bases, touching = model.elastic(model.q, amplitudes, shift, with_bases=True)
    by_q = jax.jacfwd(lambda q: model.elastic(q, amplitudes, shift))(model.q)
    by_shift = jax.jacfwd(lambda h: model.elastic(model.q, amplitudes, h))(shift)
    return elastic, bases, touching, by_q, by_shift


def _home_residuals(shift, args):
    """The log's weighted residuals for a shift of its onsets, each channel's
    baseline solved with it."""
    model, amplitudes, basis, observed, used, weights = args
    elastic = model.elastic(model.q, amplitudes, shift)
    coefficients = solve_baselines(basis, observed - elastic, used)
    return ((observed - elastic - basis @ coefficients.T) * weights).reshape(-1)


@eqx.filter_jit
def _fit_home(args):
    """(shift, χ², Jᵀ J): the best of HOME_GRID shifts within ±ONSET_HALF_RANGE,
    polished by Levenberg-Marquardt (the shift = ONSET_HALF_RANGE tanh(u), as the
    fit's onsets)."""
    grid = jnp.linspace(-0.98, 0.98, HOME_GRID) * ONSET_HALF_RANGE
    values = jax.lax.map(lambda shift: jnp.sum(_home_residuals(shift, args) ** 2), grid)
    start = jnp.arctanh(grid[jnp.argmin(values)] / ONSET_HALF_RANGE)

    def residuals(u, args):
        return _home_residuals(ONSET_HALF_RANGE * jnp.tanh(u), args)

    solution = solve_least_squares(residuals, start, args, make_solver("lm"), max_steps=50, throw=False)
    shift = ONSET_HALF_RANGE * jnp.tanh(solution.value)
    derivative = jax.jacfwd(_home_residuals)(shift, args)
    return shift, jnp.sum(_home_residuals(shift, args) ** 2), derivative @ derivative


def _estimate_home(model, amplitudes, basis, observed, mask, noise):
    """(shift, its variance): the shift of every onset that best fits the log (see
    :func:`_fit_home`). The variance is Gauss-Newton's, scaled by the reduced χ²
    where it exceeds 1, given the fit (the fit's own errors are in the band, not
    here)."""
    weights = jnp.where(jnp.asarray(mask), 1.0 / jnp.asarray(noise)[None, :], 0.0)
    shift, chi_square, curvature = _fit_home((model, amplitudes, jnp.asarray(basis), jnp.asarray(observed), jnp.asarray(mask), weights))
    dof = max(int(mask.sum()) - basis.shape[1] * observed.shape[1] - 1, 1)
    return float(shift), max(float(chi_square) / dof, 1.0) / max(float(curvature), 1e-300)


def _tare_variance(basis, used, noise):
    """(T, C) the variance the tare's noise adds to each sample's prediction: the
    baseline's least squares over the `used` samples (T, C) of each channel."""
    variance = np.zeros(used.shape)
    for c in range(used.shape[1]):
        rows = basis[used[:, c]]
        if len(rows):
            inverse = np.linalg.pinv(rows.T @ rows)
            variance[:, c] = noise[c] ** 2 * np.einsum("td,de,te->t", basis, inverse, basis)
    return variance


def _parameter_variance(dq, dh, shift_var, covariance, bases, touching, elastic, all_basis, mask):
    """(T, C) the variance the fit's parameters (q and the amplitudes, jointly) and
    the home shift add to each sample's prediction, to first order (`dq` (T, C, Q)
    and `dh` (T, C) the elastic part's derivatives in q and the shift). With the
    tare fitted to all samples (`all_basis`), the baseline absorbs part of any
    change."""
    num_samples, num_channels, _ = dq.shape
    active = touching[:, None] & (elastic > 0.0)  # (T, C): where the push is on
    columns = bases.reshape(num_samples, -1)  # (T, S J)
    variance = np.zeros((num_samples, num_channels))
    for c in range(num_channels):
        jac = np.concatenate([dq[:, c, :], columns * active[:, c, None], dh[:, c, None]], axis=1)
        if all_basis is not None:
            used = mask[:, c]
            jac = jac - all_basis @ np.linalg.lstsq(all_basis[used], jac[used], rcond=None)[0]
        qa = covariance["qa"][c]
        joint = np.block([[covariance["qq"], qa], [qa.T, covariance["aa"][c]]])
        joint = np.block([[joint, np.zeros((len(joint), 1))], [np.zeros((1, len(joint))), np.full((1, 1), shift_var)]])
        variance[:, c] = np.einsum("tp,pr,tr->t", jac, joint, jac)
    return np.maximum(variance, 0.0)
