"""A smoothed-aggregation algebraic multigrid preconditioner for the elastic solve.

Block-Jacobi CG needs thousands of steps on a sensor's P2 mesh at nu = 0.49 (2,072 on
sphere8's 124k unknowns), because its condition number grows as 1 / h^2 and with
kappa / mu. A multigrid V-cycle makes the step count nearly independent of h. The
hierarchy is pyamg's smoothed aggregation (aggregates of nodes, the six rigid-body
modes as the near-null space, Galerkin coarse operators), built once on the host from
the assembled K; the cycle itself runs in JAX as a preconditioner of lineax's CG:

- on the finest level, the matrix-free K with the damped 3 x 3 block-Jacobi smoother;
- on the coarse levels, pyamg's sparse operators with damped Jacobi;
- on the coarsest, a dense solve (its inverse, precomputed);
- the same number of smoothing steps before and after the coarse correction, each
  damped by 4 / (3 rho) (rho the spectral radius of the smoothed operator, estimated
  on the host), so the cycle is symmetric positive definite, as CG requires.

It only preconditions: the solution is the one CG converges to, its gradients come
from lineax's implicit adjoint through the operator, and the hierarchy (a constant)
is never differentiated. A hierarchy built at one nu still preconditions at another.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Float, Int
from ._problem import ElasticProblem, calc_diagonal_blocks, calc_stiffness_blocks

SMOOTHING_STEPS = 2
DENSE_COARSEST = 4000  # unknowns of the coarsest level, solved densely


class SparseMatrix(eqx.Module):
    """A sparse matrix as coordinate triplets (a pytree); `shape` static."""

    rows: Int[Array, " nnz"]
    cols: Int[Array, " nnz"]
    values: Float[Array, " nnz"]
    shape: tuple[int, int] = eqx.field(static=True)

    def __matmul__(self, x):
        return jax.ops.segment_sum(self.values * x[self.cols], self.rows, num_segments=self.shape[0])

    def rmatmul(self, x):
        """self.T @ x."""
        return jax.ops.segment_sum(self.values * x[self.rows], self.cols, num_segments=self.shape[1])


def _sparse(matrix) -> SparseMatrix:
    coo = matrix.tocoo()
    index = np.int32 if max(coo.shape) < 2**31 - 1 else np.int64
    return SparseMatrix(coo.row.astype(index), coo.col.astype(index), coo.data.astype(np.float64), tuple(int(n) for n in coo.shape))


class MultigridPreconditioner(eqx.Module):
    """The smoothed-aggregation hierarchy of an elastic problem (host-built pytree).

    **Fields:**

    - `free_dofs`: (n_0,) the flat unknowns (3 node + component) of the free nodes,
      in the order of the finest level.
    - `prolongations`: P_l, (n_l, n_{l+1}) for each level but the coarsest.
    - `operators`: the coarse levels' A_l (l >= 1; the finest is matrix-free).
    - `inverse_diagonals`: 1 / diag(A_l) of the coarse levels but the coarsest.
    - `dampings`: (levels - 1,) the Jacobi damping of each level but the coarsest.
    - `coarsest_inverse`: (n_L, n_L) dense.
    """

    free_dofs: Int[Array, " num_free"]
    prolongations: tuple[SparseMatrix, ...]
    operators: tuple[SparseMatrix, ...]
    inverse_diagonals: tuple[Float[Array, " n"], ...]
    dampings: Float[Array, " levels"]
    coarsest_inverse: Float[Array, "n n"]

    @property
    def num_levels(self) -> int:
        return len(self.prolongations) + 1

    def apply(self, operator_fn, inverse_blocks, r):
        """One symmetric V-cycle on the reduced residual r (num_nodes, 3): an
        approximation of A^{-1} r. `operator_fn` is the reduced operator A and
        `inverse_blocks` (num_nodes, 3, 3) its block-Jacobi inverse (identity on the
        fixed nodes)."""
        shape = r.shape
        if self.num_levels == 1:  # a problem small enough to solve densely
            exact = self.coarsest_inverse @ r.reshape(-1)[self.free_dofs]
            return r.reshape(-1).at[self.free_dofs].set(exact).reshape(shape)

        def smooth_fine(x, b):
            return x + self.dampings[0] * jnp.einsum("nij,nj->ni", inverse_blocks, b - operator_fn(x))

        x = self.dampings[0] * jnp.einsum("nij,nj->ni", inverse_blocks, r)
        for _ in range(SMOOTHING_STEPS - 1):
            x = smooth_fine(x, r)
        residual = (r - operator_fn(x)).reshape(-1)[self.free_dofs]
        correction = self._cycle(1, self.prolongations[0].rmatmul(residual))
        fine = jnp.zeros(shape[0] * shape[1], r.dtype).at[self.free_dofs].set(self.prolongations[0] @ correction)
        x = x + fine.reshape(shape)
        for _ in range(SMOOTHING_STEPS):
            x = smooth_fine(x, r)
        return x

    def _cycle(self, level, b):
        if level == self.num_levels - 1:
            return self.coarsest_inverse @ b
        A, inverse_diagonal, damping = self.operators[level - 1], self.inverse_diagonals[level - 1], self.dampings[level]
        x = damping * inverse_diagonal * b
        for _ in range(SMOOTHING_STEPS - 1):
            x = x + damping * inverse_diagonal * (b - A @ x)
        correction = self._cycle(level + 1, self.prolongations[level].rmatmul(b - A @ x))
        x = x + self.prolongations[level] @ correction
        for _ in range(SMOOTHING_STEPS):
            x = x + damping * inverse_diagonal * (b - A @ x)
        return x


def _rigid_body_modes(points) -> np.ndarray:
    """(3 n, 6) the translations and rotations about the origin at `points` (n, 3)."""
    modes = np.zeros((3 * len(points), 6))
    for k in range(3):
        modes[k::3, k] = 1.0
    x, y, z = points.T
    modes[0::3, 3], modes[1::3, 3] = -y, x
    modes[1::3, 4], modes[2::3, 4] = -z, y
    modes[0::3, 5], modes[2::3, 5] = z, -x
    return modes


def make_multigrid_preconditioner(problem: ElasticProblem, poisson_ratio=None) -> MultigridPreconditioner:
    """The smoothed-aggregation hierarchy of `problem`'s stiffness (host; pyamg).
    Lengths are scaled to the mesh's size for the rigid-body modes."""
    import pyamg
    import scipy.sparse as sp
    from pyamg.util.linalg import approximate_spectral_radius

    nu = problem.poisson_ratio if poisson_ratio is None else poisson_ratio
    vertices = jnp.asarray(problem.vertices)
    values = calc_stiffness_blocks(problem, vertices, jnp.asarray(nu, vertices.dtype))
    rows, cols, entries = problem.pattern.to_coo(values)
    size = 3 * problem.num_nodes
    stiffness = sp.csr_matrix((entries, (rows, cols)), shape=(size, size))
    free_nodes = ~np.asarray(problem.is_fixed)
    free = np.flatnonzero(np.repeat(free_nodes, 3))
    reduced = stiffness[free][:, free].tocsr()
    points = np.asarray(problem.calc_node_positions())[free_nodes]
    points = (points - points.mean(axis=0)) / max(float(np.ptp(points)), 1e-300)
    modes = _rigid_body_modes(points)
    hierarchy = pyamg.smoothed_aggregation_solver(reduced, B=modes, symmetry="symmetric", max_coarse=DENSE_COARSEST, keep=False)
    levels = hierarchy.levels
    # The finest level's smoother: block Jacobi on the matrix-free operator.
    blocks = np.asarray(calc_diagonal_blocks(problem, vertices, jnp.asarray(nu, vertices.dtype)))
    inverse_blocks = np.linalg.inv(np.where(free_nodes[:, None, None], blocks, np.eye(3)[None]))[free_nodes]
    count = len(inverse_blocks)
    block_jacobi = sp.bsr_matrix((inverse_blocks, np.arange(count), np.arange(count + 1)), shape=(3 * count, 3 * count)).tocsr()
    dampings = [4.0 / (3.0 * approximate_spectral_radius(block_jacobi @ reduced))]
    operators, inverse_diagonals = [], []
    for level in levels[1:-1]:
        diagonal = level.A.diagonal()
        scaled = sp.diags(1.0 / diagonal) @ level.A
        dampings.append(4.0 / (3.0 * approximate_spectral_radius(scaled)))
        operators.append(_sparse(level.A))
        inverse_diagonals.append(1.0 / diagonal)
    coarsest = levels[-1].A.toarray()
    return MultigridPreconditioner(
        free_dofs=free.astype(np.int32),
        prolongations=tuple(_sparse(level.P) for level in levels[:-1]),
        operators=tuple(operators),
        inverse_diagonals=tuple(inverse_diagonals),
        dampings=np.asarray(dampings),
        coarsest_inverse=np.linalg.inv(coarsest),
    )
