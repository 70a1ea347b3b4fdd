"""The Drake-compatible strain field: normalised distance to the boundary surface.

Drake's hydroelastic contact gives a compliant tetrahedral `Mesh` the pressure field
p_v = E d_v / max_u d_u, with d_v the distance from vertex v to the mesh's boundary
surface (all boundary faces, whatever their tag), linear inside each tet. The same
field here lets hydrotact be compared with Drake on identical meshes and fields.
"""

import jax
import jax.numpy as jnp

from .._errors import HydrotactError, where
from .._geometry import calc_distance_to_triangles
from ..mesh import TetMesh


def calc_distance_field(mesh: TetMesh, *, vertices=None, source: str | None = None):
    """e_v = d_v / max d (dimensionless, 0 on the boundary, 1 at the deepest vertex).

    Differentiable with respect to `vertices` (default `mesh.vertices`) almost
    everywhere. Raises if no vertex lies inside (all distances zero), as Drake does.
    """
    if vertices is None:
        vertices = mesh.vertices
    vertices = jnp.asarray(vertices)
    triangles = vertices[jnp.asarray(mesh.boundary_faces)]
    distance, _ = calc_distance_to_triangles(vertices, triangles)
    # Boundary vertices are at distance 0 exactly (not a rounding error above it).
    on_boundary = jnp.zeros(vertices.shape[0], dtype=bool).at[jnp.asarray(mesh.boundary_faces).reshape(-1)].set(True)
    distance = jnp.where(on_boundary, 0.0, distance)
    max_distance = jnp.max(distance)
    if not isinstance(max_distance, jax.core.Tracer) and float(max_distance) <= 0.0:
        raise HydrotactError(
            f"{where(source)}the mesh has no interior vertex (every vertex is on the boundary): "
            "the distance field is undefined"
        )
    return distance / max_distance
