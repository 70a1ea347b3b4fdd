"""The lumped press model's linear part (pure): for given bases, each channel's
baseline coefficients and amplitudes by weighted least squares (variable projection's
inner solve), the set where a channel's elastic part is on, and the elastic part itself.
:mod:`._lumped` holds the model, its nonlinear parameters and the projection's hand
Jacobian, which reuses the factors solved here.
"""

import jax
import jax.numpy as jnp

from ..._linalg import lu_factor, lu_solve, solve

ACTIVE_PASSES = 2  # solves that find where the elastic part is on, before the last
RIDGE = 1e-12  # relative to the normal matrix' diagonal: keeps an unused site's amplitude at 0


def _assemble(bases, datas, actives, contact):
    """The weighted columns per log [(drift (C, T, D), sites (C, T, S J), target (C,
    T))], the block offsets, and the matrix and right-hand side (C, N, N), (C, N) of
    the linear problem: the joint least squares' normal equations, or, with the
    baseline learned where the skin is unloaded (PressData.drift_from "unloaded"),
    their block lower-triangular form: the baseline's rows fitted over the samples
    out of contact (`contact` per log (T,)) alone, with a small penalty on its
    spline coefficients' second differences (:func:`smoothness`: a knot interval
    that a long hold covers is bridged, not left at 0), and the amplitudes' rows
    as before, given that baseline."""
    sizes = [data.baseline.shape[1] for data in datas]
    first = [sum(sizes[:k]) for k in range(len(sizes))]
    num_baseline = sum(sizes)
    _, num_sites, num_powers = bases[0].shape
    num_channels = datas[0].observed.shape[1]
    size = num_baseline + num_sites * num_powers
    normal = jnp.zeros((num_channels, size, size), bases[0].dtype)
    rhs = jnp.zeros((num_channels, size), bases[0].dtype)
    weighted = []
    for k, (basis, data, active, touching) in enumerate(zip(bases, datas, actives, contact)):
        weights = data.weights.T  # (C, T)
        drift = data.baseline[None, :, :] * weights[:, :, None]  # (C, T, D)
        columns = basis.reshape(basis.shape[0], -1)  # (T, S J)
        sites = columns[None, :, :] * (weights * active.T)[:, :, None] * responding_columns(data, num_powers)[:, None, :]  # (C, T, S J)
        target = data.observed.T * weights  # (C, T)
        weighted.append((drift, sites, target))
        low, high = first[k], first[k] + sizes[k]
        cross = jnp.einsum("ctd,cts->cds", drift, sites)
        normal = normal.at[:, num_baseline:, low:high].set(jnp.transpose(cross, (0, 2, 1)))
        normal = normal.at[:, num_baseline:, num_baseline:].add(jnp.einsum("cts,ctr->csr", sites, sites))
        rhs = rhs.at[:, num_baseline:].add(jnp.einsum("cts,ct->cs", sites, target))
        if data.drift_from == "unloaded":
            own = unloaded_gram(drift, touching)
            normal = normal.at[:, low:high, low:high].set(own + smoothness(own))
            rhs = rhs.at[:, low:high].set(jnp.einsum("ctd,ct->cd", drift * (~touching)[None, :, None], target))
        else:
            normal = normal.at[:, low:high, low:high].set(jnp.einsum("ctd,cte->cde", drift, drift))
            normal = normal.at[:, low:high, num_baseline:].set(cross)
            rhs = rhs.at[:, low:high].set(jnp.einsum("ctd,ct->cd", drift, target))
    return weighted, (sizes, first, num_baseline), normal, rhs


def unloaded_gram(drift, touching):
    """(C, D, D) a log's weighted baseline columns (C, T, D) against themselves over
    the samples out of contact (`touching` (T,) False): the baseline's block of the
    linear problem when it is learned there, and of its right-hand side's Gram matrix."""
    return jnp.einsum("ctd,cte->cde", drift * (~touching)[None, :, None], drift)


SMOOTHNESS = 1e-6  # the baseline spline's penalty on second differences, relative to its mean diagonal


def smoothness(normal):
    """(C, D, D) a penalty for a baseline's normal matrix (C, D, D): SMOOTHNESS of its
    mean diagonal times Δ²ᵀΔ² (second differences of the coefficients; none for a
    constant or a line). Against the data's own terms it is negligible; where no
    sample reaches a B-spline (a knot interval under one long hold), the coefficients
    there are interpolated linearly from their neighbours, not left at 0."""
    size = normal.shape[-1]
    second = jnp.diff(jnp.eye(size, dtype=normal.dtype), 2, axis=0)
    mean = jnp.trace(normal, axis1=-2, axis2=-1) / size
    return SMOOTHNESS * mean[..., None, None] * (second.T @ second)[None]


def responding_columns(data, num_powers):
    """(C, S J) 1 where the channel's law at the site is fitted, 0 where it is fixed at 0."""
    return jnp.repeat(data.responds, num_powers, axis=1).astype(data.weights.dtype)


def _factor(normal):
    """The Jacobi-scaled, ridged normal matrix' LU factors and the scale (C, N)."""
    diagonal = jnp.diagonal(normal, axis1=1, axis2=2)  # 0 for a site no press of the logs reaches
    used = diagonal > 0.0
    scale = jnp.where(used, jnp.sqrt(jnp.where(used, diagonal, 1.0)), 1.0)  # safe to differentiate where 0
    scaled = normal / (scale[:, :, None] * scale[:, None, :]) + RIDGE * jnp.eye(normal.shape[1])[None]
    return lu_factor(scaled), scale  # one channel at a time: jaxlib's batched LAPACK can deadlock (hydrotact._linalg)


def apply_inverse(factors, scale, rhs):
    """N⁻¹ rhs (C, N) with the factors of :func:`_factor`."""
    return lu_solve(factors, rhs / scale) / scale


def solve_scaled(normal, rhs):
    """normal⁻¹ rhs per channel (C, N, N), (C, N), Jacobi scaled and ridged as the
    projection's normal matrix is (a row of zeros gives 0)."""
    factors, scale = _factor(normal)
    return apply_inverse(factors, scale, rhs)


def baseline_inverses(datas):
    """Per log (C, D, D) the inverse of its weighted baseline columns' Gram matrix over
    every sample (Jacobi scaled and ridged as the projection's): with the baseline
    learned over the whole log (PressData.drift_from "all"), what projects it out of
    a solve whose other columns move (the onset scan's) without refitting it."""
    out = []
    for data in datas:
        drift = data.baseline[None, :, :] * data.weights.T[:, :, None]  # (C, T, D)
        factors, scale = _factor(jnp.einsum("ctd,cte->cde", drift, drift))
        identity = jnp.broadcast_to(jnp.eye(drift.shape[2], dtype=drift.dtype)[:, None, :], (drift.shape[2], drift.shape[0], drift.shape[2]))
        out.append(jnp.transpose(jax.vmap(apply_inverse, in_axes=(None, None, 0))(factors, scale, identity), (1, 2, 0)))
    return out


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


def solve_linear(bases, datas, actives, contact):
    """The linear parameters given each log's bases: per channel, weighted least
    squares over every log's baseline coefficients and the amplitudes per site and
    power (shared by the logs), by the normal equations assembled block by block
    (Jacobi scaled; a tiny ridge keeps what a channel never sees at 0). `actives`
    per log (T, C): where a channel's elastic part is on (elsewhere it reads its
    baseline); `contact` per log (T,): where the probe touches (with the baseline
    learned where the skin is unloaded, it is fitted to the other samples only).

    **Returns:** (baseline coefficients per log [(C, D_l)], amplitudes (C, S, J),
    weighted residuals per log [(T_l, C)]).
    """
    drifts, amplitudes, residuals, _ = solve_linear_factored(bases, datas, actives, contact)
    return drifts, amplitudes, residuals


def solve_linear_factored(bases, datas, actives, contact):
    """:func:`solve_linear`, plus what its derivative reuses: (weighted columns,
    blocks, factors, scale)."""
    weighted, blocks, normal, rhs = _assemble(bases, datas, actives, contact)
    factors, scale = _factor(normal)
    coefficients = apply_inverse(factors, scale, rhs)
    residuals = [(target - fitted).T for (_, _, target), fitted in zip(weighted, _fitted(weighted, blocks, coefficients))]
    drifts, amplitudes = _split(coefficients, blocks, (normal.shape[0], *bases[0].shape[1:]))
    return drifts, amplitudes, residuals, (weighted, blocks, factors, scale)


def find_actives(bases, contact, datas):
    """Per log (T, C): where each channel's elastic part is on. The amplitudes are
    solved over the contact, then over where that solution is positive, ACTIVE_PASSES
    times; the set is piecewise constant in the parameters (no derivative)."""
    frozen = [jax.lax.stop_gradient(basis) for basis in bases]
    num_channels = datas[0].observed.shape[1]
    touching = [jnp.broadcast_to(c[:, None], (c.shape[0], num_channels)) for c in contact]
    actives = touching
    for _ in range(ACTIVE_PASSES):
        _, amplitudes, _ = solve_linear(frozen, datas, actives, contact)
        actives = [on & (jnp.einsum("tsj,csj->tc", basis, amplitudes) > 0.0) for basis, on in zip(frozen, touching)]
    return actives


def solve_baselines(basis, targets, used):
    """(C, D) each channel's baseline coefficients: least squares of targets (T, C)
    on the basis (T, D) over the `used` samples (T, C), with the spline's smoothness
    penalty (:func:`smoothness`: a knot interval no used sample reaches is bridged)
    and a 1e-9 ridge relative to the normal matrix' mean diagonal."""
    weights = used.astype(basis.dtype)
    normal = jnp.einsum("td,tc,te->cde", basis, weights, basis)
    ridge = 1e-9 * jnp.trace(normal, axis1=1, axis2=2) / basis.shape[1]
    rhs = jnp.einsum("td,tc->cd", basis, weights * targets)
    return solve(normal + smoothness(normal) + ridge[:, None, None] * jnp.eye(basis.shape[1])[None], rhs)


def calc_elastic(bases, touching, amplitudes):
    """(T, C) the elastic part of the readings, for bases (T, S, J) and amplitudes
    (C, S, J): max(0, Σ A B) where the probe touches (`touching` (T,)), 0 elsewhere
    (the skin pushes on a barometer but never pulls)."""
    return jnp.where(touching[:, None], jnp.maximum(jnp.einsum("tsj,csj->tc", bases, amplitudes), 0.0), 0.0)
