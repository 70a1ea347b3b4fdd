"""Initial guesses: a linear fit on a grid of relaxation times, merged to K terms.

With the relaxation times fixed, the model is linear in the moduli: each reading is
E∞ · u + Σ_g E_g · (exp(−t/τ_g) ∗ u) (+ offset). A non-negative least-squares fit
(scipy's NNLS) on a dense log-spaced τ grid picks the time scales present in the data;
neighbouring grid terms are then merged (at the widest gaps in log τ) into K terms,
each with the summed modulus and the modulus-weighted mean log τ. This is the start
Levenberg–Marquardt needs: Prony fits from a blind start often stall with two terms
sharing one time scale.
"""

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import nnls

from ..visco import Prony, calc_hereditary_integral

_MAX_ROWS = 20000  # the linear fit only needs the shape of the data: thin long logs
_MODULUS_FLOOR = 1e-6  # of the total modulus: a term NNLS left at 0 starts here
_NEGLIGIBLE = 1e-2  # of the terms' total modulus: grid terms below this are not merged


def make_tau_grid(times_list, per_decade: int = 4) -> np.ndarray:
    """Log-spaced relaxation times from twice the shortest step to the longest span."""
    shortest = min(float(np.min(np.diff(np.asarray(times)))) for times in times_list)
    span = max(float(times[-1] - times[0]) for times in times_list)
    low, high = np.log10(max(2.0 * shortest, span * 1e-5)), np.log10(span)
    count = max(2, int(np.ceil((high - low) * per_decade)) + 1)
    return np.logspace(low, high, count)


@jax.jit
def _basis(times, inputs, taus):
    """(T, columns, 1 + G): the input itself (E∞'s share) and its response to each
    unit-modulus single-term kernel."""
    def one(tau):
        kernel = Prony(jnp.zeros((), times.dtype), jnp.ones((1,), times.dtype), tau[None])
        return calc_hereditary_integral(kernel, times, inputs)

    terms = jax.vmap(one, out_axes=-1)(taus)
    return jnp.concatenate([inputs[..., None], terms], axis=-1)


def merge_terms(taus: np.ndarray, moduli: np.ndarray, num_terms: int, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge a grid's non-zero terms into `num_terms` (τ, E) pairs, splitting at the
    widest gaps in log τ; pad with small terms spread over the grid if too few."""
    # Grid terms far below the others (a sliver of modulus at the log's length, say)
    # would take a term of their own and force two real time scales into one.
    active = moduli > _NEGLIGIBLE * moduli.sum()
    taus_on, moduli_on = taus[active], moduli[active]
    if num_terms == 0:
        return np.zeros(0), np.zeros(0)
    if len(taus_on) >= num_terms:
        logs = np.log(taus_on)
        cuts = np.sort(np.argsort(np.diff(logs))[::-1][: num_terms - 1]) + 1
        groups = np.split(np.arange(len(taus_on)), cuts)
        merged_taus = np.array([np.exp(np.average(logs[g], weights=moduli_on[g])) for g in groups])
        merged_moduli = np.array([moduli_on[g].sum() for g in groups])
    else:
        merged_taus, merged_moduli = list(taus_on), list(moduli_on)
        for tau in taus[np.argsort(np.abs(np.log(taus) - np.log(np.median(taus))))]:
            if len(merged_taus) == num_terms:
                break
            if all(abs(np.log(tau / t)) > 0.5 for t in merged_taus):
                merged_taus.append(tau)
                merged_moduli.append(floor)
        merged_taus, merged_moduli = np.array(merged_taus), np.array(merged_moduli)
    order = np.argsort(merged_taus)
    return merged_taus[order], np.maximum(merged_moduli[order], floor)


def fit_linear_moduli(blocks) -> np.ndarray:
    """NNLS moduli [E∞, E_g...] for stacked (design, target) blocks (host)."""
    design = np.concatenate([block[0] for block in blocks])
    target = np.concatenate([block[1] for block in blocks])
    column_scale = np.maximum(np.linalg.norm(design, axis=0), 1e-300)
    solution, _ = nnls(design / column_scale, target, maxiter=50 * design.shape[1])
    return solution / column_scale


def design_block(times, inputs, observed, weights, centred_columns: int, taus):
    """One log's rows for the linear fit: basis responses (rows = samples × columns),
    weighted; the first `centred_columns` columns lose their mean (their offset is
    free)."""
    step = max(1, len(times) // _MAX_ROWS)
    basis = np.array(_basis(jnp.asarray(times), jnp.asarray(inputs), jnp.asarray(taus))[::step])
    observed = np.asarray(observed, dtype=np.float64)[::step].copy()
    weights = np.asarray(weights, dtype=np.float64)[::step]
    observed[:, :centred_columns] -= observed[:, :centred_columns].mean(axis=0)
    basis[:, :centred_columns] -= basis[:, :centred_columns].mean(axis=0)
    return (basis * weights[:, :, None]).reshape(-1, basis.shape[2]), (observed * weights).reshape(-1)
