"""The solvers a fit can use, behind one call (pure, jittable).

A solver is an object holding settings only, and its type picks the method:
any `optimistix.AbstractLeastSquaresSolver` minimises ½‖r‖² with the residuals
(Levenberg–Marquardt by default; Gauss–Newton with a backtracking line search,
Dogleg), any `optimistix.AbstractMinimiser` (e.g. BFGS) minimises ½‖r‖² as a scalar,
and :class:`BoundedLBFGSB` runs jaxopt's bounded L-BFGS-B. The optimistix solutions
are differentiable in the data through the implicit function theorem
(`optimistix.ImplicitAdjoint`). Failures come back as an `optimistix.RESULTS` code in
the solution, or as an error with `throw=True`.

`SOLVERS` names the choices the command line offers (`hydrotact fit --solver`);
`solver_name` gives a solver's name back for the report.
"""

import functools
import types
import warnings
from collections.abc import Callable
from typing import TypeAlias

import equinox as eqx
import jax
import jax.numpy as jnp

with warnings.catch_warnings():  # jaxopt (in maintenance) warns on import that it is deprecated
    warnings.simplefilter("ignore", DeprecationWarning)
    import jaxopt
import lineax as lx
import optimistix as optx

from .._errors import HydrotactError
from .._types import Array, Float, Int


def _quiet(**_) -> None:
    """The solver's verbose hook, silent."""


class GaussNewtonArmijo(optx.AbstractGaussNewton):
    """Gauss–Newton steps with a backtracking (Armijo) line search: plain
    Gauss–Newton (optimistix.GaussNewton) takes every full step and can run off from
    a start that Levenberg–Marquardt handles; the line search keeps each step a
    decrease of ½‖r‖²."""

    rtol: float
    atol: float
    norm: Callable = optx.max_norm
    descent: optx.AbstractDescent = optx.NewtonDescent()
    search: optx.AbstractSearch = optx.BacktrackingArmijo()
    verbose: Callable = _quiet


class LevenbergMarquardt(optx.AbstractGaussNewton):
    """Levenberg–Marquardt (optimistix's: damped Newton steps in a classical trust
    region) that also stops when, after a rejected step, the next step it would try
    is below `xtol` (1 + ‖y‖∞) in every coordinate (MINPACK's xtol test).

    optimistix's Cauchy test asks every residual to change by less than atol + rtol
    |rᵢ|, so with thousands of residuals, some near 0, it ends only once an accepted
    step is ~1e-10 in size. Where the cost has kinks (a contact that starts pushing
    between samples, the press fit's max(0, ·)), no smooth step improves on a point
    long before that, and the solver spends the rest shrinking its region a quarter
    at a time: on the real-size press stand-in, 26 of 45 steps (each a Jacobian)
    after the cost had stopped moving. With xtol 1e-6 the parameters are settled far
    below their standard errors when it stops.
    """

    rtol: float
    atol: float
    norm: Callable = optx.max_norm
    descent: optx.AbstractDescent = optx.DampedNewtonDescent()
    search: optx.AbstractSearch = optx.ClassicalTrustRegion()
    verbose: Callable = _quiet
    xtol: float = 1e-6

    def terminate(self, fn, y, args, options, state, tags):
        done, result = super().terminate(fn, y, args, options, state, tags)
        step = optx.max_norm(jax.tree.map(lambda a, b: a - b, state.y_eval, y))
        stalled = (state.num_steps_since_acceptance >= 1) & (step <= self.xtol * (1.0 + optx.max_norm(y)))
        return done | stalled, result


class BoundedLBFGSB(eqx.Module):
    """Settings for jaxopt's L-BFGS-B on ½‖r‖² (scaled by its value at the start,
    when above 1), the one solver that takes box bounds.

    **Fields:** `tol` the stopping tolerance on the projected gradient's norm (of the
    scaled loss); `history_size` the number of (step, gradient change) pairs kept for
    the inverse-Hessian estimate.
    """

    tol: float = 1e-10
    history_size: int = 10

    def __check_init__(self):
        if not self.tol > 0.0:
            raise HydrotactError(f"BoundedLBFGSB: tol must be positive, got {self.tol}")
        if int(self.history_size) < 1:
            raise HydrotactError(f"BoundedLBFGSB: history_size must be 1 or more, got {self.history_size}")


Solver: TypeAlias = optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser | BoundedLBFGSB

_TOLERANCE = 1e-10

SOLVERS: types.MappingProxyType[str, Callable[[], Solver]] = types.MappingProxyType(
    {
        # The damped normal equations are positive definite: Cholesky on JᵀJ + λI is
        # several times faster than QR of the tall Jacobian (many samples, few
        # parameters) and accurate enough for a step.
        "lm": functools.partial(LevenbergMarquardt, rtol=_TOLERANCE, atol=_TOLERANCE, descent=optx.DampedNewtonDescent(linear_solver=lx.Normal(lx.Cholesky()))),
        "gn": functools.partial(GaussNewtonArmijo, rtol=_TOLERANCE, atol=_TOLERANCE),
        "dogleg": functools.partial(optx.Dogleg, rtol=_TOLERANCE, atol=_TOLERANCE),
        "bfgs": functools.partial(optx.BFGS, rtol=_TOLERANCE, atol=_TOLERANCE),
        "lbfgsb": functools.partial(BoundedLBFGSB, tol=_TOLERANCE),
    }
)
"""The named solvers (name -> a function making one, settings as `hydrotact fit` uses
them): "lm" Levenberg–Marquardt (the default), "gn" Gauss–Newton with a line search,
"dogleg", "bfgs" (minimising ½‖r‖²) and "lbfgsb" (bounded)."""


def make_solver(name: str) -> Solver:
    """The solver named `name` in SOLVERS; a HydrotactError naming the choices if
    there is none."""
    try:
        return SOLVERS[name]()
    except (KeyError, TypeError):
        raise HydrotactError(f"unknown solver {name!r}; use one of {', '.join(SOLVERS)}") from None


def solver_name(solver: Solver) -> str:
    """The SOLVERS name of a solver with that choice's settings exactly, else its
    class name (e.g. "LevenbergMarquardt" with other tolerances)."""
    for name, make in SOLVERS.items():
        candidate = make()
        if type(candidate) is type(solver) and eqx.tree_equal(candidate, solver) is True:
            return name
    return type(solver).__name__


def check_solver(solver) -> Solver:
    """The solver, or the default (Levenberg–Marquardt) for None; a HydrotactError
    for anything that is not a solver object (a name included)."""
    if solver is None:
        return SOLVERS["lm"]()
    if not isinstance(solver, (optx.AbstractLeastSquaresSolver, optx.AbstractMinimiser, BoundedLBFGSB)):
        hint = f"; for a named one use make_solver({solver!r}) (one of {', '.join(SOLVERS)})" if isinstance(solver, str) else ""
        raise HydrotactError(f"solver: expected an optimistix least-squares solver or minimiser, or BoundedLBFGSB, got {type(solver).__name__}{hint}")
    return solver


def default_max_steps(solver: Solver) -> int:
    """The step cap when none is given: 400 for least-squares solvers, 4000 for the
    minimisers (each of their steps uses one gradient, not a Jacobian)."""
    return 400 if isinstance(solver, optx.AbstractLeastSquaresSolver) else 4000


class LeastSquaresSolution(eqx.Module):
    """The outcome of :func:`solve_least_squares`.

    **Fields:** `value` the last iterate, like x0; `result` an `optimistix.RESULTS`
    code (`successful`; `nonlinear_max_steps_reached` when the cap stopped the solve;
    `optimistix.RESULTS[result]` is its message); `num_steps` the steps taken.
    """

    value: Float[Array, " num_parameters"]
    result: optx.RESULTS
    num_steps: Int[Array, ""]

    @property
    def converged(self):
        """Whether the solve met its tolerances (a boolean array)."""
        return self.result == optx.RESULTS.successful


def _half_squared_norm(residual_fn):
    return lambda x, args: 0.5 * jnp.sum(residual_fn(x, args) ** 2)


def _solve_lbfgsb(residual_fn, x0, args, solver: BoundedLBFGSB, max_steps: int, bounds) -> LeastSquaresSolution:
    loss = _half_squared_norm(residual_fn)
    lower, upper = bounds if bounds is not None else (jnp.full_like(x0, -jnp.inf), jnp.full_like(x0, jnp.inf))
    scale = jnp.maximum(loss(x0, args), 1.0)
    optimiser = jaxopt.LBFGSB(fun=lambda x: loss(x, args) / scale, maxiter=max_steps, tol=solver.tol, history_size=solver.history_size, implicit_diff=False)
    value, state = optimiser.run(jnp.clip(x0, lower, upper), bounds=(lower, upper))
    # jaxopt stops when the error is within tol or at maxiter (a NaN error stops it too).
    stopped = optx.RESULTS.where(jnp.isfinite(state.error), optx.RESULTS.nonlinear_max_steps_reached, optx.RESULTS.nonfinite)
    result = optx.RESULTS.where(state.error <= solver.tol, optx.RESULTS.successful, stopped)
    return LeastSquaresSolution(value, result, jnp.asarray(state.iter_num))


def _is_traced(tree) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


def raise_if_failed(solution: LeastSquaresSolution, solver: Solver) -> LeastSquaresSolution:
    """The solution, if it converged; else a HydrotactError with the result's message
    (outside jit), or a runtime error when the traced computation runs (inside jit,
    `equinox.error_if`)."""
    if _is_traced(solution):
        return eqx.tree_at(lambda s: s.value, solution, solution.result.error_if(solution.value, ~solution.converged))
    if not bool(solution.converged):
        message = optx.RESULTS[solution.result]
        raise HydrotactError(f"the {solver_name(solver)} solver failed after {int(solution.num_steps)} steps: {message}")
    return solution


def solve_least_squares(residual_fn, x0, args, solver: Solver | None = None, *, max_steps: int | None = None, bounds=None, throw: bool = True) -> LeastSquaresSolution:
    """Minimise ½‖residual_fn(x, args)‖² from x0.

    **Arguments:** `solver` a solver object (see the module docstring; None is
    SOLVERS["lm"]); `max_steps` the step cap (None: :func:`default_max_steps`);
    `bounds` (lower, upper) arrays like x, for BoundedLBFGSB only (the others are
    unbounded: positive parameters are logarithms); `throw` raise if the solve fails
    (see :func:`raise_if_failed`) rather than only report it in the result code.

    **Returns:** a :class:`LeastSquaresSolution`.
    """
    solver = check_solver(solver)
    max_steps = default_max_steps(solver) if max_steps is None else int(max_steps)
    if bounds is not None and not isinstance(solver, BoundedLBFGSB):
        raise HydrotactError(f"bounds: only BoundedLBFGSB takes bounds, not {type(solver).__name__}")
    if isinstance(solver, optx.AbstractLeastSquaresSolver):
        solution = optx.least_squares(residual_fn, solver, x0, args, max_steps=max_steps, throw=False)
        solution = LeastSquaresSolution(solution.value, solution.result, solution.stats["num_steps"])
    elif isinstance(solver, optx.AbstractMinimiser):
        solution = optx.minimise(_half_squared_norm(residual_fn), solver, x0, args, max_steps=max_steps, throw=False)
        solution = LeastSquaresSolution(solution.value, solution.result, solution.stats["num_steps"])
    else:
        solution = _solve_lbfgsb(residual_fn, x0, args, solver, max_steps, bounds)
    return raise_if_failed(solution, solver) if throw else solution


def calc_jacobian(residual_fn, x, args):
    """The residuals' Jacobian at x (forward mode: few parameters, many residuals)."""
    return jax.jacfwd(residual_fn)(x, args)
