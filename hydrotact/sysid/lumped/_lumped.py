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
exact one of the projected problem, is written by hand (:func:`calc_press_jacobian`);
the inner solve is :mod:`._press_projection`'s.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...visco import Prony
from ._press_directions import lag_direction, make_log_terms, onset_directions, shape_directions
from ._press_projection import (
    apply_inverse,
    calc_elastic,
    find_actives,
    responding_columns,
    solve_linear,
    solve_linear_factored,
    unloaded_gram,
)
from ._press_windows import PressData, calc_bases, calc_depths, log_windows


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
    return calc_projection(shape, onsets, lags, datas)[:3]


def calc_projection(shape: Prony, onsets, lags, datas):
    """:func:`calc_press_residuals`, and where each channel's elastic part is on per
    log (T, C), the contact per log (T,) and the bases per log (T, S, J)."""
    bases, contact = [], []
    for data, onset, lag in zip(datas, onsets, lags):
        depths = calc_depths(data, onset, lag)
        bases.append(calc_bases(shape, depths, data))
        contact.append(depths > 0.0)
    actives = find_actives(bases, contact, datas)
    drifts, amplitudes, residuals = solve_linear(bases, datas, actives, contact)
    return residuals, drifts, amplitudes, actives, contact, bases


def calc_press_jacobian(layout: "PressLayout", x, args, linear: bool = False):
    """The flat weighted residuals (R,) and their Jacobian (R, M) in x, by hand
    (with `linear`, also the amplitudes (C, S, J), per log the bases (T, S, J)
    and the contact (T,), and the amplitudes' :class:`LinearSensitivity`).

    Variable projection's derivative (Golub and Pereyra) per direction k:
    v = −dΦ a on the active samples, da = N⁻¹ (Φᵀ v + dΦᵀ r), dr = v − Φ da (exact for
    the normal matrix N = ΦᵀΦ; the ridge is 1e-12 of it), with one solve per
    direction with N's factors. With the baseline learned where the skin is
    unloaded, N is the block lower-triangular matrix of :mod:`._press_projection` and the
    baseline's part of Φᵀ v is 0 (the unloaded samples do not move with x; the
    contact set is piecewise constant in it, as the active set is). dΦ v and dΦᵀ r come from one recursion over the
    press windows (:func:`_log_windows`) and the free decays after them, never as a
    (T, S, J) array per direction; an onset moves only its own press's column: the
    whole Jacobian costs a few narrow recursions and M solves of the small normal
    matrix, not M passes of forward mode through the integrals and the
    factorisation.
    """
    datas, starts, given_lags = args
    shape, onsets, lags = layout.unpack(x, starts, given_lags)
    k = layout.num_terms
    pieces = [log_windows(shape, onset, jnp.asarray(lag, x.dtype), data, layout.estimate_lag) for data, onset, lag in zip(datas, onsets, lags)]
    bases = [piece[0] for piece in pieces]
    contact = [piece[2] for piece in pieces]
    actives = find_actives(bases, contact, datas)
    _, amplitudes, residuals, (weighted, blocks, factors, scale) = solve_linear_factored(bases, datas, actives, contact)
    size = layout.size
    num_channels, num_sites, num_powers = amplitudes.shape
    first_onset = 2 * k
    first_lag = 2 * k + sum(layout.num_presses)
    vectors, extra = [], jnp.zeros((size, num_channels, num_sites * num_powers), x.dtype)
    for log, ((_, windows, _), data, active, residual) in enumerate(zip(pieces, datas, actives, residuals)):
        terms = make_log_terms(windows, data, amplitudes, (data.weights * active).T, residual)
        num_presses = layout.num_presses[log]
        vector = jnp.zeros((size, num_channels, terms.on.shape[1]), x.dtype)
        shape_vectors, shape_extra = shape_directions(shape, windows, data, terms)
        vector = vector.at[: 2 * k].set(shape_vectors)
        extra = extra.at[: 2 * k].add(shape_extra)
        # chain rule through x: exp for the shape (in the directions already), tanh for onsets and lag
        onset_scale = ONSET_HALF_RANGE * (1.0 - jnp.tanh(x[first_onset : first_onset + num_presses]) ** 2)
        onset_vectors, by_press = onset_directions(shape, windows, data, terms)
        vector = vector.at[first_onset : first_onset + num_presses].set(onset_vectors * onset_scale[:, None, None])
        by_press = by_press * onset_scale[:, None, None]
        extra = extra.at[first_onset : first_onset + num_presses].add((by_press[:, :, None, :] * terms.press_site[:, None, :, None]).reshape(num_presses, num_channels, -1))
        if layout.estimate_lag:
            lag_scale = LAG_BOUND * (1.0 - jnp.tanh(x[first_lag + log]) ** 2)
            lag_vector, lag_extra = lag_direction(shape, windows, data, terms)
            vector = vector.at[first_lag + log].set(lag_vector * lag_scale)
            extra = extra.at[first_lag + log].add(lag_extra * lag_scale)
        vectors.append(vector)
        first_onset += num_presses
    sizes, first, num_baseline = blocks
    rhs = jnp.zeros((size, num_channels, num_baseline + num_sites * num_powers), x.dtype)
    for log, ((drift, sites, _), vector, data) in enumerate(zip(weighted, vectors, datas)):
        if data.drift_from != "unloaded":  # a baseline fitted out of contact does not move with x
            rhs = rhs.at[:, :, first[log] : first[log] + sizes[log]].set(jnp.einsum("ctd,mct->mcd", drift, vector))
        rhs = rhs.at[:, :, num_baseline:].add(jnp.einsum("cts,mct->mcs", sites, vector))
    rhs = rhs.at[:, :, num_baseline:].add(extra * responding_columns(datas[0], num_powers)[None])  # a law fixed at 0 stays there
    step = jax.vmap(apply_inverse, in_axes=(None, None, 0))(factors, scale, rhs)  # (M, C, N)
    columns = []
    for log, ((drift, sites, _), vector) in enumerate(zip(weighted, vectors)):
        fitted = jnp.einsum("ctd,mcd->mct", drift, step[:, :, first[log] : first[log] + sizes[log]]) + jnp.einsum("cts,mcs->mct", sites, step[:, :, num_baseline:])
        columns.append(jnp.transpose(vector - fitted, (2, 1, 0)).reshape(-1, size))
    value, jacobian = jnp.concatenate([r.reshape(-1) for r in residuals]), jnp.concatenate(columns, axis=0)
    if not linear:
        return value, jacobian
    # For the amplitudes' covariance: where each (channel, site, power) is fitted, its
    # derivative in x and its block of N⁻¹ (0 where the law is fixed at 0 or no sample reaches it).
    fitted_columns = responding_columns(datas[0], num_powers) * (sum(jnp.einsum("cts,cts->cs", sites, sites) for _, sites, _ in weighted) > 0.0)
    size_linear = num_baseline + num_sites * num_powers
    identity = jnp.broadcast_to(jnp.eye(size_linear)[:, None, :], (size_linear, num_channels, size_linear))
    if datas[0].drift_from == "unloaded":
        # The linear parameters are M⁻¹ Φ̃ᵀ y with M block lower-triangular (the
        # baseline's rows from the unloaded samples): their covariance is M⁻¹ Σ M⁻ᵀ,
        # Σ the right-hand side's Gram matrix, block diagonal (the sites' columns
        # are 0 out of contact): each log's unloaded baseline block and the sites'.
        inverse = jax.vmap(apply_inverse, in_axes=(None, None, 0))(factors, scale, identity)  # (N, C, N): column j of M⁻¹
        rows = jnp.transpose(inverse[:, :, num_baseline:], (1, 2, 0))  # (C, S J, N): the amplitudes' rows of M⁻¹
        amplitude_rows = rows[:, :, num_baseline:]
        amplitude_inverse = jnp.einsum("cas,csr,cbr->cab", amplitude_rows, sum(jnp.einsum("cts,ctr->csr", sites, sites) for _, sites, _ in weighted), amplitude_rows)
        for log, ((drift, _, _), touching) in enumerate(zip(weighted, contact)):
            block = rows[:, :, first[log] : first[log] + sizes[log]]
            amplitude_inverse = amplitude_inverse + jnp.einsum("cad,cde,cbe->cab", block, unloaded_gram(drift, touching), block)
    else:
        inverse = jax.vmap(apply_inverse, in_axes=(None, None, 0))(factors, scale, identity[num_baseline:])  # (S J, C, N)
        amplitude_inverse = jnp.transpose(inverse[:, :, num_baseline:], (1, 0, 2))
    amplitude_inverse = amplitude_inverse * fitted_columns[:, :, None] * fitted_columns[:, None, :]
    sensitivity = LinearSensitivity(step[:, :, num_baseline:] * fitted_columns[None], amplitude_inverse)
    return value, jacobian, amplitudes, bases, contact, sensitivity


class LinearSensitivity(eqx.Module):
    """What the amplitudes' covariance needs from the projection: `steps` (M, C, S J)
    the amplitudes' derivatives in x, `inverse` (C, S J, S J) their covariance from
    the readings' noise at fixed x, Pa² (the block of the weighted normal matrix'
    inverse; with the baseline learned out of contact, of M⁻¹ Σ M⁻ᵀ). With Cₓ the covariance of x, the
    amplitudes' is N⁻¹ + G Cₓ Gᵀ and their covariance with x is G Cₓ (the Schur
    complement of the full problem's normal matrix; G = steps)."""

    steps: jax.Array
    inverse: jax.Array


def calc_press_predictions(shape: Prony, onsets, lag, baseline_coefficients, amplitudes, data: PressData):
    """(T, C) one log's readings for given linear parameters (baseline (C, D),
    amplitudes (C, S, J)): the baseline plus the elastic part."""
    depths = calc_depths(data, onsets, lag)
    return data.baseline @ baseline_coefficients.T + calc_elastic(calc_bases(shape, depths, data), depths > 0.0, amplitudes)


ONSET_HALF_RANGE = 0.5e-3  # m: a press's onset stays within this of its start value
LAG_BOUND = 0.5  # s: an estimated lag stays within ±this


class PressLayout(eqx.Module):
    """Where the nonlinear parameters sit in x (static): log Eᵢ/E∞ (K), log τᵢ (K),
    each log's onsets' unbounded coordinates (P_l), and each log's lag's (1 per log,
    when estimated).

    `active` (K,) 1 or 0 per term, or None (all on): a term that is off has Eᵢ = 0,
    so it adds nothing and its two columns of the Jacobian are 0 (the solver leaves
    them where they start). It is an array, not a static field, so that the fits of
    1 to K terms `terms="auto"` compares run one compiled program (K terms, some
    off) instead of one per count: the compilation is most of a cold fit's cost per
    count. :meth:`without_inactive` gives the layout and x of the terms that are on."""

    num_terms: int = eqx.field(static=True)
    num_presses: tuple[int, ...] = eqx.field(static=True)
    estimate_lag: bool = eqx.field(static=True)
    active: jax.Array | None = None

    @property
    def size(self) -> int:
        return 2 * self.num_terms + sum(self.num_presses) + len(self.num_presses) * int(self.estimate_lag)

    def unpack(self, x, onset_starts, lags):
        """(shape, onsets per log, lags per log) from x; `onset_starts` the centres of
        the onsets' ranges, `lags` the lags when they are not estimated."""
        k = self.num_terms
        moduli = jnp.exp(x[:k]) if self.active is None else jnp.exp(x[:k]) * self.active.astype(x.dtype)
        shape = Prony(jnp.ones((), x.dtype), moduli, jnp.exp(x[k : 2 * k]))
        first = 2 * k
        onsets = []
        for count, start in zip(self.num_presses, onset_starts):
            onsets.append(start + ONSET_HALF_RANGE * jnp.tanh(x[first : first + count]))
            first += count
        if self.estimate_lag:
            lags = tuple(LAG_BOUND * jnp.tanh(x[first + log]) for log in range(len(self.num_presses)))
        return shape, tuple(onsets), tuple(lags)

    def without_inactive(self):
        """(the layout of the terms that are on, the indices of their entries in x):
        x[indices] is x in that layout (host-side; `active` concrete)."""
        if self.active is None:
            return self, np.arange(self.size)
        on = np.flatnonzero(np.asarray(self.active) > 0.0)
        k = self.num_terms
        indices = np.concatenate([on, k + on, np.arange(2 * k, self.size)])
        return PressLayout(len(on), self.num_presses, self.estimate_lag), indices


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
