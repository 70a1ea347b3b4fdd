"""P1 finite elements for Laplace's equation with a fixed sparsity pattern.

The pattern (which vertex pairs couple, and where each tet's 4 x 4 element matrix
lands in the value array) is built once on the host. The values are computed on the
device from the vertex positions, so the stiffness matrix is differentiable in them:

    K_ij = sum over tets t of V_t grad(phi_i) . grad(phi_j),

with phi the linear hat functions. For a tet with edges e_k = x_k - x_0 and
det = e_1 . (e_2 x e_3) (= 6 V > 0), the barycentric gradients are
grad(lambda_1) = (e_2 x e_3) / det, grad(lambda_2) = (e_3 x e_1) / det,
grad(lambda_3) = (e_1 x e_2) / det and grad(lambda_0) = -(their sum).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Bool, Float, Int


class StiffnessPattern(eqx.Module):
    """Where the entries of the assembled P1 stiffness matrix live (host-built).

    The matrix is stored row by row in ELLPACK form: each vertex's row holds
    `max_row_entries` slots, the couplings to its neighbours (sorted) then padding that
    points at the vertex itself with value 0. A product K x is then one gather and one
    row sum, which vectorises on CPUs and GPUs alike (no scatter in the CG loop).

    **Fields:**

    - `cols`: (num_vertices, max_row_entries) column of each slot.
    - `is_entry`: (num_vertices, max_row_entries) False on padding slots.
    - `scatter`: (num_tets * 16,) for each element-matrix entry, its flat slot (row
      node a, column node b, in the order of `tets[:, a], tets[:, b]`).
    - `diagonal`: (num_vertices,) the flat slot of each diagonal entry.
    """

    cols: Int[Array, "num_vertices max_row_entries"]
    is_entry: Bool[Array, "num_vertices max_row_entries"]
    scatter: Int[Array, " num_element_entries"]
    diagonal: Int[Array, " num_vertices"]

    @property
    def num_vertices(self) -> int:
        return self.cols.shape[0]

    @property
    def num_slots(self) -> int:
        return self.cols.shape[0] * self.cols.shape[1]

    def to_coo(self, values) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, values) of the stored entries, for scipy and other checks (host)."""
        is_entry = np.asarray(self.is_entry)
        rows = np.broadcast_to(np.arange(self.num_vertices)[:, None], is_entry.shape)
        return rows[is_entry], np.asarray(self.cols)[is_entry], np.asarray(values).reshape(is_entry.shape)[is_entry]


def make_stiffness_pattern(tets, num_vertices: int) -> StiffnessPattern:
    """Build the sparsity pattern of the P1 stiffness matrix of `tets` (host). Any
    element width works: (num_elements, k) node indices couple every pair of their
    nodes (the P2 elasticity's 10-node tets use it for their 3 x 3 blocks)."""
    tets = np.asarray(tets, dtype=np.int64)
    width = tets.shape[1]
    rows = np.repeat(tets, width, axis=1).reshape(-1)
    cols = np.tile(tets, (1, width)).reshape(-1)
    unique_keys, inverse = np.unique(rows * num_vertices + cols, return_inverse=True)
    unique_rows, unique_cols = unique_keys // num_vertices, unique_keys % num_vertices
    row_starts = np.searchsorted(unique_rows, np.arange(num_vertices))
    position = np.arange(len(unique_keys)) - row_starts[unique_rows]  # slot within its row
    width = int(position.max()) + 1
    ell_cols = np.broadcast_to(np.arange(num_vertices)[:, None], (num_vertices, width)).copy()
    ell_cols[unique_rows, position] = unique_cols
    is_entry = np.zeros((num_vertices, width), dtype=bool)
    is_entry[unique_rows, position] = True
    flat_slot = unique_rows * width + position
    diagonal_key = np.searchsorted(unique_keys, np.arange(num_vertices) * (num_vertices + 1))
    index_dtype = np.int32 if num_vertices * width < 2**31 - 1 else np.int64
    return StiffnessPattern(
        cols=ell_cols.astype(index_dtype),
        is_entry=is_entry,
        scatter=flat_slot[inverse.reshape(-1)].astype(index_dtype),
        diagonal=flat_slot[diagonal_key].astype(index_dtype),
    )


def calc_tet_gradients(vertices, tets):
    """Gradients of the four barycentric coordinates of every tet, and its volume.

    **Returns:** (gradients (num_tets, 4, 3) in 1/m, volumes (num_tets,) in m^3; the
    volume is signed, positive for a positively oriented tet).
    """
    p = vertices[tets]
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    c23, c31, c12 = jnp.cross(e2, e3), jnp.cross(e3, e1), jnp.cross(e1, e2)
    det = jnp.sum(e1 * c23, axis=-1)
    g123 = jnp.stack([c23, c31, c12], axis=1) / det[:, None, None]
    g0 = -jnp.sum(g123, axis=1, keepdims=True)
    return jnp.concatenate([g0, g123], axis=1), det / 6.0


def calc_stiffness_values(pattern: StiffnessPattern, vertices, tets) -> Float[Array, " num_slots"]:
    """The entries of K in the pattern's flat ELLPACK slots (0 on padding)."""
    gradients, volumes = calc_tet_gradients(vertices, tets)
    element = volumes[:, None, None] * jnp.einsum("tid,tjd->tij", gradients, gradients)
    return jax.ops.segment_sum(
        element.reshape(-1), pattern.scatter, num_segments=pattern.num_slots, indices_are_sorted=False
    )


def apply_stiffness(pattern: StiffnessPattern, values, x):
    """K x for the assembled matrix given by `pattern` and `values`."""
    return jnp.sum(values.reshape(pattern.cols.shape) * x.at[pattern.cols].get(mode="promise_in_bounds"), axis=1)
