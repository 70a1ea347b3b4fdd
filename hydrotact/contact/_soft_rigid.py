"""Soft-rigid contact: the rigid surface inside the soft body, with the soft body's
pressure on it (Drake's soft-volume / rigid-surface intersection).

For each candidate pair of a soft tet and a rigid triangle, the triangle is clipped by
the tet's four faces; the piece (a convex polygon of at most 7 vertices) carries the
tet's linear pressure and the triangle's outward normal, which is the direction the
pressure pushes the soft body.
"""

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from .._buffers import compact_indices
from ..field import PressureField
from ._broadphase import Capacity, TetClusters, boxes_overlap, calc_boxes, calc_cluster_boxes
from ._polygon import calc_polygon_integrals_columns, calc_tet_face_planes, clip_polygon_by_tet_faces_columns, to_polygon_rows
from ._pose import Pose
from ._surface import POLYGON_CAPACITY, ContactSurface, assemble_surface

if TYPE_CHECKING:  # the probes module imports this kernel
    from ._probes import RigidSurface


def calc_tet_pressure_planes(field: PressureField):
    """Each tet's pressure as p(x) = offset + gradient . x (frame S)."""
    gradients = field.calc_tet_pressure_gradients()
    first = field.tets[:, 0]
    offsets = field.modulus * field.strain[first] - jnp.sum(gradients * field.vertices[first], axis=-1)
    return offsets, gradients


def is_normal_along_gradient(normal, gradient, axis: int = -1):
    """Whether the direction `normal` in which a polygon pushes a soft body lies within
    5 pi / 8 of that body's pressure gradient (which points into the body); the
    vectors' components along `axis`.

    This is Drake's filter: a piece of rigid surface that faces back out of the soft
    body (say, the far side of a probe pushed right through a thin pad) is dropped.
    """
    gradient_norm = jnp.sqrt(jnp.maximum(jnp.sum(gradient * gradient, axis=axis), 1e-300))
    return jnp.sum(normal * gradient, axis=axis) >= jnp.cos(5.0 * jnp.pi / 8.0) * gradient_norm


# Separation tests cull a pair only when it is separated by more than this fraction of
# the coordinates' magnitude (a picometre at centimetre scale), far above round-off:
# a culled pair is one whose clipped polygon would have been empty.
SEPARATION_TOLERANCE = 1e-10

# The cluster search holds this many times `Capacity.tets` tet slots before the tets
# inside the region are compacted into the `tets` buffer.
CLUSTER_SEARCH = 4


# Per-tet rows (43), in the order the stages stop reading them, so that each stage's
# gather takes one leading block: the clipping reads TET_CLIP_ROWS, the plane tests
# TET_TEST_ROWS, the box test all.
TET_VERTICES = 0  # 12, vertex-major
TET_PLANES = 12  # 16, face-major: outward normal (unnormalised), offset
TET_PLANE_LENGTHS = 28  # 4, the face normals' lengths
TET_REACH = 32  # 1, the largest coordinate
TET_PRESSURE = 33  # 4: the pressure plane's offset, then its gradient
TET_TEST_ROWS = 33
TET_CLIP_ROWS = 37
TET_LO = 37  # 3
TET_HI = 40  # 3

# Per-triangle rows (35), likewise.
TRI_VERTICES = 0  # 9, vertex-major
TRI_NORMAL = 9  # 3, unit
TRI_OFFSET = 12  # 1, normal . x on the plane
TRI_REACH = 13  # 1, the largest coordinate
TRI_CLIP_ROWS = 14
TRI_EDGES = 14  # 12: for each edge the outward in-plane normal (end - start) x normal, then its offset
TRI_EDGE_LENGTHS = 26  # 3, the edge normals' lengths
TRI_TEST_ROWS = 29
TRI_LO = 29  # 3
TRI_HI = 32  # 3


class _Columns:
    """Row k of a table held as columns: `_Columns(a)[k]` is `a[:, k]`."""

    def __init__(self, table):
        self.table = table

    def __getitem__(self, k):
        return self.table[:, k]


def _tet_columns(tet_points, face_planes, offsets, gradients):
    """Per-tet data the pair tests and the clipping read, one row per quantity (43,
    num_tets), laid out as the TET_* indices say."""
    lo, hi = calc_boxes(tet_points)
    lengths = jnp.sqrt(jnp.sum(face_planes[..., :3] ** 2, axis=-1))
    reach = jnp.max(jnp.maximum(jnp.abs(lo), jnp.abs(hi)), axis=-1, keepdims=True)
    rows = [tet_points.reshape(-1, 12), face_planes.reshape(-1, 16), lengths, reach, offsets[:, None], gradients, lo, hi]
    return jnp.concatenate(rows, axis=1).T


def _triangle_rows(triangles, lo, hi):
    """Per-triangle data the pair tests and the clipping read (num_triangles, 35), laid
    out as the TRI_* indices say, from the triangles (T, 3, 3) and their boxes."""
    normals = jnp.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals = normals / jnp.sqrt(jnp.maximum(jnp.sum(normals**2, axis=-1, keepdims=True), 1e-300))
    offset = jnp.sum(normals * triangles[:, 0], axis=-1, keepdims=True)
    edges, lengths = [], []
    for e in range(3):
        start, end = triangles[:, e], triangles[:, (e + 1) % 3]
        outward = jnp.cross(end - start, normals)
        edges += [outward, jnp.sum(outward * start, axis=-1, keepdims=True)]
        lengths.append(jnp.sqrt(jnp.sum(outward * outward, axis=-1, keepdims=True)))
    reach = jnp.max(jnp.maximum(jnp.abs(lo), jnp.abs(hi)), axis=-1, keepdims=True)
    return jnp.concatenate([triangles.reshape(-1, 9), normals, offset, reach, *edges, *lengths, lo, hi], axis=1)


def _boxes_meet(tet, triangle):
    """Whether the boxes of tets and triangles overlap (`tet[k]` row k of `_tet_columns`,
    `triangle[k]` row k of `_triangle_rows`' transpose, or a `_Columns` view; each row
    shaped to broadcast against the other's: (S, 1) against (1, T) for every tet
    against every triangle)."""
    meet = None
    for axis in range(3):
        overlap = (tet[TET_LO + axis] <= triangle[TRI_HI + axis]) & (triangle[TRI_LO + axis] <= tet[TET_HI + axis])
        meet = overlap if meet is None else meet & overlap
    return meet


def _heights_above_triangle_plane(tet, triangle):
    """The four tet vertices' signed heights along the triangle's unit normal, above
    its plane (rows as in :func:`_boxes_meet`): a list of 4 rows."""
    n = [triangle[TRI_NORMAL + axis] for axis in range(3)]
    return [tet[3 * k] * n[0] + tet[3 * k + 1] * n[1] + tet[3 * k + 2] * n[2] - triangle[TRI_OFFSET] for k in range(4)]


def _pair_scale(tet, triangle):
    """SEPARATION_TOLERANCE times the pair's coordinate magnitude."""
    return SEPARATION_TOLERANCE * jnp.maximum(tet[TET_REACH], triangle[TRI_REACH])


def _planes_may_meet(tet, triangle):
    """Whether tets and triangles whose boxes overlap may meet: the tet straddles the
    triangle's plane, and no tet face plane and no triangle edge plane separates them
    (rows as in :func:`_boxes_meet`, here one pair per column).

    Every plane is a face of one of the two convex bodies, so no pair whose
    intersection has positive area is culled; the tests cull only pairs apart by more
    than SEPARATION_TOLERANCE times the coordinates' magnitude (far above round-off).
    """
    heights = _heights_above_triangle_plane(tet, triangle)
    lowest = jnp.minimum(jnp.minimum(heights[0], heights[1]), jnp.minimum(heights[2], heights[3]))
    highest = jnp.maximum(jnp.maximum(heights[0], heights[1]), jnp.maximum(heights[2], heights[3]))
    scale = _pair_scale(tet, triangle)
    # A tet with a face in the plane from the soft side (three vertices within the tie
    # tolerance above it) is kept for the tie rule (:func:`_resolve_face_ties`), which
    # drops its neighbour on the rigid side within the same tolerance: a face a hair on
    # either side of a tet-face layer keeps its piece once. One touching at an edge or
    # a vertex only would give a polygon of no area: culled.
    near = [jnp.where(h <= scale, 1, 0) for h in heights]
    face_on_plane = (lowest > 0.0) & (near[0] + near[1] + near[2] + near[3] >= 3)
    meet = ((lowest <= 0.0) & (highest >= 0.0)) | face_on_plane
    for f in range(4):
        row = TET_PLANES + 4 * f
        nearest = None
        for v in range(3):
            d = tet[row] * triangle[3 * v] + tet[row + 1] * triangle[3 * v + 1] + tet[row + 2] * triangle[3 * v + 2]
            nearest = d if nearest is None else jnp.minimum(nearest, d)
        meet = meet & (nearest - tet[row + 3] <= scale * tet[TET_PLANE_LENGTHS + f])
    for e in range(3):
        row = TRI_EDGES + 4 * e
        nearest = None
        for k in range(4):
            d = tet[3 * k] * triangle[row] + tet[3 * k + 1] * triangle[row + 1] + tet[3 * k + 2] * triangle[row + 2]
            nearest = d if nearest is None else jnp.minimum(nearest, d)
        meet = meet & (nearest - triangle[row + 3] <= scale * triangle[TRI_EDGE_LENGTHS + e])
    return meet


def _resolve_face_ties(tet, triangle):
    """The tie rule for a rigid triangle whose plane touches a tet (rows as in
    :func:`_planes_may_meet`, one pair per column).

    A triangle in the plane of a face shared by two tets lies, to round-off, inside
    both, and clipping would give each the whole piece: the pressure counted twice (a
    flat probe face on a vertex layer of a structured mesh). The rule keeps the piece
    in the tets on the side the triangle's normal points to (out of the rigid body,
    into the soft body it pushes) and drops every pair whose tet only touches the
    plane from the rigid body's side (at a face, an edge or a vertex). A kept tet
    whose face lies in the plane is not clipped by that face. The pressure is
    continuous across the face, so the surface is the limit of the poses just off
    the tie from either side; and every polygon left is the one the triangle's motion
    along its normal (deeper) opens, so derivatives on the tie are the one-sided ones
    of going deeper (the zero-area polygons that the touching tets on the rigid side
    would give open only the other way).

    "Touching" means within SEPARATION_TOLERANCE times the coordinates' magnitude (a
    picometre at centimetre scale): far above the round-off of the pose transform and
    the face planes, far below any real offset. Off the tie the clipping decides as
    usual; what the tolerance moves has a thickness below it.

    **Returns:** (the tet's outward face normals (4, 3, P) and the offsets to clip by
    (4, P), with the kept tie faces moved out of the way; which pairs the rule drops
    (P,)).
    """
    planes = tet[TET_PLANES : TET_PLANES + 16].reshape(4, 4, -1)
    scale = _pair_scale(tet, triangle)
    heights = _heights_above_triangle_plane(tet, triangle)
    touching = [jax.lax.stop_gradient(jnp.abs(h) <= scale) for h in heights]
    highest = jnp.maximum(jnp.maximum(heights[0], heights[1]), jnp.maximum(heights[2], heights[3]))
    drop = jax.lax.stop_gradient(highest <= scale)
    # Face f (opposite vertex f) lies in the plane when its three vertices do; a kept
    # tie face clips nothing: its plane moves out by the tet's own size.
    offsets = []
    for f in range(4):
        others = [touching[k] for k in range(4) if k != f]
        tie = others[0] & others[1] & others[2]
        margin = jax.lax.stop_gradient(tet[TET_REACH] * tet[TET_PLANE_LENGTHS + f])
        offsets.append(jnp.where(tie, planes[f, 3] + margin, planes[f, 3]))
    return planes[:, :3], jnp.stack(offsets), drop


def calc_soft_rigid_surface(
    field: PressureField,
    rigid: "RigidSurface",
    X_SR: Pose,
    capacity: Capacity = Capacity(),
    brute_force: bool = False,
    clusters: TetClusters | None = None,
) -> ContactSurface:
    """The contact surface of a soft body and a rigid surface at pose X_SR (pure,
    jittable, vmappable over X_SR, differentiable in X_SR, E and the field).

    Normals point out of the rigid body, the direction of the force on the soft body.
    Convention (Drake's soft-volume / rigid-mesh query): a polygon whose normal is
    more than 5 pi / 8 from the tet's pressure gradient is dropped
    (:func:`is_normal_along_gradient`); a triangle lying in the plane of a tet face
    counts in one tet only (:func:`_resolve_face_ties`), where Drake counts it in both.
    `brute_force` clips every tet against every triangle (the reference for the broad
    phase; its buffers hold num_tets x num_faces polygons and never overflow).
    `clusters` (from :func:`make_tet_clusters`) makes the tet search hierarchical.

    Broad phase: the tets (found through their clusters) and the triangles whose
    boxes meet the region where the bodies can touch, the soft body's box cut to the
    box of the triangles that meet it (`tets`, `others` buffers); then every such tet
    against every such triangle by their boxes, at once (the pairs whose boxes meet
    fill the `pairs` buffer); on those pairs only, the triangle's plane, the tet's
    face planes and the triangle's edge planes (:func:`_planes_may_meet`); the pairs
    that pass (`polygons`) are clipped, in column layout (see `_polygon.py`). When
    `pairs` overflows, `needed[3]` counts only the pairs that fitted.
    """
    dtype = field.vertices.dtype
    vertices_S = X_SR.apply(jnp.asarray(rigid.vertices_R, dtype))
    triangles = vertices_S[rigid.faces]
    tri_lo, tri_hi = calc_boxes(triangles)
    # Grown by the tie tolerance (at the largest coordinate of either body, above every
    # pair's): a triangle a hair outside a tet-face layer still meets the tets on the
    # layer's other side, and the tie rule (_resolve_face_ties) decides which tet keeps
    # its piece; the boxes only select candidates.
    grow = jax.lax.stop_gradient(SEPARATION_TOLERANCE * jnp.maximum(jnp.max(jnp.abs(field.vertices)), jnp.max(jnp.abs(vertices_S))))
    tri_lo, tri_hi = tri_lo - grow, tri_hi + grow
    tet_points = field.vertices[field.tets]
    face_planes = calc_tet_face_planes(tet_points)  # (num_tets, 4, 4)
    offsets, gradients = calc_tet_pressure_planes(field)
    tet_rows = _tet_columns(tet_points, face_planes, offsets, gradients).T  # (num_tets, 43)

    if brute_force:
        num_tets, num_tris = tet_points.shape[0], triangles.shape[0]
        tet_index = jnp.repeat(jnp.arange(num_tets), num_tris)
        tri_index = jnp.tile(jnp.arange(num_tris), num_tets)
        pair_valid = jnp.ones(tet_index.shape, dtype=bool)
        needed = jnp.array([num_tets, num_tris, tet_index.shape[0], tet_index.shape[0]])
        overflow = jnp.asarray(False)
        pair_tets, pair_triangles = tet_rows[tet_index].T, _triangle_rows(triangles, tri_lo, tri_hi)[tri_index].T
    else:
        if clusters is None:  # every tet its own cluster
            clusters = TetClusters(members=jnp.arange(tet_points.shape[0], dtype=jnp.int32)[:, None])
        members = jnp.asarray(clusters.members)
        cluster_size = clusters.cluster_size
        cluster_lo, cluster_hi = calc_cluster_boxes(clusters, tet_points)
        # The region: the soft body's box, cut to the box of the triangles that meet it
        # (a triangle that meets a tet meets the soft body's box, at a point of both).
        soft_lo, soft_hi = jnp.min(cluster_lo, axis=0), jnp.max(cluster_hi, axis=0)
        touching = boxes_overlap(tri_lo, tri_hi, soft_lo[None], soft_hi[None])[:, None]
        big = jnp.asarray(jnp.inf, dtype)
        region_lo = jnp.maximum(soft_lo, jnp.min(jnp.where(touching, tri_lo, big), axis=0))
        region_hi = jnp.minimum(soft_hi, jnp.max(jnp.where(touching, tri_hi, -big), axis=0))
        # Tets near the other body: clusters first, then their tets, compacted.
        num_cluster_slots = max(1, CLUSTER_SEARCH * capacity.tets // cluster_size)
        hit, hit_valid, num_hit = compact_indices(boxes_overlap(cluster_lo, cluster_hi, region_lo[None], region_hi[None]), num_cluster_slots)
        # An empty slot holds index 0 (jnp.maximum): its members must not count, or
        # cluster 0's tets would be found once per empty slot whenever cluster 0 is
        # near the probe (a press near the corner of the mesh's box where the Morton
        # order starts), duplicating their polygons.
        candidates = jnp.where(hit_valid[:, None], members[jnp.maximum(hit, 0)], -1).reshape(-1)
        safe_candidates = jnp.maximum(candidates, 0)
        candidate_boxes = tet_rows[:, TET_LO : TET_HI + 3][safe_candidates]  # the boxes only; whole rows for the near tets
        near_mask = (candidates >= 0) & boxes_overlap(candidate_boxes[:, :3], candidate_boxes[:, 3:], region_lo[None], region_hi[None])
        near, near_valid, num_near = compact_indices(near_mask, capacity.tets)
        near_tets = safe_candidates[jnp.maximum(near, 0)]
        near_rows = tet_rows[near_tets]
        # The triangles near the soft body: in the region and meeting the box of a
        # cluster found (every near tet lies in one), which on a curved sensor leaves
        # the part of a probe over the skin near the press, not all of it inside the
        # sensor's box; their full rows only for those.
        hit_lo = jnp.where(hit_valid[:, None], cluster_lo[jnp.maximum(hit, 0)], big)
        hit_hi = jnp.where(hit_valid[:, None], cluster_hi[jnp.maximum(hit, 0)], -big)
        near_clusters = jnp.any(boxes_overlap(tri_lo[:, None], tri_hi[:, None], hit_lo[None], hit_hi[None]), axis=1)
        near_triangles = boxes_overlap(tri_lo, tri_hi, region_lo[None], region_hi[None]) & near_clusters
        tris, tris_valid, num_tris = compact_indices(near_triangles, capacity.others)
        tris = jnp.maximum(tris, 0)
        tri_rows = _triangle_rows(triangles[tris], tri_lo[tris], tri_hi[tris])
        # Every near tet against every near triangle by their boxes (cheap, dense);
        # the finer plane tests only on the pairs whose boxes meet; then the survivors.
        boxes_meet = _boxes_meet(near_rows.T[:, :, None], tri_rows.T[:, None, :])
        boxes_meet = boxes_meet & near_valid[:, None] & tris_valid[None, :]
        candidate, candidate_valid, num_candidates = compact_indices(boxes_meet, capacity.pairs)
        candidate = jnp.maximum(candidate, 0)
        i, j = candidate // tris.shape[0], candidate % tris.shape[0]
        # The rows the plane tests read, gathered from the small near lists.
        candidate_tets, candidate_triangles = _Columns(near_rows[:, :TET_TEST_ROWS][i]), _Columns(tri_rows[:, :TRI_TEST_ROWS][j])
        may_meet = candidate_valid & _planes_may_meet(candidate_tets, candidate_triangles)
        chosen, pair_valid, num_polygons = compact_indices(may_meet, capacity.polygons)
        chosen = jnp.maximum(chosen, 0)
        tet_index, tri_index = near_tets[i[chosen]], tris[j[chosen]]
        # Only the rows the clipping reads, gathered from the small near lists.
        pair_tets = near_rows[:, :TET_CLIP_ROWS][i[chosen]].T
        pair_triangles = tri_rows[:, :TRI_CLIP_ROWS][j[chosen]].T
        search_slots = num_cluster_slots * cluster_size
        needed = jnp.array(
            [jnp.maximum(num_near, -(-num_hit * cluster_size // CLUSTER_SEARCH)), num_tris, num_candidates, num_polygons]
        )
        overflow = (
            (num_hit * cluster_size > search_slots)
            | (num_near > capacity.tets)
            | (num_tris > capacity.others)
            | (num_candidates > capacity.pairs)
            | (num_polygons > capacity.polygons)
        )

    num_polygons_slots = tet_index.shape[0]
    normals = pair_triangles[TRI_NORMAL : TRI_NORMAL + 3]  # (3, P)
    corners = jnp.transpose(pair_triangles[TRI_VERTICES : TRI_VERTICES + 9].reshape(3, 3, num_polygons_slots), (1, 0, 2))  # (3 coordinates, 3 corners, P)
    pair_gradients = pair_tets[TET_PRESSURE + 1 : TET_PRESSURE + 4]
    keep = is_normal_along_gradient(normals, pair_gradients, axis=0)
    face_normals, face_offsets, tie_drop = _resolve_face_ties(pair_tets, pair_triangles)
    vertices, counts = clip_polygon_by_tet_faces_columns(corners, jnp.full(tri_index.shape, 3), face_normals, face_offsets)
    pressures = pair_tets[TET_PRESSURE][None] + jnp.sum(vertices * pair_gradients[:, None], axis=0)
    pressures = jnp.where(jnp.arange(vertices.shape[1])[:, None] < counts[None], pressures, 0.0)
    area, integral, first_moment, pressure_moment = calc_polygon_integrals_columns(vertices, counts, pressures, normals)
    vertices, pressures = to_polygon_rows(vertices, pressures, POLYGON_CAPACITY)
    polygon = (vertices, pressures, counts, area, integral, first_moment.T, pressure_moment.T)
    return assemble_surface(polygon, normals.T, pair_valid, keep & ~tie_drop, tet_index, tri_index, overflow, needed)
