"""Small geometric kernels shared by the stages (pure JAX, vmappable, differentiable)."""

import jax
import jax.numpy as jnp

from ._math import safe_norm


def _point_segment_distance(p, a, b):
    ab = b - a
    t = jnp.clip(jnp.dot(p - a, ab) / jnp.maximum(jnp.dot(ab, ab), 1e-300), 0.0, 1.0)
    return safe_norm(p - (a + t * ab))


def calc_point_triangle_distance(p, a, b, c):
    """Unsigned distance from point `p` to the closed triangle (a, b, c).

    If the orthogonal projection of `p` onto the triangle's plane falls inside the
    triangle, the distance is the distance to the plane; otherwise the closest point
    lies on one of the three edges. Degenerate (zero-area) triangles fall back to the
    edge distances. All arguments have shape (3,); returns a scalar.
    """
    n = jnp.cross(b - a, c - a)
    area2 = jnp.dot(n, n)
    nondegenerate = area2 > 0.0
    safe_area2 = jnp.where(nondegenerate, area2, 1.0)
    # Barycentric coordinates of the projection (signed sub-areas over the total).
    w_a = jnp.dot(jnp.cross(b - p, c - p), n) / safe_area2
    w_b = jnp.dot(jnp.cross(c - p, a - p), n) / safe_area2
    w_c = 1.0 - w_a - w_b
    inside = nondegenerate & (w_a >= 0.0) & (w_b >= 0.0) & (w_c >= 0.0)
    plane_distance = jnp.abs(jnp.dot(p - a, n)) / jnp.sqrt(safe_area2)
    edge_distance = jnp.minimum(
        jnp.minimum(_point_segment_distance(p, a, b), _point_segment_distance(p, b, c)),
        _point_segment_distance(p, c, a),
    )
    return jnp.where(inside, plane_distance, edge_distance)


@jax.jit
def _min_distance_chunk(points, triangles):
    per_pair = jax.vmap(
        lambda p: jax.vmap(lambda t: calc_point_triangle_distance(p, t[0], t[1], t[2]))(triangles)
    )(points)
    return jnp.min(per_pair, axis=1), jnp.argmin(per_pair, axis=1)


def calc_distance_to_triangles(points, triangles, chunk_size: int = 512):
    """Distance from each point to the nearest of `triangles`, and that triangle's index.

    Exact (every pair is tested), in chunks of `chunk_size` points so memory stays at
    chunk_size x num_triangles. `points` (N, 3), `triangles` (M, 3, 3); returns
    (distances (N,), nearest triangle indices (N,)).
    """
    points = jnp.asarray(points)
    triangles = jnp.asarray(triangles)
    num_points = points.shape[0]
    pad = (-num_points) % chunk_size
    padded = jnp.concatenate([points, jnp.broadcast_to(points[:1], (pad, 3))]) if pad else points
    chunks = padded.reshape(-1, chunk_size, 3)
    distances, nearest = jax.lax.map(lambda chunk: _min_distance_chunk(chunk, triangles), chunks)
    return distances.reshape(-1)[:num_points], nearest.reshape(-1)[:num_points]
