"""The solvers a fit can use, behind one call (pure, jittable).

Least squares with optimistix (Levenberg–Marquardt by default; Gauss–Newton with a
backtracking line search, Dogleg),
or minimisation of ½‖r‖² with optimistix's BFGS or jaxopt's bounded L-BFGS-B. The
optimistix solutions are differentiable in the data through the implicit function
theorem (`optimistix.ImplicitAdjoint`).
"""

import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp

with warnings.catch_warnings():  # jaxopt (in maintenance) warns on import that it is deprecated
    warnings.simplefilter("ignore", DeprecationWarning)
    import jaxopt
import lineax as lx
import optimistix as optx

SOLVERS = ("lm", "gn", "dogleg", "bfgs", "lbfgsb")


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


def solve_least_squares(residual_fn, x0, args, solver: str = "lm", *, rtol: float = 1e-10, atol: float = 1e-10, max_steps: int = 400, bounds=None):
    """Minimise ½‖residual_fn(x, args)‖² from x0.

    **Arguments:** `solver` one of SOLVERS; `bounds` (lower, upper) arrays like x, used
    by "lbfgsb" only (the others are unbounded: positive parameters are logarithms).

    **Returns:** (x, number of steps, converged flag).
    """
    if solver in ("lm", "gn", "dogleg"):
        if solver == "lm":
            # The damped normal equations are positive definite: Cholesky on JᵀJ + λI is
            # several times faster than QR of the tall Jacobian (many samples, few
            # parameters) and accurate enough for a step.
            method = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
        else:
            method = {"gn": GaussNewtonArmijo, "dogleg": optx.Dogleg}[solver](rtol=rtol, atol=atol)
        solution = optx.least_squares(residual_fn, method, x0, args, max_steps=max_steps, throw=False)
        return solution.value, solution.stats["num_steps"], solution.result == optx.RESULTS.successful
    loss = lambda x, args: 0.5 * jnp.sum(residual_fn(x, args) ** 2)  # noqa: E731
    if solver == "bfgs":
        solution = optx.minimise(loss, optx.BFGS(rtol=rtol, atol=atol), x0, args, max_steps=max_steps * 10, throw=False)
        return solution.value, solution.stats["num_steps"], solution.result == optx.RESULTS.successful
    if solver == "lbfgsb":
        lower, upper = bounds if bounds is not None else (jnp.full_like(x0, -jnp.inf), jnp.full_like(x0, jnp.inf))
        scale = jnp.maximum(loss(x0, args), 1.0)
        optimiser = jaxopt.LBFGSB(fun=lambda x: loss(x, args) / scale, maxiter=max_steps * 10, tol=atol, implicit_diff=False)
        value, state = optimiser.run(jnp.clip(x0, lower, upper), bounds=(lower, upper))
        return value, state.iter_num, state.error <= atol
    raise ValueError(f"unknown solver {solver!r}; use one of {', '.join(SOLVERS)}")


def calc_jacobian(residual_fn, x, args):
    """The residuals' Jacobian at x (forward mode: few parameters, many residuals)."""
    return jax.jacfwd(residual_fn)(x, args)
