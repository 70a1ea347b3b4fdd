"""Quadratic (P2) tetrahedra: the ten nodes of each tet, their shape functions, and the
block sparsity pattern of a vector P2 stiffness matrix (host-built).

A P2 tet has its four vertices and the midpoints of its six edges as nodes, in the
order of scikit-fem's `ElementTetP2`: vertices 0-3, then the edges (0, 1), (1, 2),
(0, 2), (0, 3), (1, 3), (2, 3). With the barycentric coordinates lambda_i, the shape
functions are N_i = lambda_i (2 lambda_i - 1) at vertex i and N_ij = 4 lambda_i
lambda_j at the midpoint of edge ij; their gradients are linear in lambda because the
grad(lambda_i) are constant over a straight-sided tet.

The stiffness matrix couples every pair of nodes of a tet in all three displacement
components, so it is stored as 3 x 3 blocks, node row by node row, in ELLPACK form:
each node's row holds `max_row_entries` block slots (its neighbours, sorted, then
padding that points at the node itself with value 0). A product K u is one gather and
one small contraction per row.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._types import Array, Bool, Int
from ..field import make_stiffness_pattern

# The edges of a tet, in scikit-fem's ElementTetP2 order of its midside nodes.
TET_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
NODES_PER_TET = 10


def make_quadratic_nodes(vertices, tets) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The P2 nodes of a tet mesh (host).

    **Returns:** (edges (num_edges, 2) vertex pairs, sorted; tet_nodes (num_tets, 10)
    the node indices of each tet, vertices first (node i < num_vertices is vertex i),
    then its six edges' midside nodes num_vertices + edge index; the node positions
    (num_vertices + num_edges, 3)).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    pairs = np.sort(tets[:, TET_EDGES], axis=-1).reshape(-1, 2)  # (num_tets * 6, 2)
    edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
    edge_of_tet = inverse.reshape(-1, 6)
    tet_nodes = np.concatenate([tets, len(vertices) + edge_of_tet], axis=1)
    nodes = np.concatenate([vertices, 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])], axis=0)
    return edges, tet_nodes, nodes


def calc_node_positions(vertices, edges):
    """The P2 node positions from the vertex positions (differentiable in them)."""
    return jnp.concatenate([vertices, 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])], axis=0)


def calc_shape_functions(barycentric):
    """The ten P2 shape functions at points given by their barycentric coordinates.

    **Arguments:** `barycentric` (..., 4). **Returns:** (..., 10).
    """
    lam = barycentric
    corner = lam * (2.0 * lam - 1.0)
    edge = 4.0 * lam[..., TET_EDGES[:, 0]] * lam[..., TET_EDGES[:, 1]]
    return jnp.concatenate([corner, edge], axis=-1)


def calc_shape_gradients(barycentric, lambda_gradients):
    """Gradients of the ten P2 shape functions.

    **Arguments:** `barycentric` (..., 4) at the points; `lambda_gradients` (..., 4, 3)
    the constant gradients of the barycentric coordinates of the points' tets.
    **Returns:** (..., 10, 3) in 1/m.
    """
    lam = barycentric[..., :, None]
    corner = (4.0 * lam - 1.0) * lambda_gradients
    i, j = TET_EDGES[:, 0], TET_EDGES[:, 1]
    edge = 4.0 * (lam[..., j, :] * lambda_gradients[..., i, :] + lam[..., i, :] * lambda_gradients[..., j, :])
    return jnp.concatenate([corner, edge], axis=-2)


class BlockPattern(eqx.Module):
    """Where the 3 x 3 blocks of an assembled vector P2 matrix live (host-built).

    **Fields:**

    - `cols`: (num_nodes, max_row_entries) the node of each block slot.
    - `is_entry`: (num_nodes, max_row_entries) False on padding slots.
    - `scatter`: (num_tets * 100,) for each (row node, column node) pair of each tet,
      in the order of `tet_nodes[:, a], tet_nodes[:, b]`, its flat slot.
    - `diagonal`: (num_nodes,) the flat slot of each node's own block.
    """

    cols: Int[Array, "num_nodes max_row_entries"]
    is_entry: Bool[Array, "num_nodes max_row_entries"]
    scatter: Int[Array, " num_element_blocks"]
    diagonal: Int[Array, " num_nodes"]

    @property
    def num_nodes(self) -> int:
        return self.cols.shape[0]

    @property
    def num_slots(self) -> int:
        return self.cols.shape[0] * self.cols.shape[1]

    def to_coo(self, values) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, values) of the scalar entries (degree of freedom 3 node + k),
        for scipy and other checks (host)."""
        is_entry = np.asarray(self.is_entry)
        blocks = np.asarray(values).reshape(*is_entry.shape, 3, 3)[is_entry]  # (m, 3, 3)
        node_rows = np.broadcast_to(np.arange(self.num_nodes)[:, None], is_entry.shape)[is_entry]
        node_cols = np.asarray(self.cols)[is_entry]
        k = np.arange(3)
        rows = (3 * node_rows[:, None, None] + k[None, :, None]) + 0 * k[None, None, :]
        cols = (3 * node_cols[:, None, None] + k[None, None, :]) + 0 * k[None, :, None]
        return rows.reshape(-1), cols.reshape(-1), blocks.reshape(-1)


def make_block_pattern(tet_nodes, num_nodes: int) -> BlockPattern:
    """Build the block sparsity pattern of a vector P2 matrix on `tet_nodes` (host):
    the scalar pattern of the node couplings (:func:`hydrotact.field.make_stiffness_pattern`),
    each slot holding a 3 x 3 block."""
    scalar = make_stiffness_pattern(tet_nodes, num_nodes)
    return BlockPattern(cols=scalar.cols, is_entry=scalar.is_entry, scatter=scalar.scatter, diagonal=scalar.diagonal)


def apply_blocks(pattern: BlockPattern, values, u):
    """K u for the block matrix given by `pattern` and `values` (num_slots, 3, 3);
    `u` (num_nodes, 3)."""
    blocks = values.reshape(*pattern.cols.shape, 3, 3)
    gathered = u.at[pattern.cols].get(mode="promise_in_bounds")  # (num_nodes, width, 3)
    return jnp.einsum("nwij,nwj->ni", blocks, gathered)
