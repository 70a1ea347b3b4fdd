"""Convex polygons in fixed-capacity buffers: clipping by half-spaces, and the exact
integrals of a linear pressure over them.

A polygon is (vertices (capacity, 3), count): the first `count` rows, in order; the
rest is padding. Clipping keeps the winding. Everything is written for one polygon
and vmapped, and stays finite (with finite gradients) for empty, degenerate and
grazing polygons.
"""

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
    used = i + 1 < count
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


# Column layout: many polygons at once, the polygon index last, so that every step is
# an elementwise operation over long contiguous rows (what XLA's CPU backend
# vectorises well). vertices (3, n, P), pressures (n, P), counts (P,). The results
# are the same as the one-polygon functions above, vertex for vertex (but for a polygon
# lying in a clipping plane: see _clip_stage_columns).


def _pick_columns(values, index):
    """values (n, ..., P) at a per-polygon row index (P,): a one-hot sum over the n rows."""
    n = values.shape[0]
    onehot = (jnp.arange(n)[:, None] == index[None]).reshape(n, *(1,) * (values.ndim - 2), -1)
    return jnp.sum(jnp.where(onehot, values, 0.0), axis=0)


def _clip_stage_columns(vertices, count, normal, offset):
    """One Sutherland-Hodgman stage of :func:`clip_polygon_by_tet_faces_columns`:
    P polygons as arrays, vertices (n, 3, P), count (P,), each clipped by its own
    half-space normal . x <= offset (normal (3, P), offset (P,)); -> vertices
    (n + 1, 3, P), count (P,).

    A plane cuts a convex polygon in one run of outside vertices: the run around the
    farthest vertex, from e + 1 to b - 1 cyclically (e the last inside vertex before
    it, b the first after). Sutherland-Hodgman's output, in the order it emits it, is
    then either v_0..v_e, the exit crossing (of edge e, e + 1), the entry crossing (of
    edge b - 1, b), v_b..v_last (the run does not pass vertex 0, or ends at the last
    vertex), or the entry crossing, v_b..v_e, the exit crossing (it passes vertex 0).
    Each output slot takes its vertex unshifted, one of the two crossings, or the
    vertex a per-polygon shift further on, shifted in log2(n) steps: a few selects
    per slot, where emitting every candidate at a running count and picking each
    slot's by a one-hot sum over 2n candidates cost (n + 1) 2n (3.6x slower alone;
    in the soft-rigid kernel, 1.0-1.16x: benchmarks/RESULTS.md, issue 48). The output is that of :func:`clip_polygon` vertex for vertex whenever the
    inside vertices are one run; where round-off splits them (vertices within
    round-off of the plane, on either side), the other runs count as inside: they
    differ from the plane by round-off. A polygon lying in the plane (every distance
    round-off) is the one case where this matters, and the soft-rigid kernel's tie
    rule moves such a face's plane out of the way first (`_resolve_face_ties`).
    """
    n = vertices.shape[0]
    # Keep the reduction over the 3-long axis: it is a fusion barrier (written as
    # v[0] * n[0] + v[1] * n[1] + v[2] * n[2], XLA's CPU fusion recomputed each stage's
    # vertices inside the next, and four chained stages ran 100x slower; issue 12).
    distance = jnp.sum(vertices * normal[None], axis=1) - offset[None]  # (n, P)
    index = jnp.arange(n)[:, None]
    is_last = index == (count - 1)[None]
    following = jnp.where(is_last[:, None], vertices[:1], jnp.roll(vertices, -1, axis=0))
    next_distance = jnp.where(is_last, distance[:1], jnp.roll(distance, -1, axis=0))
    active = index < count[None]
    inside = active & (distance <= 0.0)
    t = safe_div(distance, distance - next_distance)
    crossing = vertices + t[:, None] * (following - vertices)  # of edge (i, i + 1)
    # The outside run around the farthest vertex: e before it, b after it (cyclically).
    farthest = jnp.argmax(jnp.where(active, distance, -jnp.inf), axis=0)
    last_before = jnp.max(jnp.where(inside & (index < farthest[None]), index, -1), axis=0)
    first_after = jnp.min(jnp.where(inside & (index > farthest[None]), index, n), axis=0)
    e = jnp.where(last_before >= 0, last_before, jnp.max(jnp.where(inside, index, -1), axis=0))
    b = jnp.where(first_after < n, first_after, jnp.min(jnp.where(inside, index, n), axis=0))
    exit_point = _pick_columns(crossing, e)
    entry_point = _pick_columns(crossing, jnp.where(b == 0, count - 1, b - 1))
    prefix = (e < b) | (b == 0)  # v_0..v_e, exit, entry, v_b..; else entry, v_b..v_e, exit
    new_count = jnp.where(prefix, e + 3 + jnp.where(b == 0, 0, count - b), e - b + 3)
    # Slot s of the shifted run takes v_(s + shift): rows w_s = v_(s - 1), taken at s + shift + 1.
    shift = jnp.where(prefix, b - e - 2, b)
    shifted = jnp.concatenate([vertices[:1], vertices])
    for bit in range(n.bit_length()):
        shifted = jnp.where((((shift >> bit) & 1) == 1)[None, None], jnp.roll(shifted, -(1 << bit), axis=0), shifted)
    slots = jnp.arange(n + 1)[:, None]
    unshifted = jnp.concatenate([vertices, vertices[:1]])
    out = jnp.where((prefix[None] & (slots <= e[None]))[:, None], unshifted, shifted)
    out = jnp.where((slots == jnp.where(prefix, e + 1, new_count - 1)[None])[:, None], exit_point[None], out)
    out = jnp.where((slots == jnp.where(prefix, e + 2, 0)[None])[:, None], entry_point[None], out)
    # No vertex outside: the polygon as it was; none inside: nothing.
    cut = jnp.any(active & ~inside, axis=0)
    out = jnp.where(cut[None, None], out, unshifted)
    new_count = jnp.where(cut, jnp.where(jnp.any(inside, axis=0), new_count, 0), count)
    return jnp.where((slots < new_count[None])[:, None], out, 0.0), new_count


def clip_polygon_by_tet_faces_columns(vertices, count, face_normals, face_offsets):
    """Clip P polygons by the four faces of their tets: `face_normals` (4, 3, P) and
    `face_offsets` (4, P), each face's outward normal and offset, as
    :func:`calc_tet_face_planes` gives them. vertices (3, n, P) -> (3, n + 4, P)."""
    vertices = jnp.transpose(vertices, (1, 0, 2))
    for face in range(4):
        vertices, count = _clip_stage_columns(vertices, count, face_normals[face], face_offsets[face])
    return jnp.transpose(vertices, (1, 0, 2)), count


def calc_tet_face_planes(tet_vertices):
    """Outward face planes (normal . x <= offset inside) of positively oriented tets
    (..., 4, 3), the faces in the order :func:`clip_polygon_by_tet_faces` clips by:
    (..., 4 faces, 4) with the unnormalised normal in 0-2 and the offset in 3."""
    planes = []
    for face in ([1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]):
        a, b, c = tet_vertices[..., face[0], :], tet_vertices[..., face[1], :], tet_vertices[..., face[2], :]
        outward = jnp.cross(b - a, c - a)
        planes.append(jnp.concatenate([outward, jnp.sum(outward * a, axis=-1, keepdims=True)], axis=-1))
    return jnp.stack(planes, axis=-2)


def calc_polygon_integrals_columns(vertices, count, pressures, normal):
    """:func:`calc_polygon_integrals` for P polygons: vertices (3, n, P), count (P,),
    pressures (n, P), normal (3, P).

    **Returns:** (area (P,), int p dA (P,), int x dA (3, P), int p x dA (3, P)).
    """
    n = vertices.shape[1]
    v0, p0 = vertices[:, 0], pressures[0]
    area = force = first_moment = pressure_moment = 0.0
    for i in range(1, n - 1):
        vi, vj, pi, pj = vertices[:, i], vertices[:, i + 1], pressures[i], pressures[i + 1]
        fan = 0.5 * jnp.sum(jnp.cross(vi - v0, vj - v0, axis=0) * normal, axis=0)
        fan = jnp.where(i + 1 < count, fan, 0.0)
        sum_p = p0 + pi + pj
        sum_x = v0 + vi + vj
        area = area + fan
        force = force + fan * sum_p
        first_moment = first_moment + fan[None] * sum_x
        weighted = p0[None] * v0 + pi[None] * vi + pj[None] * vj + sum_p[None] * sum_x
        pressure_moment = pressure_moment + fan[None] * weighted
    return area, force / 3.0, first_moment / 3.0, pressure_moment / 12.0


def to_polygon_rows(vertices, pressures, capacity):
    """Column-layout polygons (3, n, P), (n, P) to the ContactSurface layout
    (P, capacity, 3), (P, capacity), padding with zeros."""
    n = vertices.shape[1]
    vertices = jnp.transpose(vertices, (2, 1, 0))
    pressures = jnp.transpose(pressures)
    if n < capacity:
        vertices = jnp.concatenate([vertices, jnp.zeros((vertices.shape[0], capacity - n, 3), vertices.dtype)], axis=1)
        pressures = jnp.concatenate([pressures, jnp.zeros((pressures.shape[0], capacity - n), pressures.dtype)], axis=1)
    return vertices, pressures
