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


def is_normal_along_gradient(normal, gradient):
    """Whether the direction `normal` in which a polygon pushes a soft body lies within
    5 pi / 8 of that body's pressure gradient (which points into the body).

    This is Drake's filter: a piece of rigid surface that faces back out of the soft
    body (say, the far side of a probe pushed right through a thin pad) is dropped.
    """
    gradient_norm = jnp.sqrt(jnp.maximum(jnp.sum(gradient * gradient), 1e-300))
    return jnp.dot(normal, gradient) >= jnp.cos(5.0 * jnp.pi / 8.0) * gradient_norm


# Separation tests cull a pair only when it is separated by more than this fraction of
# the coordinates' magnitude (a picometre at centimetre scale), far above round-off:
# a culled pair is one whose clipped polygon would have been empty.
SEPARATION_TOLERANCE = 1e-10

# The cluster search holds this many times `Capacity.tets` tet slots before the tets
# inside the region are compacted into the `tets` buffer.
CLUSTER_SEARCH = 4


def _tet_columns(tet_points, face_planes, offsets, gradients):
    """Per-tet data the pair tests and the clipping read, one row per quantity
    (43, num_tets): vertices (12, vertex-major), box lo (3), hi (3), face planes (16,
    face-major: outward normal, offset), the face normals' lengths (4), the largest
    coordinate (1), the pressure plane (offset 1, gradient 3)."""
    lo, hi = calc_boxes(tet_points)
    lengths = jnp.sqrt(jnp.sum(face_planes[..., :3] ** 2, axis=-1))
    reach = jnp.max(jnp.maximum(jnp.abs(lo), jnp.abs(hi)), axis=-1, keepdims=True)
    rows = [tet_points.reshape(-1, 12), lo, hi, face_planes.reshape(-1, 16), lengths, reach, offsets[:, None], gradients]
    return jnp.concatenate(rows, axis=1).T


def _triangle_columns(triangles, normals):
    """Per-triangle data the pair tests read (35, num_triangles): vertices (9), box lo
    (3), hi (3), unit normal (3), plane offset (1), edge planes (12: for each edge the
    outward in-plane normal (end - start) x normal, then its offset), the edge
    normals' lengths (3), the largest coordinate (1)."""
    lo, hi = calc_boxes(triangles)
    offset = jnp.sum(normals * triangles[:, 0], axis=-1, keepdims=True)
    edges, lengths = [], []
    for e in range(3):
        start, end = triangles[:, e], triangles[:, (e + 1) % 3]
        outward = jnp.cross(end - start, normals)
        edges += [outward, jnp.sum(outward * start, axis=-1, keepdims=True)]
        lengths.append(jnp.sqrt(jnp.sum(outward * outward, axis=-1, keepdims=True)))
    reach = jnp.max(jnp.maximum(jnp.abs(lo), jnp.abs(hi)), axis=-1, keepdims=True)
    return jnp.concatenate([triangles.reshape(-1, 9), lo, hi, normals, offset, *edges, *lengths, reach], axis=1).T


def _boxes_meet(tet, triangle):
    """Whether the boxes of tets and triangles overlap (`tet` rows from `_tet_columns`,
    `triangle` rows from `_triangle_columns`, each row shaped to broadcast against the
    other's: (S, 1) against (1, T) for every tet against every triangle)."""
    meet = None
    for axis in range(3):
        overlap = (tet[12 + axis] <= triangle[12 + axis]) & (triangle[9 + axis] <= tet[15 + axis])
        meet = overlap if meet is None else meet & overlap
    return meet


def _heights_above_triangle_plane(tet, triangle):
    """The four tet vertices' signed heights along the triangle's unit normal, above
    its plane (rows as in :func:`_boxes_meet`): a list of 4 rows."""
    return [tet[3 * k] * triangle[15] + tet[3 * k + 1] * triangle[16] + tet[3 * k + 2] * triangle[17] - triangle[18] for k in range(4)]


def _planes_may_meet(tet, triangle):
    """Whether tets and triangles whose boxes overlap may meet: the tet straddles the
    triangle's plane, and no tet face plane and no triangle edge plane separates them
    (rows as in :func:`_boxes_meet`, here one pair per column).

    Every plane is a face of one of the two convex bodies, so no pair whose
    intersection has positive area is culled; the face and edge tests cull only pairs
    apart by more than SEPARATION_TOLERANCE times the coordinates' magnitude (far
    above round-off).
    """
    heights = _heights_above_triangle_plane(tet, triangle)
    lowest = jnp.minimum(jnp.minimum(heights[0], heights[1]), jnp.minimum(heights[2], heights[3]))
    highest = jnp.maximum(jnp.maximum(heights[0], heights[1]), jnp.maximum(heights[2], heights[3]))
    meet = (lowest <= 0.0) & (highest >= 0.0)
    scale = SEPARATION_TOLERANCE * jnp.maximum(tet[38], triangle[34])
    for f in range(4):
        row = 18 + 4 * f
        nearest = None
        for v in range(3):
            d = tet[row] * triangle[3 * v] + tet[row + 1] * triangle[3 * v + 1] + tet[row + 2] * triangle[3 * v + 2]
            nearest = d if nearest is None else jnp.minimum(nearest, d)
        meet = meet & (nearest - tet[row + 3] <= scale * tet[34 + f])
    for e in range(3):
        row = 19 + 4 * e
        nearest = None
        for k in range(4):
            d = tet[3 * k] * triangle[row] + tet[3 * k + 1] * triangle[row + 1] + tet[3 * k + 2] * triangle[row + 2]
            nearest = d if nearest is None else jnp.minimum(nearest, d)
        meet = meet & (nearest - triangle[row + 3] <= scale * triangle[31 + e])
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
    planes = tet[18:34].reshape(4, 4, -1)
    scale = SEPARATION_TOLERANCE * jnp.maximum(tet[38], triangle[34])
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
        margin = jax.lax.stop_gradient(tet[38] * tet[34 + f])
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
    triangle_normals = jnp.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    norms = jnp.sqrt(jnp.maximum(jnp.sum(triangle_normals**2, axis=-1, keepdims=True), 1e-300))
    triangle_normals = triangle_normals / norms
    tet_points = field.vertices[field.tets]
    face_planes = calc_tet_face_planes(tet_points)  # (num_tets, 4, 4)
    offsets, gradients = calc_tet_pressure_planes(field)
    tet_rows = _tet_columns(tet_points, face_planes, offsets, gradients).T  # (num_tets, 43)
    triangle_columns = _triangle_columns(triangles, triangle_normals)  # (35, num_triangles)

    if brute_force:
        num_tets, num_tris = tet_points.shape[0], triangles.shape[0]
        tet_index = jnp.repeat(jnp.arange(num_tets), num_tris)
        tri_index = jnp.tile(jnp.arange(num_tris), num_tets)
        pair_valid = jnp.ones(tet_index.shape, dtype=bool)
        needed = jnp.array([num_tets, num_tris, tet_index.shape[0], tet_index.shape[0]])
        overflow = jnp.asarray(False)
        pair_tets, pair_triangles = tet_rows[tet_index].T, triangle_columns[:, tri_index]
    else:
        if clusters is None:  # every tet its own cluster
            clusters = TetClusters(members=jnp.arange(tet_points.shape[0], dtype=jnp.int32)[:, None])
        members = jnp.asarray(clusters.members)
        cluster_size = clusters.cluster_size
        cluster_lo, cluster_hi = calc_cluster_boxes(clusters, tet_points)
        tri_lo, tri_hi = triangle_columns[9:12].T, triangle_columns[12:15].T
        # The region: the soft body's box, cut to the box of the triangles that meet it
        # (a triangle that meets a tet meets the soft body's box, at a point of both).
        soft_lo, soft_hi = jnp.min(cluster_lo, axis=0), jnp.max(cluster_hi, axis=0)
        touching = boxes_overlap(tri_lo, tri_hi, soft_lo[None], soft_hi[None])[:, None]
        big = jnp.asarray(jnp.inf, dtype)
        region_lo = jnp.maximum(soft_lo, jnp.min(jnp.where(touching, tri_lo, big), axis=0))
        region_hi = jnp.minimum(soft_hi, jnp.max(jnp.where(touching, tri_hi, -big), axis=0))
        # Tets near the other body: clusters first, then their tets, compacted.
        num_cluster_slots = max(1, CLUSTER_SEARCH * capacity.tets // cluster_size)
        hit, _, num_hit = compact_indices(boxes_overlap(cluster_lo, cluster_hi, region_lo[None], region_hi[None]), num_cluster_slots)
        candidates = members[jnp.maximum(hit, 0)].reshape(-1)
        safe_candidates = jnp.maximum(candidates, 0)
        candidate_rows = tet_rows[safe_candidates]
        near_mask = (candidates >= 0) & boxes_overlap(candidate_rows[:, 12:15], candidate_rows[:, 15:18], region_lo[None], region_hi[None])
        near, near_valid, num_near = compact_indices(near_mask, capacity.tets)
        near = jnp.maximum(near, 0)
        near_tets, near_rows = safe_candidates[near], candidate_rows[near]
        tris, tris_valid, num_tris = compact_indices(boxes_overlap(tri_lo, tri_hi, region_lo[None], region_hi[None]), capacity.others)
        tris = jnp.maximum(tris, 0)
        tri_rows = triangle_columns[:, tris].T
        # Every near tet against every near triangle by their boxes (cheap, dense);
        # the finer plane tests only on the pairs whose boxes meet; then the survivors.
        boxes_meet = _boxes_meet(near_rows.T[:, :, None], tri_rows.T[:, None, :])
        boxes_meet = boxes_meet & near_valid[:, None] & tris_valid[None, :]
        candidate, candidate_valid, num_candidates = compact_indices(boxes_meet, capacity.pairs)
        candidate = jnp.maximum(candidate, 0)
        i, j = candidate // tris.shape[0], candidate % tris.shape[0]
        candidate_tets, candidate_triangles = near_rows[i].T, tri_rows[j].T  # gathers from the small near lists
        may_meet = candidate_valid & _planes_may_meet(candidate_tets, candidate_triangles)
        chosen, pair_valid, num_polygons = compact_indices(may_meet, capacity.polygons)
        chosen = jnp.maximum(chosen, 0)
        tet_index, tri_index = near_tets[i[chosen]], tris[j[chosen]]
        # Gathered again from the small near lists: taking the chosen columns of the
        # candidate tables instead ran 13 % slower on the CPU (benchmarks/RESULTS.md).
        pair_tets, pair_triangles = near_rows[i[chosen]].T, tri_rows[j[chosen]].T
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
    normals = pair_triangles[15:18]  # (3, P)
    corners = jnp.transpose(pair_triangles[:9].reshape(3, 3, num_polygons_slots), (1, 0, 2))  # (3 coordinates, 3 corners, P)
    face_normals, face_offsets, tie_drop = _resolve_face_ties(pair_tets, pair_triangles)
    vertices, counts = clip_polygon_by_tet_faces_columns(corners, jnp.full(tri_index.shape, 3), face_normals, face_offsets)
    pair_gradients = pair_tets[40:43]
    pressures = pair_tets[39][None] + jnp.sum(vertices * pair_gradients[:, None], axis=0)
    pressures = jnp.where(jnp.arange(vertices.shape[1])[:, None] < counts[None], pressures, 0.0)
    area, integral, first_moment, pressure_moment = calc_polygon_integrals_columns(vertices, counts, pressures, normals)
    vertices, pressures = to_polygon_rows(vertices, pressures, POLYGON_CAPACITY)
    polygon = (vertices, pressures, counts, area, integral, first_moment.T, pressure_moment.T)
    keep = jax.vmap(is_normal_along_gradient)(normals.T, pair_gradients.T) & ~tie_drop
    return assemble_surface(polygon, normals.T, pair_valid, keep, tet_index, tri_index, overflow, needed)
