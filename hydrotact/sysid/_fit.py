"""Fit a Prony material (and channel gains and offsets) to barometer logs.

`fit_problem` runs one solver from a linear-fit start and returns a :class:`FitResult`
with the parameter covariance from the Jacobian, C = s² (JᵀJ)⁻¹ with s² the reduced
chi-square (the residuals are already divided by each channel's noise estimate);
standard errors of positive parameters follow by the delta method (σ_E = E σ_log E).
`fit_auto` fits 0..max_terms Prony terms and keeps the one with the lowest Bayesian
information criterion, BIC = N ln(RSS/N) + P ln N.

The solver is an object holding settings (see `_solve.py`; `make_solver("lm")` and
the other names of SOLVERS are what the command line offers); a fit that stops before
converging comes back with its `optimistix.RESULTS` code, or raises with `throw=True`.
"""

import dataclasses
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._errors import HydrotactError
from ..visco import Prony
from ._initial import _MODULUS_FLOOR, design_block, fit_linear_moduli, make_tau_grid, merge_terms
from ._model import ParameterLayout, calc_predictions, calc_residuals, make_layout, pack
from ._problem import FitProblem
from ._rig_problem import BOUND_FRACTION, rig_start
from ._solve import BoundedLBFGSB, Solver, calc_jacobian, check_solver, raise_if_failed, solve_least_squares, solver_name

MAX_AUTO_TERMS = 4


def calc_covariance(chi_square: float, normal: np.ndarray, num_residuals: int) -> np.ndarray:
    """The parameters' covariance s² (JᵀJ)⁺ from the normal matrix JᵀJ of residuals
    already divided by their noise, s² = χ² / (N − P) the reduced chi-square."""
    dof = max(1, num_residuals - normal.shape[0])
    inverse = np.linalg.pinv(normal, rcond=1e-13, hermitian=True)
    # symmetric to round-off only: with hundreds of parameters (a rig fit's drift
    # splines) the pseudo-inverse of an ill-conditioned JᵀJ is 1e-9 off symmetry
    return float(chi_square) / dof * 0.5 * (inverse + inverse.T)


def calc_bic(chi_square: float, num_residuals: int, num_parameters: int) -> float:
    """The Bayesian information criterion N ln(χ²/N) + P ln N."""
    n = num_residuals
    return float(n * np.log(max(chi_square, 1e-300) / n) + num_parameters * np.log(n))


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A fitted number and its standard error."""

    value: float
    std: float

    def to_json(self) -> dict:
        """{value, std}; std null where the fit gives no finite standard error (a
        direction the data do not constrain: JSON has no NaN)."""
        return {"value": float(self.value), "std": float(self.std) if np.isfinite(self.std) else None}


CHI_SQUARE_WARNING = 4.0
"""A reduced χ² above this draws a warning: the model misses the data by more than
their noise (a wrong sensor, swapped channel names, a unit slip), whatever the solver
says about convergence."""

MIN_TERM_FRACTION = 1e-4
"""A Prony term whose modulus is below this fraction of E(0) moves no reading: its E
and τ are the solver's last word, not measured."""


def identify_time(value: float, std: float, step: float, span: float) -> tuple[bool, str]:
    """Whether the data identify a time constant `value` ± `std` (s) sampled every
    `step` s over `span` s: it lies in [step / 10, 10 x span] and its standard error
    is below it; and, if not, why."""
    if not step / 10 <= value <= 10 * span:
        return False, f"outside [{step / 10:.3g} s, {10 * span:.3g} s] (sampling step / 10, 10 x the longest log)"
    if not np.isfinite(std):
        return False, "no finite standard error: the logs do not constrain it"
    if not std < value:
        return False, "standard error larger than the value"
    return True, ""


def identify_modulus(value: float, std: float) -> tuple[bool, str]:
    """Whether a fitted modulus is measured: a finite standard error below it."""
    if not np.isfinite(std):
        return False, "no finite standard error: the logs do not constrain it"
    return (True, "") if std < value else (False, "standard error larger than the value")


@dataclasses.dataclass(frozen=True)
class FitResult:
    """The outcome of a fit (host, NumPy).

    **Fields:** `problem`, `layout`; `x` the solution (flat, log space for positive
    parameters) and `names`; `covariance` of x; `chi_square` Σ r², `dof` N − P,
    `num_residuals` N; `num_steps`; `result` the solver's `optimistix.RESULTS` code
    (`converged` when successful); `solver` the solver object and `solver_name` its
    name in SOLVERS (or its class name); `seconds` (including compilation);
    `criteria` {num_terms: BIC} when the number of terms was chosen.
    """

    problem: FitProblem
    layout: ParameterLayout
    x: np.ndarray
    names: list
    covariance: np.ndarray
    chi_square: float
    num_residuals: int
    num_steps: int
    result: optx.RESULTS
    solver: Solver
    solver_name: str
    seconds: float
    criteria: dict = dataclasses.field(default_factory=dict)

    @property
    def converged(self) -> bool:
        return bool(self.result == optx.RESULTS.successful)

    @property
    def dof(self) -> int:
        return max(1, self.num_residuals - self.layout.size)

    @property
    def reduced_chi_square(self) -> float:
        return self.chi_square / self.dof

    @property
    def bic(self) -> float:
        return calc_bic(self.chi_square, self.num_residuals, self.layout.size)

    @property
    def std_log(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def _estimate(self, name: str, positive: bool = True) -> Estimate:
        k = self.names.index(name)
        value = float(np.exp(self.x[k])) if positive else float(self.x[k])
        return Estimate(value, value * float(self.std_log[k]) if positive else float(self.std_log[k]))

    @property
    def long_term_modulus(self) -> Estimate:
        return self._estimate("log_long_term_modulus")

    @property
    def terms(self) -> list[tuple[Estimate, Estimate]]:
        """(Eᵢ, τᵢ) estimates, τ ascending."""
        pairs = [(self._estimate(f"log_modulus_{k + 1}"), self._estimate(f"log_tau_{k + 1}")) for k in range(self.layout.num_terms)]
        return sorted(pairs, key=lambda pair: pair[1].value)

    def identification(self) -> list[tuple[tuple[bool, str], tuple[bool, str]]]:
        """Per term of :attr:`terms`: ((Eᵢ identified, why not), (τᵢ identified, why
        not)). A τ outside [sampling step / 10, 10 x the longest log] or with a standard
        error above it is not identified (nor is its Eᵢ: the term is then any slow or
        fast remainder); a term under :data:`MIN_TERM_FRACTION` of E(0) moves no
        reading, so neither number is measured, however small its standard error."""
        step = float(np.median(np.concatenate([np.diff(np.asarray(log.times)) for log in self.problem.logs])))
        span = max(float(np.asarray(log.times)[-1] - np.asarray(log.times)[0]) for log in self.problem.logs)
        total = self.instantaneous_modulus.value
        result = []
        for modulus, tau in self.terms:
            time_ok = identify_time(tau.value, tau.std, step, span)
            if modulus.value < MIN_TERM_FRACTION * total:
                small = (False, f"under {MIN_TERM_FRACTION:.0e} of E(0): the term moves no reading")
                result.append((small, small))
                continue
            modulus_ok = identify_modulus(modulus.value, modulus.std)
            if not time_ok[0]:
                modulus_ok = (False, f"its τ is not identified ({time_ok[1]})")
            result.append((modulus_ok, time_ok))
        return result

    def unidentified(self) -> list[str]:
        """Names (E1, τ1, ...) of the parameters the data do not identify."""
        names = []
        for k, ((modulus_ok, _), (tau_ok, _)) in enumerate(self.identification()):
            names += [name for name, ok in ((f"E{k + 1}", modulus_ok), (f"τ{k + 1}", tau_ok)) if not ok]
        return names + [name for name, (ok, _) in self.rig_identification().items() if not ok]

    @property
    def instantaneous_modulus(self) -> Estimate:
        """E(0) = E∞ + Σ Eᵢ, its error from the covariance (gradient of a sum of exps)."""
        k = [i for i, name in enumerate(self.names) if name == "log_long_term_modulus" or name.startswith("log_modulus_")]
        values = np.exp(self.x[k])
        value = float(values.sum())
        return Estimate(value, float(np.sqrt(max(values @ self.covariance[np.ix_(k, k)] @ values, 0.0))))

    @property
    def prony(self) -> Prony:
        terms = self.terms
        return Prony(jnp.asarray(self.long_term_modulus.value), jnp.asarray([m.value for m, _ in terms]), jnp.asarray([t.value for _, t in terms]))

    @property
    def gains(self) -> dict:
        """Each free gain (sensor/channel -> Estimate), in the problem's order.
        Relative gains: the reference's last is the inverse of the reference's
        others' product; its error from their covariance."""
        names, derived = self.problem.gain_names, self.layout.derived_gain
        result = {}
        for j, name in enumerate(names):
            if j != derived:
                result[name] = self._estimate(f"log_gain[{name}]")
                continue
            k = [self.names.index(f"log_gain[{other}]") for other in names[:j]]
            value = float(np.exp(-np.sum(self.x[k])))
            result[name] = Estimate(value, value * float(np.sqrt(max(np.sum(self.covariance[np.ix_(k, k)]), 0.0))))
        return result

    def gains_outside_the_mean(self) -> list[str]:
        """Relative gains: the channels (sensor/channel) whose readings did not move as
        the model's response does, against the others (dead, misplaced, or beyond the
        model): fitted on their own, outside the reference's geometric mean."""
        return list(self.problem.gain_names[self.layout.num_reference_gains :]) if self.layout.relative_gains else []

    def offsets(self) -> list[dict]:
        """Per log: channel -> offset estimate (Pa); with a drifting baseline, its
        value at the log's first sample."""
        result = []
        for k, (info, log, size) in enumerate(zip(self.problem.infos, self.problem.logs, self.layout.drifts)):
            entries = {}
            for c, channel in enumerate(info.channels):
                base, scale = float(log.offset_base[c]), float(log.offset_scale[c])
                if size == 1:
                    theta = self._estimate(f"offset[{k + 1}/{channel}]", positive=False)
                    entries[channel] = Estimate(base + scale * theta.value, scale * theta.std)
                    continue
                index = [self.names.index(f"drift[{k + 1}/{channel}/{j + 1}]") for j in range(size)]
                row = np.asarray(log.drift)[0]
                variance = float(row @ self.covariance[np.ix_(index, index)] @ row)
                entries[channel] = Estimate(base + scale * float(row @ self.x[index]), scale * float(np.sqrt(max(variance, 0.0))))
            result.append(entries)
        return result

    def rig_parameters(self) -> dict:
        """The rig's parameters (m, s): name -> Estimate (standard error 0 where fixed);
        empty without a rig."""
        rig = self.problem.rig
        if rig is None:
            return {}
        centre, half = np.asarray(rig.centre), np.asarray(rig.half)
        u = np.zeros(len(centre))
        std = np.zeros(len(centre))
        for k in self.layout.rig_free:
            index = self.names.index(f"rig[{rig.names[k]}]")
            u[k], std[k] = self.x[index], self.std_log[index]
        values = centre + half * np.tanh(u)
        stds = half * (1.0 - np.tanh(u) ** 2) * std
        return {name: Estimate(float(v), float(e)) for name, v, e in zip(rig.names, values, stds)}

    def rig_identification(self) -> dict:
        """Per fitted rig parameter: (identified, why not): one within 2 % of its
        range from a bound is where the bound stopped it, not where the logs put it."""
        rig = self.problem.rig
        if rig is None:
            return {}
        result = {}
        for k in self.layout.rig_free:
            u = self.x[self.names.index(f"rig[{rig.names[k]}]")]
            result[rig.names[k]] = (True, "") if abs(np.tanh(u)) < BOUND_FRACTION else (False, "at a bound of the rig's range")
        return result

    def predictions(self) -> list[np.ndarray]:
        return [np.asarray(p) for p in _predict(jnp.asarray(self.x), self.problem.without_infos(), self.layout)]

    def residual_diagnostics(self) -> list[dict]:
        """Per log and column: RMS residual (data units), RMS in noise units, lag-1
        autocorrelation of the residual (near 0 for white residuals) and the largest
        |residual|."""
        diagnostics = []
        for info, log, prediction in zip(self.problem.infos, self.problem.logs, self.predictions()):
            residual = np.asarray(log.observed) - prediction
            columns = {}
            for c, name in enumerate(info.channels + info.force_columns):
                r = residual[:, c] - residual[:, c].mean()
                lag1 = float(np.dot(r[1:], r[:-1]) / max(np.dot(r, r), 1e-300))
                columns[name] = {
                    "rms": float(np.sqrt(np.mean(residual[:, c] ** 2))),
                    "rms_in_noise": float(np.sqrt(np.mean(residual[:, c] ** 2)) / info.noise[c]),
                    "noise": float(info.noise[c]),
                    "lag1_autocorrelation": lag1,
                    "max_abs": float(np.max(np.abs(residual[:, c]))),
                }
            diagnostics.append({"source": info.source, "columns": columns})
        return diagnostics


@eqx.filter_jit
def _predict(x, problem, layout):
    return calc_predictions(x, problem, layout)


def _residual_fn(layout):
    return lambda x, problem: calc_residuals(x, problem, layout)


@eqx.filter_jit
def _run(problem: FitProblem, layout: ParameterLayout, x0, solver: Solver, bounds, max_steps: int | None):
    """The solution (never raising), χ² and the normal matrix JᵀJ at it."""
    residual_fn = _residual_fn(layout)
    solution = solve_least_squares(residual_fn, x0, problem, solver, max_steps=max_steps, bounds=bounds, throw=False)
    residuals = residual_fn(solution.value, problem)
    jacobian = calc_jacobian(residual_fn, solution.value, problem)
    return solution, jnp.sum(residuals**2), jacobian.T @ jacobian


def fit_parameters(problem: FitProblem, layout: ParameterLayout, x0, solver: Solver | None = None, *, max_steps: int | None = None, throw: bool = True):
    """The fitted x alone (pure): differentiable in the problem's data through the
    implicit function theorem (for the optimistix solvers).

    **Arguments:** `solver` a solver object (None: Levenberg–Marquardt); `max_steps`
    the step cap (None: the solver's default); `throw` fail, rather than return the
    last iterate, when the solve does not converge (an error when the computation
    runs, under jit).
    """
    return solve_least_squares(_residual_fn(layout), x0, problem, solver, max_steps=max_steps, throw=throw).value


def make_initial_guess(problem: FitProblem, num_terms: int) -> tuple[ParameterLayout, np.ndarray]:
    """A layout for `num_terms` Prony terms and the linear-fit start (host)."""
    layout = make_layout(problem, num_terms)
    times_list = [np.asarray(log.times) for log in problem.logs]
    grid = make_tau_grid(times_list)
    gains = np.asarray(problem.gain_starts) if problem.gain_starts else np.ones(layout.num_gains)
    scales = [np.concatenate([np.append(gains, 1.0)[np.asarray(log.gain_index)], np.ones(log.inputs.shape[1] - log.num_channels)]) for log in problem.logs]
    blocks = [design_block(log.times, np.asarray(log.inputs) * scale, log.observed, log.weights, log.num_channels, grid) for log, scale in zip(problem.logs, scales)]
    moduli = fit_linear_moduli(blocks)
    total = max(float(moduli.sum()), 1e-300)
    floor = _MODULUS_FLOOR * total
    long_term = max(float(moduli[0]), floor)
    taus, term_moduli = merge_terms(grid, moduli[1:], num_terms, floor)
    rig = () if problem.rig is None else rig_start(problem.rig, layout.rig_free, problem.rig_start)
    x0 = pack(layout, long_term=long_term, moduli=term_moduli, taus=taus, gains=gains, offsets=np.zeros(layout.num_offsets), rig=rig)
    # Baselines: each channel's misfit at the start, in noise units, on its drift basis
    # (its mean, for a constant offset), over the samples that count.
    predictions = _predict(jnp.asarray(x0), problem.without_infos(), layout)
    first = layout.num_material + layout.num_gain_parameters
    for log, prediction, size in zip(problem.logs, predictions, layout.drifts):
        count = log.num_channels
        misfit = (np.asarray(log.observed)[:, :count] - np.asarray(prediction)[:, :count]) / np.asarray(log.offset_scale)
        basis, used = np.asarray(log.drift), np.asarray(log.weights)[:, :count] > 0.0
        for c in range(count):
            rows = used[:, c] if used[:, c].sum() >= size else np.ones(len(basis), dtype=bool)
            x0[first + c * size : first + (c + 1) * size] = np.linalg.lstsq(basis[rows], misfit[rows, c], rcond=None)[0]
        first += count * size
    return layout, x0


def _bounds(problem: FitProblem, layout: ParameterLayout, x0: np.ndarray):
    """Box bounds for L-BFGS-B: τ within [shortest step / 10, 10 × span], moduli and
    gains within 10⁻⁶..10⁶ of the start, offsets free."""
    lower, upper = np.full_like(x0, -1e12), np.full_like(x0, 1e12)
    shortest = min(float(np.min(np.diff(np.asarray(log.times)))) for log in problem.logs)
    span = max(float(log.times[-1] - log.times[0]) for log in problem.logs)
    k = slice(1 + layout.num_terms, 1 + 2 * layout.num_terms)
    lower[k], upper[k] = np.log(shortest / 10.0), np.log(10.0 * span)
    for sl in (slice(0, 1 + layout.num_terms), slice(layout.num_material, layout.num_material + layout.num_gain_parameters)):
        lower[sl], upper[sl] = x0[sl] - np.log(1e6), x0[sl] + np.log(1e6)
    return jnp.asarray(lower), jnp.asarray(upper)


def fit_problem(problem: FitProblem, num_terms: int, solver: Solver | None = None, *, max_steps: int | None = None, throw: bool = False) -> FitResult:
    """Fit `num_terms` Prony terms (with gains and offsets) to the problem (host).

    **Arguments:** `solver` a solver object (None: Levenberg–Marquardt; BoundedLBFGSB
    gets box bounds on τ, moduli and gains); `max_steps` the step cap (None: the
    solver's default); `throw` raise a HydrotactError with the result's message if
    the solve does not converge (else the result says so: `result`, `converged`).
    """
    solver = check_solver(solver)
    if int(num_terms) < 0:
        raise HydrotactError(f"the number of Prony terms must be 0 or more, got {num_terms}")
    start = time.perf_counter()
    layout, x0 = make_initial_guess(problem, int(num_terms))
    bounds = _bounds(problem, layout, x0) if isinstance(solver, BoundedLBFGSB) else None
    solution, chi_square, normal = _run(problem.without_infos(), layout, jnp.asarray(x0), solver, bounds, max_steps)
    if throw:
        raise_if_failed(solution, solver)
    num_residuals = problem.num_samples
    covariance = calc_covariance(float(chi_square), np.asarray(normal), num_residuals)
    return FitResult(
        problem=problem,
        layout=layout,
        x=np.asarray(solution.value),
        names=layout.names(problem),
        covariance=covariance,
        chi_square=float(chi_square),
        num_residuals=num_residuals,
        num_steps=int(solution.num_steps),
        result=solution.result,
        solver=solver,
        solver_name=solver_name(solver),
        seconds=time.perf_counter() - start,
    )


def fit_auto(problem: FitProblem, solver: Solver | None = None, max_terms: int = MAX_AUTO_TERMS, progress=None, *, max_steps: int | None = None, throw: bool = False) -> FitResult:
    """Fit 0..max_terms Prony terms; keep the lowest BIC. `progress(k)` is called
    after each fit, if given; `solver`, `max_steps` and `throw` as for
    :func:`fit_problem` (with `throw`, any of the fits failing raises)."""
    solver = check_solver(solver)
    results = {}
    for num_terms in range(max_terms + 1):
        results[num_terms] = fit_problem(problem, num_terms, solver, max_steps=max_steps, throw=throw)
        if progress is not None:
            progress(num_terms)
    criteria = {k: result.bic for k, result in results.items()}
    best = min(criteria, key=criteria.get)
    return dataclasses.replace(results[best], criteria=criteria)
