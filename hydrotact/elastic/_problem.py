"""Linear elasticity of the elastomer on quadratic tets, locking-free for silicone.

Small strains, isotropic, Young's modulus E and Poisson's ratio nu (shear modulus
mu = E / (2 (1 + nu)), bulk modulus kappa = E / (3 (1 - 2 nu))). Silicone is nearly
incompressible (nu 0.45-0.499), where a displacement-only element locks, so the stress
is split into its deviatoric part and the hydrostatic pressure p = -tr(sigma) / 3,
and p is a field of its own (the mixed P2-P0 element: quadratic displacements,
one pressure per tet):

    int 2 mu dev eps(u) : dev eps(v) dV - int p div v dV = int f . v dV + int t . v dA,
    int q (div u + p / kappa) dV = 0   for every piecewise constant q,

so sigma = 2 mu dev eps(u) - p I and p = -kappa (mean of div u over the tet). The
pressure is eliminated tet by tet (it is discontinuous), which leaves one symmetric
positive definite system in the displacements:

    K = int 2 mu dev eps : dev eps dV + sum over tets of kappa V m m^T,

with m the tet's mean divergence as a row over its 30 displacement unknowns. The
solution is the mixed method's exactly (scikit-fem's mixed P2-P0 assembly agrees to
round-off; tests/test_elastic.py), and as kappa grows the second term only enforces
div u ~ 0 tet by tet, which P2 displacements can satisfy without locking.

Faces tagged `core` (bonded to the PCB or insert) are fixed: every P2 node on them
has u = 0 (or the given Dirichlet values). The system is solved like the strain
field's: A = P K P + (I - P), b = P (f - K u_D), by preconditioned conjugate gradients
(lineax, 3 x 3 block-Jacobi preconditioner) with lineax's implicit adjoint, so
gradients in the vertex positions, nu and the loads cost one more solve.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np

from .._errors import HydrotactError, where
from .._linalg import inv3
from .._types import Array, Bool, Float, Int
from ..field import calc_tet_gradients
from ..field._solve import _default_rtol
from ..mesh import CORE, TetMesh
from ._quadratic import (
    BlockPattern,
    calc_node_positions,
    calc_shape_gradients,
    make_block_pattern,
    make_quadratic_nodes,
)

# The four-point rule on a tet, exact for quadratics (the deviatoric integrand).
_A, _B = 0.5854101966249685, 0.1381966011250105
TET_QUADRATURE = np.full((4, 4), _B) + np.eye(4) * (_A - _B)  # (points, barycentric)
# Silicone's range and the element's: nu = 0.5 (kappa infinite) is not a solid.
POISSON_RANGE = (-0.999, 0.4999)


class ElasticProblem(eqx.Module):
    """The elastomer's elasticity problem on P2 tets (a pytree, host-built).

    **Fields:**

    - `vertices`: (num_vertices, 3) m; the P2 nodes are the vertices then the edge
      midpoints, and move with them (differentiate with respect to these).
    - `tets`: (num_tets, 4); `edges`: (num_edges, 2); `tet_nodes`: (num_tets, 10).
    - `pattern`: the block sparsity pattern of K.
    - `is_fixed`: (num_nodes,) the nodes on core faces (u prescribed).
    - `poisson_ratio`: nu (a leaf: readings are differentiable in it).
    """

    vertices: Float[Array, "num_vertices 3"]
    tets: Int[Array, "num_tets 4"]
    edges: Int[Array, "num_edges 2"]
    tet_nodes: Int[Array, "num_tets 10"]
    pattern: BlockPattern
    is_fixed: Bool[Array, " num_nodes"]
    poisson_ratio: Float[Array, ""]

    @property
    def num_nodes(self) -> int:
        return self.pattern.num_nodes

    @property
    def num_unknowns(self) -> int:
        return 3 * int(np.sum(~np.asarray(self.is_fixed)))

    def calc_node_positions(self, vertices=None):
        """(num_nodes, 3) the P2 node positions, m."""
        return calc_node_positions(self.vertices if vertices is None else vertices, self.edges)


def check_poisson_ratio(poisson_ratio, source: str | None = None) -> float:
    """nu as a float, or one error naming it (host)."""
    try:
        value = float(poisson_ratio)
    except (TypeError, ValueError):
        raise HydrotactError(f"{where(source)}poisson_ratio must be a number, got {poisson_ratio!r}") from None
    low, high = POISSON_RANGE
    if not (np.isfinite(value) and low <= value <= high):
        raise HydrotactError(
            f"{where(source)}poisson_ratio must lie in [{low:g}, {high:g}] (0.5 is incompressible, "
            f"which no solid is; silicone is 0.45-0.499), got {value:g}"
        )
    return value


def make_elastic_problem(mesh: TetMesh, poisson_ratio=0.49, *, fixed_tag: int = CORE, source: str | None = None) -> ElasticProblem:
    """Set up the elastomer's elasticity problem (host).

    **Arguments:**

    - `mesh`: the elastomer; its faces tagged `fixed_tag` (core: bonded to the PCB)
      have their nodes fixed.
    - `poisson_ratio`: nu, in [-0.999, 0.4999]; silicone is 0.45-0.499.
    - `source`: the name to use in error messages.
    """
    nu = check_poisson_ratio(poisson_ratio, source)
    edges, tet_nodes, _ = make_quadratic_nodes(mesh.vertices, mesh.tets)
    num_vertices = mesh.num_vertices
    fixed_faces = mesh.faces_tagged(fixed_tag)
    if len(fixed_faces) == 0:
        raise HydrotactError(
            f"{where(source)}the mesh has no core faces: an elastomer with nothing fixed can move as a "
            "rigid body; tag the faces bonded to the PCB or insert as core"
        )
    is_fixed = np.zeros(num_vertices + len(edges), dtype=bool)
    is_fixed[fixed_faces.reshape(-1)] = True
    face_edges = np.sort(fixed_faces[:, [[0, 1], [1, 2], [0, 2]]], axis=-1).reshape(-1, 2)
    keys = edges[:, 0] * num_vertices + edges[:, 1]
    at = np.searchsorted(keys, face_edges[:, 0] * num_vertices + face_edges[:, 1])
    is_fixed[num_vertices + at] = True
    return ElasticProblem(
        vertices=np.asarray(mesh.vertices, dtype=np.float64),
        tets=np.asarray(mesh.tets),
        edges=edges.astype(np.asarray(mesh.tets).dtype),
        tet_nodes=tet_nodes.astype(np.asarray(mesh.tets).dtype),
        pattern=make_block_pattern(tet_nodes, num_vertices + len(edges)),
        is_fixed=is_fixed,
        poisson_ratio=np.asarray(nu, dtype=np.float64),
    )


def calc_lame(modulus, poisson_ratio):
    """(shear modulus mu, bulk modulus kappa) from E and nu."""
    return modulus / (2.0 * (1.0 + poisson_ratio)), modulus / (3.0 * (1.0 - 2.0 * poisson_ratio))


def calc_element_operators(problem: ElasticProblem, vertices):
    """Per tet: the shape gradients at the quadrature points (num_tets, 4, 10, 3), the
    quadrature weights (num_tets, 4) m^3 and the mean shape gradients m
    (num_tets, 10, 3) (the mean of div u over the tet is sum_a m_a . u_a)."""
    lambda_gradients, volumes = calc_tet_gradients(vertices, problem.tets)
    num_tets = lambda_gradients.shape[0]
    points = jnp.broadcast_to(jnp.asarray(TET_QUADRATURE, vertices.dtype)[None], (num_tets, 4, 4))  # (T, q, 4)
    gradients = calc_shape_gradients(points, jnp.broadcast_to(lambda_gradients[:, None], (num_tets, 4, 4, 3)))
    weights = jnp.broadcast_to(volumes[:, None] / 4.0, (volumes.shape[0], 4))
    mean_gradients = jnp.einsum("tq,tqad->tad", weights, gradients) / volumes[:, None, None]
    return gradients, weights, mean_gradients


def calc_stiffness_blocks(problem: ElasticProblem, vertices, poisson_ratio, modulus=1.0):
    """The entries of K in the pattern's flat block slots, (num_slots, 3, 3)."""
    mu, kappa = calc_lame(modulus, poisson_ratio)
    gradients, weights, mean_gradients = calc_element_operators(problem, vertices)
    dot = jnp.einsum("tq,tqad,tqbd->tab", weights, gradients, gradients)
    cross = jnp.einsum("tq,tqal,tqbk->tabkl", weights, gradients, gradients)
    eye = jnp.eye(3, dtype=vertices.dtype)
    volumes = jnp.sum(weights, axis=1)
    # 2 mu [1/2 d_kl g_a.g_b + 1/2 g_a,l g_b,k - 1/3 g_a,k g_b,l] + kappa V m_a,k m_b,l
    blocks = mu * (dot[..., None, None] * eye[None, None, None] + cross - (2.0 / 3.0) * jnp.swapaxes(cross, -1, -2))
    blocks = blocks + kappa * volumes[:, None, None, None, None] * jnp.einsum("tak,tbl->tabkl", mean_gradients, mean_gradients)
    return jax.ops.segment_sum(blocks.reshape(-1, 3, 3), problem.pattern.scatter, num_segments=problem.pattern.num_slots)


class ElasticSolution(eqx.Module):
    """Displacements and hydrostatic pressures of an elastic solve.

    **Fields:**

    - `displacements`: (num_nodes, 3) u at the P2 nodes, m.
    - `pressures`: (num_tets,) the hydrostatic pressure p = -tr(sigma) / 3 of each
      tet, Pa (positive in compression).
    - `num_steps`, `relative_residual`, `result`: how CG went (as the strain solve's).
    """

    displacements: Float[Array, "num_nodes 3"]
    pressures: Float[Array, " num_tets"]
    num_steps: Int[Array, ""]
    relative_residual: Float[Array, ""]
    result: lx.RESULTS


def calc_diagonal_blocks(problem: ElasticProblem, vertices, poisson_ratio, modulus=1.0):
    """The 3 x 3 diagonal blocks of K, (num_nodes, 3, 3)."""
    mu, kappa = calc_lame(modulus, poisson_ratio)
    gradients, weights, mean_gradients = calc_element_operators(problem, vertices)
    dot = jnp.einsum("tq,tqad,tqad->ta", weights, gradients, gradients)
    cross = jnp.einsum("tq,tqal,tqak->takl", weights, gradients, gradients)  # symmetric in k, l
    eye = jnp.eye(3, dtype=vertices.dtype)
    volumes = jnp.sum(weights, axis=1)
    blocks = mu * (dot[..., None, None] * eye[None, None] + cross / 3.0)
    blocks = blocks + kappa * volumes[:, None, None, None] * jnp.einsum("tak,tal->takl", mean_gradients, mean_gradients)
    return jax.ops.segment_sum(blocks.reshape(-1, 3, 3), problem.tet_nodes.reshape(-1), num_segments=problem.num_nodes)


def calc_reduced_system(problem: ElasticProblem, vertices, poisson_ratio, modulus):
    """The fixed-node-reduced operator A = P K P + (I - P) as a function, its
    block-Jacobi preconditioner and K itself (as a function of u).

    K u is applied element by element without assembling K (matrix-free): the strain
    at each tet's four quadrature points, the deviatoric stress, its virtual work
    against the shape gradients, plus the tet's volumetric term, summed into the
    nodes. It reads the shape gradients (num_tets x 120 numbers) instead of K's
    blocks (~9 x 125 numbers per node), several times less memory per product
    (:func:`calc_stiffness_blocks` assembles K for checks and other solvers)."""
    mu, kappa = calc_lame(modulus, poisson_ratio)
    gradients, weights, mean_gradients = calc_element_operators(problem, vertices)
    volumes = jnp.sum(weights, axis=1)
    dtype = vertices.dtype
    mask = (~problem.is_fixed).astype(dtype)[:, None]
    eye = jnp.eye(3, dtype=dtype)

    def stiffness(u):
        element_u = u[problem.tet_nodes]  # (T, 10, 3)
        grad_u = jnp.einsum("tak,tqal->tqkl", element_u, gradients)
        strain = 0.5 * (grad_u + jnp.swapaxes(grad_u, -1, -2))
        trace = jnp.trace(strain, axis1=-2, axis2=-1)
        stress = (2.0 * mu) * (strain - trace[..., None, None] * eye[None, None] / 3.0) * weights[:, :, None, None]
        forces = jnp.einsum("tqkl,tqal->tak", stress, gradients)
        divergence = jnp.einsum("tad,tad->t", mean_gradients, element_u)
        forces = forces + (kappa * volumes * divergence)[:, None, None] * mean_gradients
        return jax.ops.segment_sum(forces.reshape(-1, 3), problem.tet_nodes.reshape(-1), num_segments=problem.num_nodes)

    def operator_fn(u):
        return mask * stiffness(mask * u) + (1.0 - mask) * u

    diagonal = calc_diagonal_blocks(problem, vertices, poisson_ratio, modulus)
    diagonal = jnp.where(problem.is_fixed[:, None, None], eye[None], diagonal)
    inverse = jax.lax.stop_gradient(inv3(diagonal))  # closed form: no batched LAPACK (hydrotact._linalg)
    return operator_fn, inverse, stiffness


def _run_cg(problem, params, rhs, rtol, max_steps, throw, multigrid):
    """Preconditioned CG on A(params) x = rhs (lineax), never differentiated: the
    stopping rule's absolute part scales with this right-hand side's largest entry."""
    vertices, poisson_ratio, modulus = jax.lax.stop_gradient(params)
    rhs = jax.lax.stop_gradient(rhs)
    operator_fn, inverse, _ = calc_reduced_system(problem, vertices, poisson_ratio, modulus)
    structure = jax.ShapeDtypeStruct(rhs.shape, rhs.dtype)
    tags = (lx.symmetric_tag, lx.positive_semidefinite_tag)
    operator = lx.FunctionLinearOperator(operator_fn, structure, tags=tags)
    if multigrid is None:
        precondition = lambda r: jnp.einsum("nij,nj->ni", inverse, r)
    else:
        multigrid = jax.lax.stop_gradient(multigrid)
        precondition = lambda r: multigrid.apply(operator_fn, inverse, r)
    preconditioner = lx.FunctionLinearOperator(precondition, structure, tags=tags)
    # lineax's CG stops when |r_i| <= atol + rtol |b_i| for every i; most b_i are 0, so
    # the absolute part scales with the largest entry of b.
    atol = rtol * jnp.max(jnp.abs(rhs))
    solver = lx.CG(rtol=rtol, atol=atol, max_steps=max_steps)
    solution = lx.linear_solve(operator, rhs, solver, options={"preconditioner": preconditioner}, throw=throw)
    x = solution.value
    rhs_norm = jnp.linalg.norm(rhs)
    relative = jnp.linalg.norm(operator_fn(x) - rhs) / jnp.where(rhs_norm > 0, rhs_norm, 1.0)
    return x, (solution.stats["num_steps"], relative, solution.result)


@eqx.filter_custom_vjp
def _linear_solve(params_and_rhs, problem, rtol, max_steps, throw, multigrid):
    params, rhs = params_and_rhs
    return _run_cg(problem, params, rhs, rtol, max_steps, throw, multigrid)


@_linear_solve.def_fwd
def _linear_solve_fwd(perturbed, params_and_rhs, problem, rtol, max_steps, throw, multigrid):
    out = _linear_solve(params_and_rhs, problem, rtol, max_steps, throw, multigrid)
    return out, out[0]


@_linear_solve.def_bwd
def _linear_solve_bwd(x, grad_obj, perturbed, params_and_rhs, problem, rtol, max_steps, throw, multigrid):
    params, _ = params_and_rhs
    x_bar = grad_obj[0]
    if x_bar is None:
        return None
    # A is symmetric: the adjoint solve is a solve with A, its stopping rule scaled to
    # the cotangent (not to the forward right-hand side). Then
    # d(params) = -lambda . dA/d(params) x and d(rhs) = lambda.
    lam, _ = _run_cg(problem, params, x_bar, rtol, max_steps, throw, multigrid)
    _, pullback = jax.vjp(lambda p: calc_reduced_system(problem, *p)[0](x), params)
    (params_bar,) = pullback(-lam)
    return params_bar, lam


def solve_reduced(problem, params, rhs, rtol, max_steps, throw, multigrid=None):
    """Solve A(params) x = rhs, params = (vertices, nu, E), by preconditioned CG
    (lineax): block Jacobi, or a multigrid V-cycle (:class:`MultigridPreconditioner`)
    when given. Differentiable in reverse mode by the implicit adjoint (one more solve
    with A, whose stopping rule is scaled to the cotangent: lineax's own adjoint reuses
    the forward solve's absolute tolerance, which a cotangent of another scale never
    reaches); forward mode is not defined.

    **Returns:** (x, num_steps, relative residual ||A x - b|| / ||b||, result)."""
    x, (num_steps, relative, result) = _linear_solve((params, rhs), problem, rtol, max_steps, throw, multigrid)
    return x, num_steps, jax.lax.stop_gradient(relative), result


@eqx.filter_jit
def _solve(problem, vertices, poisson_ratio, modulus, loads, dirichlet_values, rtol, max_steps, throw, multigrid):
    _, _, stiffness = calc_reduced_system(problem, vertices, poisson_ratio, modulus)
    mask = (~problem.is_fixed).astype(loads.dtype)[:, None]
    fixed = (1.0 - mask) * dirichlet_values
    rhs = mask * (loads - stiffness(fixed))
    x, num_steps, relative, result = solve_reduced(problem, (vertices, poisson_ratio, modulus), rhs, rtol, max_steps, throw, multigrid)
    displacements = mask * x + fixed
    _, kappa = calc_lame(modulus, poisson_ratio)
    _, _, mean_gradients = calc_element_operators(problem, vertices)
    divergence = jnp.einsum("tad,tad->t", mean_gradients, displacements[problem.tet_nodes])
    return ElasticSolution(displacements, -kappa * divergence, num_steps, relative, result)


def solve_elasticity(
    problem: ElasticProblem,
    loads,
    *,
    modulus=1.0,
    poisson_ratio=None,
    vertices=None,
    dirichlet_values=None,
    rtol: float | None = None,
    max_steps: int | None = None,
    throw: bool = True,
    multigrid=None,
) -> ElasticSolution:
    """Solve for the elastomer's displacement and pressure (jittable, vmappable over
    loads, differentiable in the loads, vertices, E and nu by the implicit adjoint).

    **Arguments:**

    - `problem`: from :func:`make_elastic_problem`.
    - `loads`: (num_nodes, 3) consistent nodal forces, N (:func:`calc_point_loads`,
      :func:`calc_face_loads`, :func:`calc_body_loads` build them from point forces,
      surface tractions and body forces); entries at fixed nodes are ignored.
    - `modulus`: Young's modulus E, Pa. For loads given as forces the stresses do not
      depend on it (only the displacements scale as 1/E).
    - `poisson_ratio`: nu; default the problem's.
    - `vertices`: positions to solve on; default the problem's.
    - `dirichlet_values`: (num_nodes, 3) displacements of the fixed nodes, m (default 0).
    - `rtol`, `max_steps`, `throw`: as :func:`hydrotact.field.solve_strain`'s.
    - `multigrid`: a :class:`MultigridPreconditioner` of the problem (from
      :func:`make_multigrid_preconditioner`): far fewer CG steps on large meshes;
      default block Jacobi.

    **Returns:** an :class:`ElasticSolution`.
    """
    vertices = jnp.asarray(problem.vertices if vertices is None else vertices)
    dtype = vertices.dtype
    loads = jnp.asarray(loads, dtype)
    num_nodes = problem.pattern.num_nodes
    if loads.shape != (num_nodes, 3):
        raise HydrotactError(f"loads must be ({num_nodes}, 3) nodal forces, got shape {loads.shape}")
    nu = jnp.asarray(problem.poisson_ratio if poisson_ratio is None else poisson_ratio, dtype)
    dirichlet_values = jnp.zeros((num_nodes, 3), dtype) if dirichlet_values is None else jnp.asarray(dirichlet_values, dtype)
    rtol = _default_rtol(dtype) if rtol is None else rtol
    max_steps = 20 * num_nodes + 1000 if max_steps is None else max_steps
    return _solve(problem, vertices, nu, jnp.asarray(modulus, dtype), loads, dirichlet_values, rtol, max_steps, throw, multigrid)


def calc_stress(problem: ElasticProblem, solution: ElasticSolution, modulus=1.0, poisson_ratio=None, vertices=None):
    """The stress sigma = 2 mu dev eps(u) - p I at each tet's centroid, (num_tets, 3, 3) Pa."""
    vertices = jnp.asarray(problem.vertices if vertices is None else vertices)
    nu = problem.poisson_ratio if poisson_ratio is None else poisson_ratio
    mu, _ = calc_lame(modulus, nu)
    lambda_gradients, _ = calc_tet_gradients(vertices, problem.tets)
    centroid = jnp.full((4,), 0.25, vertices.dtype)
    gradients = calc_shape_gradients(centroid[None], lambda_gradients)  # (T, 10, 3)
    grad_u = jnp.einsum("tak,tal->tkl", solution.displacements[problem.tet_nodes], gradients)
    strain = 0.5 * (grad_u + jnp.swapaxes(grad_u, -1, -2))
    eye = jnp.eye(3, dtype=vertices.dtype)
    trace = jnp.trace(strain, axis1=-2, axis2=-1)
    deviatoric = strain - trace[:, None, None] * eye[None] / 3.0
    return 2.0 * mu * deviatoric - solution.pressures[:, None, None] * eye[None]

