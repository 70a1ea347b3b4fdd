"""Fit a Prony series to a measured relaxation curve E(t) (a relaxation test, or a
master curve), the task pyvisco solves: same start (NNLS on a τ grid, merged), same
solvers and uncertainties as the log fits.

Residuals are relative, (E_data − E_model) / (σ_rel E_data): relaxation data span
decades in time and the modulus falls by a factor, so each point counts by its
relative error; σ_rel is the noise estimate (median absolute second difference).
"""

import dataclasses
import time

import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._errors import HydrotactError
from ..visco import Prony
from ._fit import MAX_AUTO_TERMS, Estimate, calc_bic, calc_covariance
from ._initial import _MODULUS_FLOOR, fit_linear_moduli, merge_terms
from ._solve import Solver, calc_jacobian, check_solver, solve_least_squares


@dataclasses.dataclass(frozen=True)
class RelaxationFit:
    """A Prony series fitted to E(t): estimates, covariance of the log parameters
    [log E∞, log E₁.., log τ₁..], RMS residual (Pa), BIC, the solver's
    `optimistix.RESULTS` code (`converged` when successful) and the time taken."""

    long_term_modulus: Estimate
    terms: list
    covariance: np.ndarray
    residual_rms: float
    bic: float
    result: optx.RESULTS
    seconds: float

    @property
    def converged(self) -> bool:
        return bool(self.result == optx.RESULTS.successful)

    @property
    def prony(self) -> Prony:
        return Prony(jnp.asarray(self.long_term_modulus.value), jnp.asarray([m.value for m, _ in self.terms]), jnp.asarray([t.value for _, t in self.terms]))


def _residuals(x, data):
    times, modulus, weights = data
    count = (x.shape[0] - 1) // 2
    prony = Prony(jnp.exp(x[0]), jnp.exp(x[1 : 1 + count]), jnp.exp(x[1 + count :]))
    return (modulus - prony.calc_relaxation_modulus(times)) * weights


def fit_relaxation_curve(times, modulus, num_terms="auto", solver: Solver | None = None, max_terms: int = MAX_AUTO_TERMS, *, throw: bool = False) -> RelaxationFit:
    """Fit E(t) = E∞ + Σ Eᵢ exp(−t/τᵢ) to samples (times s, modulus Pa) (host).

    `num_terms` an integer or "auto" (the lowest BIC over 0..max_terms); `solver` a
    solver object (None: Levenberg–Marquardt); `throw` raise a HydrotactError if a
    solve does not converge (else the result says so)."""
    times = np.asarray(times, dtype=np.float64)
    modulus = np.asarray(modulus, dtype=np.float64)
    if times.ndim != 1 or times.shape != modulus.shape or len(times) < 4:
        raise HydrotactError(f"a relaxation curve needs matching 1-D times and moduli (at least 4), got {times.shape} and {modulus.shape}")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(modulus))) or np.any(modulus <= 0.0) or np.any(times < 0.0):
        raise HydrotactError("a relaxation curve needs finite times ≥ 0 and positive moduli")
    solver = check_solver(solver)
    if num_terms == "auto":
        fits = [fit_relaxation_curve(times, modulus, k, solver, throw=throw) for k in range(max_terms + 1)]
        return min(fits, key=lambda fit: fit.bic)
    start = time.perf_counter()
    order = np.argsort(times)
    times, modulus = times[order], modulus[order]
    relative = np.diff(np.log(modulus), n=2)
    sigma = max(float(np.median(np.abs(relative))) / (0.6745 * np.sqrt(6.0)), 1e-12)
    weights = 1.0 / (sigma * modulus)
    positive = times[times > 0.0]
    grid = np.logspace(np.log10(positive.min()) - 0.5, np.log10(times.max()) + 0.5, max(4, int(4 * np.log10(times.max() / positive.min())) + 5))
    design = np.column_stack([np.ones_like(times), np.exp(-times[:, None] / grid)]) * weights[:, None]
    moduli = fit_linear_moduli([(design, modulus * weights)])
    floor = _MODULUS_FLOOR * max(float(moduli.sum()), 1e-300)
    taus, term_moduli = merge_terms(grid, moduli[1:], int(num_terms), floor)
    x0 = np.concatenate([[np.log(max(moduli[0], floor))], np.log(term_moduli), np.log(taus)])
    data = (jnp.asarray(times), jnp.asarray(modulus), jnp.asarray(weights))
    solution = solve_least_squares(_residuals, jnp.asarray(x0), data, solver, throw=throw)
    x = solution.value
    residuals = np.asarray(_residuals(x, data))
    jacobian = np.asarray(calc_jacobian(_residuals, x, data))
    chi_square = float(np.sum(residuals**2))
    n, p = len(times), len(x0)
    covariance = calc_covariance(chi_square, jacobian.T @ jacobian, n)
    x = np.asarray(x)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    count = int(num_terms)
    pairs = ((Estimate(np.exp(x[1 + k]), np.exp(x[1 + k]) * std[1 + k]), Estimate(np.exp(x[1 + count + k]), np.exp(x[1 + count + k]) * std[1 + count + k])) for k in range(count))
    terms = sorted(pairs, key=lambda pair: pair[1].value)
    fitted = np.asarray(Prony(jnp.exp(x[0]), jnp.exp(x[1 : 1 + count]), jnp.exp(x[1 + count :])).calc_relaxation_modulus(times))
    return RelaxationFit(
        long_term_modulus=Estimate(float(np.exp(x[0])), float(np.exp(x[0]) * std[0])),
        terms=terms,
        covariance=covariance,
        residual_rms=float(np.sqrt(np.mean((modulus - fitted) ** 2))),
        bic=calc_bic(chi_square, n, p),
        result=solution.result,
        seconds=time.perf_counter() - start,
    )
