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
so the outer solver only sees the few nonlinear parameters, and their Jacobian (by
autodiff through the solve) is the exact one of the projected problem.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._types import Array, Float, Int
from ..visco import Prony, calc_hereditary_integral

DEPTH_SCALE = 1e-3  # m: δ is measured in millimetres in the law (amplitudes in Pa at 1 mm)
POWERS = (1.5, 2.0, 2.5, 3.0)  # the law's powers of the depth (from Hertz's 1.5 up: see the docstring)
ACTIVE_PASSES = 2  # solves that find where the elastic part is on, before the last
RIDGE = 1e-12  # relative to the normal matrix' diagonal: keeps an unused site's amplitude at 0


class PressData(eqx.Module):
    """One log for the lumped press model (device arrays).

    **Fields:** `times` (T,) s; `travel` (T,) m; `press` (T,) the press of each
    sample (-1 between presses); `press_site` (P,) the site of each press (the sites
    are shared by all the logs of a fit); `observed` (T, C) Pa; `weights` (T, C)
    1 / noise, 0 for masked samples; `baseline` (T, D) the basis of each channel's
    slowly varying baseline (offset and drift: a constant, a line, or a cubic
    B-spline); `num_sites` (static) the number of sites of the whole fit.
    """

    times: Float[Array, " num_samples"]
    travel: Float[Array, " num_samples"]
    press: Int[Array, " num_samples"]
    press_site: Int[Array, " num_presses"]
    observed: Float[Array, "num_samples num_channels"]
    weights: Float[Array, "num_samples num_channels"]
    baseline: Float[Array, "num_samples num_baseline"]
    num_sites: int = eqx.field(static=True)


def calc_depths(data: PressData, onsets, lag):
    """(T,) δ(t) = (travel(t − lag) − onset of the sample's press)₊, 0 between presses."""
    travel = jnp.interp(data.times - lag, data.times, data.travel)
    inside = data.press >= 0
    return jnp.where(inside, jnp.maximum(travel - onsets[jnp.maximum(data.press, 0)], 0.0), 0.0)


def calc_bases(shape: Prony, depths, data: PressData):
    """(T, S, J) the bases B_{s,j}: the hereditary integrals of the powers of the
    depth, split by site (their memory runs on between presses)."""
    positive = depths > 0.0
    log_depth = jnp.log(jnp.where(positive, depths / DEPTH_SCALE, 1.0))
    law = jnp.where(positive[:, None], jnp.exp(log_depth[:, None] * jnp.asarray(POWERS)[None, :]), 0.0)  # (T, J)
    site = jnp.where(data.press >= 0, data.press_site[jnp.maximum(data.press, 0)], -1)
    by_site = (site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(law.dtype)  # (T, S)
    return calc_hereditary_integral(shape, data.times, by_site[:, :, None] * law[:, None, :])


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


def _project_rhs(weighted, blocks, vectors, num_channels, size, dtype):
    """Φᵀ v for per-log vectors v (C, T_l), in the normal matrix' block layout."""
    sizes, first, num_baseline = blocks
    rhs = jnp.zeros((num_channels, size), dtype)
    for k, ((drift, sites, _), vector) in enumerate(zip(weighted, vectors)):
        rhs = rhs.at[:, first[k] : first[k] + sizes[k]].set(jnp.einsum("ctd,ct->cd", drift, vector))
        rhs = rhs.at[:, num_baseline:].add(jnp.einsum("cts,ct->cs", sites, vector))
    return rhs


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


@jax.custom_jvp
def solve_linear(bases, datas, actives):
    """The linear parameters given each log's bases: per channel, weighted least
    squares over every log's baseline coefficients and the amplitudes per site and
    power (shared by the logs), by the normal equations assembled block by block
    (Jacobi scaled; a tiny ridge keeps what a channel never sees at 0). `actives`
    per log (T, C): where a channel's elastic part is on (elsewhere it reads its
    baseline).

    Differentiated in the bases by Golub and Pereyra's variable-projection
    derivative, da = N⁻¹ (dΦᵀ r − Φᵀ dΦ a), dr = −dΦ a − Φ da (exact for N = ΦᵀΦ;
    the ridge is 1e-12 of it): one solve with the normal matrix' factors per
    direction instead of differentiating the normal matrix itself, ~N times cheaper.

    **Returns:** (baseline coefficients per log [(C, D_l)], amplitudes (C, S, J),
    weighted residuals per log [(T_l, C)]).
    """
    weighted, blocks, normal, rhs = _assemble(bases, datas, actives)
    factors, scale = _factor(normal)
    coefficients = _apply_inverse(factors, scale, rhs)
    residuals = [(target - fitted).T for (_, _, target), fitted in zip(weighted, _fitted(weighted, blocks, coefficients))]
    drifts, amplitudes = _split(coefficients, blocks, (normal.shape[0], *bases[0].shape[1:]))
    return drifts, amplitudes, residuals


@solve_linear.defjvp
def _solve_linear_jvp(primals, tangents):
    bases, datas, actives = primals
    dbases = tangents[0]
    weighted, blocks, normal, rhs = _assemble(bases, datas, actives)
    factors, scale = _factor(normal)
    coefficients = _apply_inverse(factors, scale, rhs)
    residuals = [(target - fitted).T for (_, _, target), fitted in zip(weighted, _fitted(weighted, blocks, coefficients))]
    shape = (normal.shape[0], *bases[0].shape[1:])
    drifts, amplitudes = _split(coefficients, blocks, shape)
    # Golub-Pereyra: with v = −dΦ a, da = N⁻¹ (Φᵀ v + dΦᵀ r) and dr = v − Φ da (only
    # the site columns move with the bases).
    vectors = []
    _, _, num_baseline = blocks
    extra = jnp.zeros((normal.shape[0], normal.shape[1] - num_baseline), normal.dtype)
    for dbasis, data, active, residual in zip(dbases, datas, actives, residuals):
        on = (data.weights * active).T  # (C, T)
        vectors.append(-jnp.einsum("tsj,csj->ct", dbasis, amplitudes) * on)
        extra = extra + jnp.einsum("tn,ct->cn", dbasis.reshape(dbasis.shape[0], -1), on * residual.T)
    rhs = _project_rhs(weighted, blocks, vectors, normal.shape[0], normal.shape[1], normal.dtype).at[:, num_baseline:].add(extra)
    step = _apply_inverse(factors, scale, rhs)
    dresiduals = [(vector - fitted).T for vector, fitted in zip(vectors, _fitted(weighted, blocks, step))]
    ddrifts, damplitudes = _split(step, blocks, shape)
    return (drifts, amplitudes, residuals), (ddrifts, damplitudes, dresiduals)


def _law_inputs(depths, data: PressData, powers):
    """(T, S, J) the site-split inputs (δ/δ_ref)^p, and (T, J) their derivative in δ
    (per m)."""
    positive = depths > 0.0
    scaled = jnp.where(positive, depths / DEPTH_SCALE, 1.0)
    law = jnp.where(positive[:, None], scaled[:, None] ** powers[None, :], 0.0)
    slope = jnp.where(positive[:, None], powers[None, :] * scaled[:, None] ** (powers[None, :] - 1.0) / DEPTH_SCALE, 0.0)
    site = jnp.where(data.press >= 0, data.press_site[jnp.maximum(data.press, 0)], -1)
    by_site = (site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(law.dtype)  # (T, S)
    return by_site[:, :, None] * law[:, None, :], slope, by_site


@jax.custom_jvp
def site_bases(shape: Prony, onsets, lag, data: PressData):
    """(T, S, J) the bases at the given shape, onsets and lag (:func:`calc_bases` of
    :func:`calc_depths`).

    Differentiated by hand in the onsets and the lag: an onset moves only its own
    press's depth, so the bases' derivatives in all P onsets are the hereditary
    integrals of P × J inputs, computed once (not once per direction, as forward
    mode through the integral would); the lag's is one more integral. The shape's
    derivative goes through the integral's own rule (its τ part also computed once).
    """
    return calc_bases(shape, calc_depths(data, onsets, lag), data)


@site_bases.defjvp
def _site_bases_jvp(primals, tangents):
    shape, onsets, lag, data = primals
    dshape, donsets, dlag = tangents[:3]
    powers = jnp.asarray(POWERS)
    depths = calc_depths(data, onsets, lag)
    inputs, slope, by_site = _law_inputs(depths, data, powers)
    bases, dbases = jax.jvp(lambda sh: calc_hereditary_integral(sh, data.times, inputs), (shape,), (dshape,))
    press = jnp.where(depths > 0.0, data.press, -1)
    by_press = (press[:, None] == jnp.arange(onsets.shape[0])[None, :]).astype(slope.dtype)  # (T, P)
    # ∂δ/∂onset_p = −[press p]; ∂δ/∂lag = −travel'(t − lag) where in contact.
    per_press = calc_hereditary_integral(shape, data.times, -by_press[:, :, None] * slope[:, None, :])  # (T, P, J)
    press_site = (data.press_site[:, None] == jnp.arange(data.num_sites)[None, :]).astype(slope.dtype)  # (P, S)
    dbases = dbases + jnp.einsum("tpj,p,ps->tsj", per_press, donsets, press_site)
    shifted = data.times - lag
    index = jnp.clip(jnp.searchsorted(data.times, shifted, side="right") - 1, 0, data.times.shape[0] - 2)
    speed = (data.travel[index + 1] - data.travel[index]) / (data.times[index + 1] - data.times[index])
    speed = jnp.where((shifted > data.times[0]) & (shifted < data.times[-1]), speed, 0.0)
    per_lag = calc_hereditary_integral(shape, data.times, by_site[:, :, None] * (-speed[:, None] * slope)[:, None, :])  # (T, S, J)
    return bases, dbases + per_lag * dlag


def _all_bases(shape, onsets, lags, datas):
    """Per log: (the bases (T, S, J), the contact (T,))."""
    out = []
    for data, onset, lag in zip(datas, onsets, lags):
        depths = calc_depths(data, onset, lag)
        out.append((site_bases(shape, onset, jnp.asarray(lag, depths.dtype), data), depths > 0.0))
    return out


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
    pieces = _all_bases(shape, onsets, lags, datas)
    bases = [basis for basis, _ in pieces]
    num_channels = datas[0].observed.shape[1]
    contact = [jnp.broadcast_to(touching[:, None], (touching.shape[0], num_channels)) for _, touching in pieces]
    actives = contact
    frozen = [jax.lax.stop_gradient(basis) for basis in bases]  # the set is piecewise constant: no tangents through these passes
    for _ in range(ACTIVE_PASSES):
        _, amplitudes, _ = solve_linear(frozen, datas, actives)
        actives = [touching & (jnp.einsum("tsj,csj->tc", basis, amplitudes) > 0.0) for basis, touching in zip(frozen, contact)]
    drifts, amplitudes, residuals = solve_linear(bases, datas, actives)
    return residuals, drifts, amplitudes


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
    """x, (datas, onset_starts, lags) -> the flat weighted residuals (for optimistix)."""

    def residuals(x, args):
        datas, onset_starts, lags = args
        per_log = calc_press_residuals(*layout.unpack(x, onset_starts, lags), datas)[0]
        return jnp.concatenate([r.reshape(-1) for r in per_log])

    return residuals
