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

from .._types import Array, Float, Int


class StiffnessPattern(eqx.Module):
    """Where the entries of the assembled P1 stiffness matrix live (host-built).

    **Fields:**

    - `rows`, `cols`: (num_entries,) the coordinates of each stored entry, sorted.
    - `scatter`: (num_tets * 16,) for each element-matrix entry, its slot in `rows`.
    - `diagonal`: (num_vertices,) the slot of each diagonal entry.
    """

    rows: Int[Array, " num_entries"]
    cols: Int[Array, " num_entries"]
    scatter: Int[Array, " num_element_entries"]
    diagonal: Int[Array, " num_vertices"]
    num_vertices: int = eqx.field(static=True)

    @property
    def num_entries(self) -> int:
        return self.rows.shape[0]


def make_stiffness_pattern(tets, num_vertices: int) -> StiffnessPattern:
    """Build the sparsity pattern of the P1 stiffness matrix of `tets` (host)."""
    tets = np.asarray(tets, dtype=np.int64)
    rows = np.repeat(tets, 4, axis=1).reshape(-1)
    cols = np.tile(tets, (1, 4)).reshape(-1)
    keys = rows * num_vertices + cols
    unique_keys, scatter = np.unique(keys, return_inverse=True)
    unique_rows, unique_cols = unique_keys // num_vertices, unique_keys % num_vertices
    diagonal = np.searchsorted(unique_keys, np.arange(num_vertices) * (num_vertices + 1))
    index_dtype = np.int32 if len(unique_keys) < 2**31 - 1 else np.int64
    return StiffnessPattern(
        rows=unique_rows.astype(index_dtype),
        cols=unique_cols.astype(index_dtype),
        scatter=scatter.reshape(-1).astype(index_dtype),
        diagonal=diagonal.astype(index_dtype),
        num_vertices=int(num_vertices),
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


def calc_stiffness_values(pattern: StiffnessPattern, vertices, tets) -> Float[Array, " num_entries"]:
    """The stored entries of K (ordered as `pattern.rows`, `pattern.cols`)."""
    gradients, volumes = calc_tet_gradients(vertices, tets)
    element = volumes[:, None, None] * jnp.einsum("tid,tjd->tij", gradients, gradients)
    return jax.ops.segment_sum(
        element.reshape(-1), pattern.scatter, num_segments=pattern.num_entries, indices_are_sorted=False
    )


def apply_stiffness(pattern: StiffnessPattern, values, x):
    """K x for the assembled matrix given by `pattern` and `values`."""
    return jax.ops.segment_sum(values * x[pattern.cols], pattern.rows, num_segments=pattern.num_vertices, indices_are_sorted=True)
