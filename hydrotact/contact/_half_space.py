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


import jax
import jax.numpy as jnp
import numpy as np

from ..field import PressureField
from ._broadphase import Capacity, TetClusters, box_meets_plane, calc_boxes, select, select_clustered_tets
from ._polygon import calc_polygon_integrals, clip_polygon_by_tet_faces
from ._pose import Pose
from ._soft_rigid import is_normal_along_gradient
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


def slice_tet_marching(tet_vertices, tet_values, heights, push):
    """The section of one tet where `heights` (signed, per vertex) vanish: polygon
    vertices (capacity, 3) wound counter-clockwise about `push`, the linearly
    interpolated `tet_values` there, and the vertex count (0, 3 or 4)."""
    case = jnp.sum(jnp.where(heights > 0.0, jnp.array([1, 2, 4, 8]), 0))
    edges = jnp.asarray(MARCHING_TETS)[case]
    used = edges >= 0
    ends = jnp.asarray(TET_EDGES)[jnp.maximum(edges, 0)]
    h0, h1 = heights[ends[:, 0]], heights[ends[:, 1]]
    denominator = h0 - h1
    t = jnp.where(used & (denominator != 0.0), h0 / jnp.where(denominator != 0.0, denominator, 1.0), 0.0)
    points = tet_vertices[ends[:, 0]] + t[:, None] * (tet_vertices[ends[:, 1]] - tet_vertices[ends[:, 0]])
    values = tet_values[ends[:, 0]] + t * (tet_values[ends[:, 1]] - tet_values[ends[:, 0]])
    count = jnp.sum(used)
    # Wind counter-clockwise about push: reverse the cycle when it runs the other way.
    orientation = jnp.dot(jnp.cross(points[1] - points[0], points[2] - points[0]), push)
    reverse = jnp.where(count == 4, jnp.array([0, 3, 2, 1]), jnp.array([0, 2, 1, 3]))
    order = jnp.where(orientation < 0.0, reverse, jnp.arange(4))
    points, values = points[order], values[order]
    pad = POLYGON_CAPACITY - 4
    points = jnp.concatenate([jnp.where(used[order][:, None], points, 0.0), jnp.zeros((pad, 3), points.dtype)])
    values = jnp.concatenate([jnp.where(used[order], values, 0.0), jnp.zeros(pad, values.dtype)])
    return points, values, count


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


def calc_half_space_surface(
    field: PressureField, X_SR: Pose, capacity: Capacity = Capacity(), brute_force: bool = False, clusters: TetClusters | None = None
) -> ContactSurface:
    """The contact surface of a soft body and the rigid half-space z >= 0 of frame R
    (pure, jittable, vmappable over X_SR, differentiable). `brute_force` slices every
    tet (the reference for the culling); `clusters` makes the tet search hierarchical."""
    inward = X_SR.rotate(jnp.array([0.0, 0.0, 1.0], field.vertices.dtype))
    point = X_SR.translation.astype(field.vertices.dtype)
    push = -inward  # the force on the soft body points out of the rigid body
    tet_points = field.vertices[field.tets]
    if brute_force or clusters is None:
        heights = jnp.einsum("tkd,d->tk", tet_points, inward) - jnp.dot(point, inward)
        cut = (jnp.min(heights, axis=1) <= 0.0) & (jnp.max(heights, axis=1) >= 0.0)
        size = tet_points.shape[0] if brute_force else capacity.pairs
        tets, tets_valid, num_tets = select(jnp.ones_like(cut) if brute_force else cut, size)
        tet_index = jnp.maximum(tets, 0)
        tet_heights = heights[tet_index]
        near_overflow, num_near = jnp.asarray(False), jnp.asarray(0)
    else:
        tet_lo, tet_hi = calc_boxes(tet_points)
        near, near_valid, num_near = select_clustered_tets(clusters, tet_lo, tet_hi, box_meets_plane(point, inward), capacity.tets)
        near = jnp.maximum(near, 0)
        near_heights = jnp.einsum("tkd,d->tk", tet_points[near], inward) - jnp.dot(point, inward)
        cut = near_valid & (jnp.min(near_heights, axis=1) <= 0.0) & (jnp.max(near_heights, axis=1) >= 0.0)
        size = capacity.pairs
        chosen, tets_valid, num_tets = select(cut, size)
        tet_index = near[jnp.maximum(chosen, 0)]
        tet_heights = near_heights[jnp.maximum(chosen, 0)]
        near_overflow = num_near > near.shape[0]
    gradients = field.calc_tet_pressure_gradients()
    vertex_pressures = field.vertex_pressures[field.tets]

    def polygon(tet_vertices, tet_pressures, tet_heights):
        vertices, pressures, count = slice_tet_marching(tet_vertices, tet_pressures, tet_heights, push)
        return (vertices, pressures, count, *calc_polygon_integrals(vertices, count, pressures, push))

    polygons = jax.vmap(polygon)(tet_points[tet_index], vertex_pressures[tet_index], tet_heights)
    normals = jnp.broadcast_to(push[None], (size, 3))
    keep = jax.vmap(is_normal_along_gradient, in_axes=(None, 0))(push, gradients[tet_index])
    overflow = (num_tets > size) | near_overflow
    return assemble_surface(polygons, normals, tets_valid, keep, tet_index, jnp.full(size, -1), overflow, jnp.array([num_near, 0, num_tets]))
