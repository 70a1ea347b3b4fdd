"""The strain field: Laplace's equation with Dirichlet data on the tagged faces.

    laplacian(e) = 0 in the elastomer,  e = 0 on `free` faces,  e = 1 on `core` faces,
    grad(e) . n = 0 on `insulated` faces.

A vertex on both a free and a core face (the rim where the skin meets the PCB) takes
the free value: the skin must be at zero pressure everywhere, so that contact starts
at zero pressure. Shapes without a core can instead fix e = 1 at every vertex at least
`core_depth` below the free skin (an inner offset surface).

The Dirichlet problem is solved as one symmetric positive definite system over all
vertices: A = P K P + (I - P) with P the diagonal mask of the unknown vertices, and
b = -P K u_D. Preconditioned conjugate gradients (lineax) solve it; lineax's
implicit rule differentiates through the solve (dx = A^{-1}(db - dA x)), so
gradients with respect to the vertex positions and the boundary values cost one more
solve and never unroll the iterations.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np

from .._errors import HydrotactError, where
from .._geometry import calc_distance_to_triangles
from .._types import Array, Bool, Float, Int
from ..mesh import CORE, FREE, TetMesh
from ._assembly import StiffnessPattern, apply_stiffness, calc_stiffness_values, make_stiffness_pattern


class LaplaceProblem(eqx.Module):
    """Everything the strain solve needs, built once on the host (a pytree).

    **Fields:**

    - `vertices`: (num_vertices, 3) in metres; differentiate with respect to these.
    - `tets`: (num_tets, 4).
    - `pattern`: the stiffness sparsity pattern.
    - `is_free_vertex`, `is_core_vertex`: (num_vertices,) Dirichlet masks (disjoint).
    """

    vertices: Float[Array, "num_vertices 3"]
    tets: Int[Array, "num_tets 4"]
    pattern: StiffnessPattern
    is_free_vertex: Bool[Array, " num_vertices"]
    is_core_vertex: Bool[Array, " num_vertices"]

    @property
    def num_unknowns(self) -> int:
        return int(np.sum(~(np.asarray(self.is_free_vertex) | np.asarray(self.is_core_vertex))))


def make_laplace_problem(mesh: TetMesh, *, core_depth: float | None = None, source: str | None = None) -> LaplaceProblem:
    """Set up the strain solve for `mesh` (host).

    **Arguments:**

    - `mesh`: the elastomer; its `core` faces get e = 1, its `free` faces e = 0.
    - `core_depth`: if given, every vertex at least this far (metres) from the free
      skin is also fixed at e = 1 (the inner offset surface option, for shapes with
      no core faces).
    - `source`: the name to use in error messages.
    """
    is_free = mesh.vertices_tagged(FREE)
    is_core = mesh.vertices_tagged(CORE)
    if not is_free.any():
        raise HydrotactError(f"{where(source)}the mesh has no free faces: nothing can be touched")
    if core_depth is not None:
        core_depth = float(core_depth)
        if not np.isfinite(core_depth) or core_depth <= 0:
            raise HydrotactError(f"{where(source)}core_depth must be a positive length in metres, got {core_depth}")
        vertices = np.asarray(mesh.vertices)
        triangles = vertices[mesh.faces_tagged(FREE)]
        depth, _ = calc_distance_to_triangles(vertices, triangles)
        deep = np.asarray(depth) >= core_depth
        if not deep.any():
            raise HydrotactError(
                f"{where(source)}no vertex lies {core_depth:g} m or more below the free skin "
                f"(the deepest is {float(np.max(depth)):.3g} m): use a smaller core_depth"
            )
        is_core = is_core | deep
    elif not is_core.any():
        raise HydrotactError(
            f"{where(source)}the mesh has no core faces: tag the faces bonded to the PCB or insert "
            "as core, or give core_depth to fix the strain on an inner offset surface"
        )
    is_core = is_core & ~is_free
    return LaplaceProblem(
        vertices=np.asarray(mesh.vertices),
        tets=np.asarray(mesh.tets),
        pattern=make_stiffness_pattern(mesh.tets, mesh.num_vertices),
        is_free_vertex=is_free,
        is_core_vertex=is_core,
    )


class StrainSolution(eqx.Module):
    """The solved strain field and how the solve went.

    **Fields:**

    - `strain`: (num_vertices,) e at each vertex (dimensionless, 0 on the skin).
    - `num_steps`: CG iterations taken.
    - `relative_residual`: ||A e - b|| / ||b|| of the reduced system (2-norm).
    - `result`: lineax's result code (`lx.RESULTS.successful` when converged).
    """

    strain: Float[Array, " num_vertices"]
    num_steps: Int[Array, ""]
    relative_residual: Float[Array, ""]
    result: lx.RESULTS


def _default_rtol(dtype) -> float:
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-5


@eqx.filter_jit
def _solve(problem, vertices, dirichlet_values, rtol, max_steps, throw):
    values = calc_stiffness_values(problem.pattern, vertices, problem.tets)
    unknown = ~(problem.is_free_vertex | problem.is_core_vertex)
    mask = unknown.astype(values.dtype)
    fixed = jnp.where(unknown, 0.0, dirichlet_values)

    def operator_fn(x):
        return mask * apply_stiffness(problem.pattern, values, mask * x) + (1.0 - mask) * x

    rhs = -mask * apply_stiffness(problem.pattern, values, fixed)
    structure = jax.ShapeDtypeStruct(rhs.shape, rhs.dtype)
    operator = lx.FunctionLinearOperator(operator_fn, structure, tags=lx.positive_semidefinite_tag)
    diagonal = jax.lax.stop_gradient(mask * values[problem.pattern.diagonal] + (1.0 - mask))
    preconditioner = lx.TaggedLinearOperator(lx.DiagonalLinearOperator(1.0 / diagonal), lx.positive_semidefinite_tag)
    # lineax's CG stops when |r_i| <= atol + rtol |b_i| for every i; most b_i are 0, so
    # the absolute part scales with the largest entry of b.
    atol = rtol * jax.lax.stop_gradient(jnp.max(jnp.abs(rhs)))
    solver = lx.CG(rtol=rtol, atol=atol, max_steps=max_steps)
    solution = lx.linear_solve(
        operator, rhs, solver, options={"preconditioner": preconditioner}, throw=throw
    )
    x = solution.value
    residual = operator_fn(x) - rhs
    rhs_norm = jnp.linalg.norm(rhs)
    relative = jnp.linalg.norm(residual) / jnp.where(rhs_norm > 0, rhs_norm, 1.0)
    strain = jnp.where(unknown, x, fixed)
    return StrainSolution(
        strain=strain,
        num_steps=solution.stats["num_steps"],
        relative_residual=jax.lax.stop_gradient(relative),
        result=solution.result,
    )


def solve_strain(
    problem: LaplaceProblem,
    *,
    vertices=None,
    core_value=1.0,
    free_value=0.0,
    dirichlet_values=None,
    rtol: float | None = None,
    max_steps: int | None = None,
    throw: bool = True,
) -> StrainSolution:
    """Solve for the strain field e (jittable, vmappable, differentiable).

    **Arguments:**

    - `problem`: from :func:`make_laplace_problem`.
    - `vertices`: (num_vertices, 3) positions to solve on; default `problem.vertices`.
      Gradients with respect to them are exact (implicit adjoint).
    - `core_value`, `free_value`: Dirichlet values on core and free vertices.
    - `dirichlet_values`: optional (num_vertices,) values that replace both on the
      fixed vertices (for general boundary data).
    - `rtol`, `max_steps`: CG stops when every residual entry is at most `rtol`
      times the largest right-hand-side entry (and the last update is as small
      relative to the solution); `rtol` defaults to 1e-10 in float64, 1e-5 in float32.
    - `throw`: raise if CG did not converge; otherwise check `result`.

    **Returns:** a :class:`StrainSolution`.
    """
    if vertices is None:
        vertices = problem.vertices
    vertices = jnp.asarray(vertices)
    dtype = vertices.dtype
    if dirichlet_values is None:
        core_value = jnp.asarray(core_value, dtype)
        free_value = jnp.asarray(free_value, dtype)
        dirichlet_values = jnp.where(jnp.asarray(problem.is_core_vertex), core_value, free_value)
    dirichlet_values = jnp.asarray(dirichlet_values, dtype)
    if rtol is None:
        rtol = _default_rtol(dtype)
    if max_steps is None:
        max_steps = 10 * int(problem.vertices.shape[0]) + 100
    return _solve(problem, vertices, dirichlet_values, rtol, max_steps, throw)
