"""Consistent nodal loads of the P2 elasticity problem: point forces, surface tractions
and body forces, each integrated against the shape functions of the tet it acts in.

A force f at a point x inside tet t contributes N_a(x) f to each of the tet's ten
nodes a (N the P2 shape functions at x's barycentric coordinates): this is the
virtual work of the force on a P2 displacement, so a load integrated by a quadrature
rule exact for its integrand gives the exact consistent loads. Tractions use the
six-point rule on triangles (exact to degree 4: a linear traction against quadratic
shape functions is cubic); body forces the tet's four-point rule (degree 2).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._types import Array, Float, Int
from ..field import calc_tet_gradients
from ._problem import TET_QUADRATURE, ElasticProblem
from ._quadratic import calc_shape_functions

# Dunavant's six-point rule on a triangle (degree 4): barycentric points, weights
# summing to 1 (multiply by the area).
_A4, _B4 = 0.445948490915965, 0.091576213509771
_W4A, _W4B = 0.223381589678011, 0.109951743655322
TRIANGLE_QUADRATURE = np.array(
    [
        [_A4, _A4, 1 - 2 * _A4],
        [_A4, 1 - 2 * _A4, _A4],
        [1 - 2 * _A4, _A4, _A4],
        [_B4, _B4, 1 - 2 * _B4],
        [_B4, 1 - 2 * _B4, _B4],
        [1 - 2 * _B4, _B4, _B4],
    ]
)
TRIANGLE_WEIGHTS = np.array([_W4A] * 3 + [_W4B] * 3)


def calc_barycentric(vertices, tets, tet_index, points_S):
    """Barycentric coordinates (M, 4) of points (M, 3) in the tets `tet_index` (M,)."""
    lambda_gradients, _ = calc_tet_gradients(vertices, tets[tet_index])
    origin = vertices[tets[tet_index, 0]]
    lam = jnp.einsum("mid,md->mi", lambda_gradients, points_S - origin)
    first = jnp.zeros_like(lam).at[:, 0].set(1.0)
    return first + lam


def calc_point_loads(problem: ElasticProblem, tet_index, points_S, forces_S, vertices=None):
    """Consistent nodal loads (num_nodes, 3) of point forces `forces_S` (M, 3) N at
    `points_S` (M, 3) inside the tets `tet_index` (M,) (pure; differentiable in the
    points, forces and vertices)."""
    vertices = jnp.asarray(problem.vertices if vertices is None else vertices)
    shape = calc_shape_functions(calc_barycentric(vertices, problem.tets, tet_index, points_S))  # (M, 10)
    contributions = shape[:, :, None] * forces_S[:, None, :]
    return jax.ops.segment_sum(contributions.reshape(-1, 3), problem.tet_nodes[tet_index].reshape(-1), num_segments=problem.num_nodes)


class FaceQuadrature(eqx.Module):
    """Quadrature points on boundary faces (host-built), for surface tractions.

    **Fields:** `points_S` (Q, 3) m; `weights` (Q,) m^2 (they sum to the faces' area);
    `normals_S` (Q, 3) outward unit normals; `tet_index` (Q,) the tet each face bounds.
    """

    points_S: Float[Array, "num_points 3"]
    weights: Float[Array, " num_points"]
    normals_S: Float[Array, "num_points 3"]
    tet_index: Int[Array, " num_points"]


def find_face_tets(tets, faces) -> np.ndarray:
    """For each boundary face (F, 3), the one tet it bounds (host); one error when a
    face bounds no tet."""
    tets = np.asarray(tets, dtype=np.int64)
    faces = np.asarray(faces, dtype=np.int64)
    opposite = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    tet_faces = np.sort(tets[:, opposite], axis=-1).reshape(-1, 3)
    scale = int(tets.max()) + 1
    keys = (tet_faces[:, 0] * scale + tet_faces[:, 1]) * scale + tet_faces[:, 2]
    order = np.argsort(keys)
    sorted_faces = np.sort(faces, axis=-1)
    wanted = (sorted_faces[:, 0] * scale + sorted_faces[:, 1]) * scale + sorted_faces[:, 2]
    at = np.clip(np.searchsorted(keys[order], wanted), 0, len(keys) - 1)
    found = keys[order][at] == wanted
    if not found.all():
        raise HydrotactError(f"face {int(np.argmin(found))} bounds no tet of the mesh")
    return order[at] // 4


def make_face_quadrature(problem: ElasticProblem, faces) -> FaceQuadrature:
    """The six-point quadrature on each of `faces` (F, 3) (vertex indices, wound
    outward as a TetMesh's boundary faces are) (host)."""
    faces = np.asarray(faces, dtype=np.int64)
    vertices = np.asarray(problem.vertices)
    corners = vertices[faces]  # (F, 3, 3)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    areas = 0.5 * np.linalg.norm(cross, axis=1)
    normals = cross / (2.0 * areas[:, None])
    points = np.einsum("qk,fkd->fqd", TRIANGLE_QUADRATURE, corners).reshape(-1, 3)
    weights = (areas[:, None] * TRIANGLE_WEIGHTS[None]).reshape(-1)
    count = len(TRIANGLE_WEIGHTS)
    return FaceQuadrature(
        points_S=points,
        weights=weights,
        normals_S=np.repeat(normals, count, axis=0),
        tet_index=np.repeat(find_face_tets(problem.tets, faces), count),
    )


def calc_face_loads(problem: ElasticProblem, quadrature: FaceQuadrature, tractions_S):
    """Consistent nodal loads of tractions `tractions_S` (Q, 3) Pa at the quadrature's
    points (pure)."""
    return calc_point_loads(problem, quadrature.tet_index, quadrature.points_S, quadrature.weights[:, None] * tractions_S)


def calc_body_loads(problem: ElasticProblem, force_density_S, vertices=None):
    """Consistent nodal loads of a uniform body force density (3,) N/m^3 (gravity:
    rho g) (pure; the four-point rule is exact for it)."""
    vertices = jnp.asarray(problem.vertices if vertices is None else vertices)
    _, volumes = calc_tet_gradients(vertices, problem.tets)
    shape = calc_shape_functions(jnp.asarray(TET_QUADRATURE, vertices.dtype))  # (4, 10)
    per_node = 0.25 * jnp.sum(shape, axis=0)  # int N_a dV / V
    force = jnp.asarray(force_density_S, vertices.dtype)
    contributions = volumes[:, None, None] * per_node[None, :, None] * force[None, None, :]
    return jax.ops.segment_sum(contributions.reshape(-1, 3), problem.tet_nodes.reshape(-1), num_segments=problem.num_nodes)
