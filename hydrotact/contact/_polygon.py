"""Convex polygons in fixed-capacity buffers: clipping by half-spaces, and the exact
integrals of a linear pressure over them.

A polygon is (vertices (capacity, 3), count): the first `count` rows, in order; the
rest is padding. Clipping keeps the winding. Everything is written for one polygon
and vmapped, and stays finite (with finite gradients) for empty, degenerate and
grazing polygons.
"""

import jax
import jax.numpy as jnp

from .._math import safe_div


def clip_polygon(vertices, count, normal, offset):
    """Clip a polygon by the half-space normal . x <= offset (Sutherland-Hodgman).

    Each vertex i emits itself if inside, then the crossing point of edge (i, i+1)
    if that edge crosses the plane. Output capacity equals input capacity; the caller
    sizes the buffer so that it cannot overflow (one clip adds at most one vertex, and
    callers start from at most capacity - 4 vertices before four clips).

    **Returns:** (vertices (capacity, 3), count).
    """
    capacity = vertices.shape[0]
    index = jnp.arange(capacity)
    active = index < count
    next_index = jnp.where(index + 1 < count, index + 1, 0)
    following = vertices[next_index]
    distance = vertices @ normal - offset
    next_distance = distance[next_index]
    inside = distance <= 0.0
    next_inside = next_distance <= 0.0
    crosses = active & (inside != next_inside)
    t = safe_div(distance, distance - next_distance)
    crossing = vertices + t[:, None] * (following - vertices)
    keep = active & inside
    # Vertex i emits its own point (if kept), then its crossing (if any). Output slot
    # s is filled by the vertex whose emitted range covers s: a gather, not a scatter.
    emitted = keep.astype(jnp.int32) + crosses.astype(jnp.int32)
    ends = jnp.cumsum(emitted)
    new_count = jnp.minimum(ends[-1], capacity)
    source = jnp.minimum(jnp.searchsorted(ends, index, side="right", method="compare_all"), capacity - 1)
    first_of_source = (ends[source] - emitted[source]) == index
    own = keep[source] & first_of_source
    out = jnp.where(own[:, None], vertices[source], crossing[source])
    out = jnp.where((index < new_count)[:, None], out, 0.0)
    return out, new_count


def clip_polygon_by_tet_faces(vertices, count, tet_vertices):
    """Clip a polygon by the four half-spaces of a positively oriented tet."""
    faces = jnp.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    for face in faces:
        a, b, c = tet_vertices[face[0]], tet_vertices[face[1]], tet_vertices[face[2]]
        outward = jnp.cross(b - a, c - a)
        vertices, count = clip_polygon(vertices, count, outward, jnp.dot(outward, a))
    return vertices, count


def calc_polygon_integrals(vertices, count, pressures, normal):
    """Exact integrals over a planar convex polygon of a pressure linear on it.

    The polygon is fan-triangulated from vertex 0; each fan triangle's area is
    ((v_i - v_0) x (v_(i+1) - v_0)) . normal / 2 (positive for counter-clockwise
    winding about `normal`, smooth even at zero area). With P1 mass-matrix weights,
    int p dA = A (p_0 + p_i + p_(i+1)) / 3 and
    int p x dA = A / 12 (sum_j p_j x_j + (sum_j p_j)(sum_j x_j)).

    **Returns:** (area, int p dA, int x dA (3,), int p x dA (3,)).
    """
    capacity = vertices.shape[0]
    i = jnp.arange(1, capacity - 1)
    used = (i + 1 < count)
    v0 = vertices[:1]  # (1, 3): broadcasts against the fan's (k, 3) explicitly
    vi, vj = vertices[i], vertices[i + 1]
    p0, pi, pj = pressures[0], pressures[i], pressures[i + 1]
    areas = 0.5 * jnp.einsum("kd,d->k", jnp.cross(vi - v0, vj - v0), normal)
    areas = jnp.where(used, areas, 0.0)
    sum_p = p0 + pi + pj
    sum_x = v0 + vi + vj
    area = jnp.sum(areas)
    force = jnp.sum(areas * sum_p) / 3.0
    first_moment = jnp.sum(areas[:, None] * sum_x, axis=0) / 3.0
    weighted = p0 * v0 + pi[:, None] * vi + pj[:, None] * vj + sum_p[:, None] * sum_x
    pressure_moment = jnp.sum(areas[:, None] * weighted, axis=0) / 12.0
    return area, force, first_moment, pressure_moment


batched_clip_by_tet = jax.vmap(clip_polygon_by_tet_faces)
