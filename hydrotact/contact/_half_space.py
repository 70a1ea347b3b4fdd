"""Soft body against a rigid half-space: slice the tets by the plane (fast path).

The rigid half-space fills z >= 0 of its frame R. In frame S its face is the plane
through p_SR with inward normal m = R_SR z; the contact surface is that plane's
section through the soft body, one convex polygon (3 or 4 vertices) per cut tet,
pushed along -m.

The section of a tet is found by marching tets: the signs of the four vertex heights
pick one of 16 cases, each a fixed cycle of the 3 or 4 tet edges the plane crosses;
each crossing is an edge interpolation, and the pressure there interpolates the
vertex pressures (exact for a linear field). The cycle is reversed where needed so
every polygon winds counter-clockwise about the push direction.
"""


import jax.numpy as jnp
import numpy as np

from .._buffers import compact_indices
from ..field import PressureField
from ._broadphase import Capacity, TetClusters, box_meets_plane, select_clusters
from ._polygon import calc_polygon_integrals_columns, clip_polygon_by_tet_faces, to_polygon_rows
from ._pose import Pose
from ._surface import POLYGON_CAPACITY, ContactSurface, assemble_surface

TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])


def _marching_tets_table() -> np.ndarray:
    """For each sign pattern (bit k set: vertex k above the plane), the crossed edges
    in cyclic order, padded with -1: (16, 4)."""
    edge_id = {tuple(e): k for k, e in enumerate(TET_EDGES.tolist())}
    table = np.full((16, 4), -1, dtype=np.int32)
    for case in range(16):
        above = [v for v in range(4) if case >> v & 1]
        below = [v for v in range(4) if not case >> v & 1]
        if len(above) in (0, 4):
            continue
        if len(above) == 2:
            (a, b), (c, d) = above, below
            cycle = [(a, c), (a, d), (b, d), (b, c)]  # consecutive edges share a vertex
        else:
            single, others = (above[0], below) if len(above) == 1 else (below[0], above)
            cycle = [(single, o) for o in others]
        for slot, (u, v) in enumerate(cycle):
            table[case, slot] = edge_id[(min(u, v), max(u, v))]
    return table


MARCHING_TETS = _marching_tets_table()


def _marching_tets_flips() -> np.ndarray:
    """For each sign pattern, whether the cycle of MARCHING_TETS runs clockwise about
    -grad h (the push direction) in a positively oriented tet (16,).

    The winding is a property of the case, not of the geometry: on a positively
    oriented tet the same case always winds the same way. Taking it from the table
    rather than from the polygon's own normal keeps it right where the polygon is
    degenerate (the plane exactly on a vertex, an edge or a face: a zero-area polygon
    whose derivative still counts), where that normal is zero. Found once on the unit
    tet, with heights +1 above and -1 below (any signs are some plane's).
    """
    corners = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    flips = np.zeros(16, dtype=bool)
    for case in range(1, 15):
        heights = np.array([1.0 if case >> v & 1 else -1.0 for v in range(4)])
        gradient = heights[1:] - heights[0]  # h(x) = h_0 + gradient . x on the unit tet
        points = []
        for edge in MARCHING_TETS[case][MARCHING_TETS[case] >= 0]:
            a, b = TET_EDGES[edge]
            t = heights[a] / (heights[a] - heights[b])
            points.append(corners[a] + t * (corners[b] - corners[a]))
        normal = np.cross(points[1] - points[0], points[2] - points[0])
        flips[case] = np.dot(normal, -gradient) < 0.0
    return flips


MARCHING_FLIPS = _marching_tets_flips()


def plane_square(point, normal, centre, half_size):
    """A square in the plane (point, normal) centred on `centre`'s projection, wound
    counter-clockwise about `normal`, in a (capacity, 3) polygon buffer."""
    helper = jnp.where(jnp.abs(normal[0]) < 0.9, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0])).astype(normal.dtype)
    u = jnp.cross(normal, helper)
    u = u / jnp.sqrt(jnp.sum(u * u))
    v = jnp.cross(normal, u)
    middle = centre - jnp.dot(centre - point, normal) * normal
    corners = jnp.stack([middle + half_size * (su * u + sv * v) for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return jnp.zeros((POLYGON_CAPACITY, 3), normal.dtype).at[:4].set(corners)


def slice_tet(tet_vertices, point, normal):
    """The section of a tet by the plane (point, normal) as a clipped square: (polygon
    buffer, count), wound counter-clockwise about `normal`. Used where the polygon is
    clipped further (soft-soft)."""
    centre = jnp.mean(tet_vertices, axis=0)
    half_size = 2.0 * jnp.max(jnp.sqrt(jnp.sum((tet_vertices - centre[None]) ** 2, axis=-1))) + 1e-300
    square = plane_square(point, normal, centre, half_size)
    return clip_polygon_by_tet_faces(square, jnp.asarray(4), tet_vertices)


def slice_tets_marching_columns(tet_vertices, tet_values, heights):
    """The sections of P positively oriented tets where `heights` (signed, per vertex,
    of a linear function) vanish, in column layout (see `_polygon.py`): tet_vertices
    (3, 4, P), tet_values and heights (4, P). Polygons wind counter-clockwise about
    the direction in which the heights fall (MARCHING_FLIPS); `tet_values` are
    interpolated linearly along the crossed edges. Every crossing is computed on all
    six edges, then each polygon slot selects its edge from the case table: no
    per-vertex gathers.

    **Returns:** (vertices (3, 4, P), values (4, P), counts (P,)).
    """
    case = sum(jnp.where(heights[k] > 0.0, 1 << k, 0) for k in range(4))
    edges = jnp.transpose(jnp.asarray(MARCHING_TETS)[case])  # (4 slots, P)
    points, values = [], []
    for a, b in TET_EDGES.tolist():
        h0, h1 = heights[a], heights[b]
        denominator = h0 - h1
        t = jnp.where(denominator != 0.0, h0 / jnp.where(denominator != 0.0, denominator, 1.0), 0.0)
        points.append(tet_vertices[:, a] + t[None] * (tet_vertices[:, b] - tet_vertices[:, a]))
        values.append(tet_values[a] + t * (tet_values[b] - tet_values[a]))
    slot_points, slot_values = [], []
    for k in range(4):
        slot_points.append(sum(jnp.where(edges[k][None] == e, points[e], 0.0) for e in range(6)))
        slot_values.append(sum(jnp.where(edges[k] == e, values[e], 0.0) for e in range(6)))
    count = jnp.sum(edges >= 0, axis=0)
    # Wind counter-clockwise about push: reverse the cycle where the case runs the
    # other way (slots 1 and 3 swap for a quadrilateral, 1 and 2 for a triangle).
    p0, p1, p2, p3 = slot_points
    flip = jnp.asarray(MARCHING_FLIPS)[case]
    quad = count == 4
    v0, v1, v2, v3 = slot_values
    order = (
        (p0, v0),
        (jnp.where(flip[None], jnp.where(quad[None], p3, p2), p1), jnp.where(flip, jnp.where(quad, v3, v2), v1)),
        (jnp.where((flip & ~quad)[None], p1, p2), jnp.where(flip & ~quad, v1, v2)),
        (jnp.where((flip & quad)[None], p1, p3), jnp.where(flip & quad, v1, v3)),
    )
    return jnp.stack([p for p, _ in order], axis=1), jnp.stack([v for _, v in order]), count


def calc_half_space_surface(
    field: PressureField, X_SR: Pose, capacity: Capacity = Capacity(), brute_force: bool = False, clusters: TetClusters | None = None
) -> ContactSurface:
    """The contact surface of a soft body and the rigid half-space z >= 0 of frame R
    (pure, jittable, vmappable over X_SR, differentiable). `brute_force` slices every
    tet (the reference for the culling); `clusters` makes the tet search hierarchical.

    Convention (Drake's soft-volume / rigid-half-space query): the section of *every*
    tet the plane cuts counts, whatever the angle between the push direction and the
    tet's pressure gradient. The soft-mesh / rigid-mesh query
    (:func:`calc_soft_rigid_surface`) instead drops polygons whose normal is more than
    5 pi / 8 from the gradient, as Drake's does. The two agree until the plane passes
    a ridge of the pressure field, where the gradient turns away from the push (the
    pad5x5 mid-plane with the distance field): past it the half-space keeps the
    whole section, as Drake does.

    The cut tets go to the `polygons` buffer; with clusters, the clusters whose boxes
    the plane crosses fill the `tets` buffer first.
    """
    inward = X_SR.rotate(jnp.array([0.0, 0.0, 1.0], field.vertices.dtype))
    point = X_SR.translation.astype(field.vertices.dtype)
    push = -inward  # the force on the soft body points out of the rigid body
    tet_points = field.vertices[field.tets]
    # Heights per vertex, gathered per tet: every tet sees the same value at a vertex.
    vertex_heights = jnp.einsum("vd,d->v", field.vertices, inward) - jnp.dot(point, inward)
    if brute_force or clusters is None:
        heights = vertex_heights[field.tets]
        cut = (jnp.min(heights, axis=1) <= 0.0) & (jnp.max(heights, axis=1) >= 0.0)
        size = tet_points.shape[0] if brute_force else capacity.polygons
        tets, tets_valid, num_tets = compact_indices(jnp.ones_like(cut) if brute_force else cut, size)
        tet_index = jnp.maximum(tets, 0)
        tet_heights = heights[tet_index]
        near_overflow, num_near = jnp.asarray(False), jnp.asarray(0)
    else:
        near, near_valid, num_near = select_clusters(clusters, tet_points, box_meets_plane(point, inward), capacity.tets)
        near = jnp.maximum(near, 0).reshape(-1)
        near_heights = vertex_heights[field.tets[near]]
        cut = near_valid.reshape(-1) & (jnp.min(near_heights, axis=1) <= 0.0) & (jnp.max(near_heights, axis=1) >= 0.0)
        size = capacity.polygons
        chosen, tets_valid, num_tets = compact_indices(cut, size)
        tet_index = near[jnp.maximum(chosen, 0)]
        tet_heights = near_heights[jnp.maximum(chosen, 0)]
        near_overflow = num_near > near.shape[0]
    # One gather per polygon: the tet's vertices, vertex pressures and gradient.
    tet_rows = jnp.concatenate(
        [tet_points.reshape(-1, 12), field.vertex_pressures[field.tets], field.calc_tet_pressure_gradients()], axis=1
    )
    rows = tet_rows[tet_index].T  # (19, size)
    vertices, pressures, counts = slice_tets_marching_columns(
        jnp.transpose(rows[:12].reshape(4, 3, -1), (1, 0, 2)), rows[12:16], tet_heights.T
    )
    area, integral, first_moment, pressure_moment = calc_polygon_integrals_columns(vertices, counts, pressures, push[:, None])
    vertices, pressures = to_polygon_rows(vertices, pressures, POLYGON_CAPACITY)
    polygons = (vertices, pressures, counts, area, integral, first_moment.T, pressure_moment.T)
    normals = jnp.broadcast_to(push[None], (size, 3))
    keep = jnp.ones(size, dtype=bool)  # Drake's half-space convention: every cut tet counts
    overflow = (num_tets > size) | near_overflow
    needed = jnp.array([num_near, 0, 0, num_tets])
    return assemble_surface(polygons, normals, tets_valid, keep, tet_index, jnp.full(size, -1), overflow, needed)
