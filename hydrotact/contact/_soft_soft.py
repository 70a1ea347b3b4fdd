"""Soft-soft contact: in each pair of overlapping tets, the plane where the two
linear pressures are equal, clipped by both tets (at most 8 vertices).

Body A's field is given in frame S, body B's in its own frame B at pose X_SB. On the
equilibrium plane (g_A - g_B) . x + (c_A - c_B) = 0 the pressures agree; the force on
A pushes along (g_A - g_B) / |g_A - g_B| (into A, away from B).
"""

import jax
import jax.numpy as jnp

from .._buffers import compact_indices
from .._math import safe_div
from ..field import PressureField
from ._broadphase import Capacity, boxes_overlap, calc_boxes, select_pairs
from ._half_space import slice_tet
from ._polygon import calc_polygon_integrals, clip_polygon_by_tet_faces
from ._pose import Pose
from ._soft_rigid import calc_tet_pressure_planes, is_normal_along_gradient
from ._surface import ContactSurface, assemble_surface


def _pair_polygon(tet_a, tet_b, offset_a, gradient_a, offset_b, gradient_b):
    difference = gradient_a - gradient_b
    norm_squared = jnp.sum(difference * difference)
    degenerate = norm_squared <= 1e-24 * (jnp.sum(gradient_a**2) + jnp.sum(gradient_b**2)) + 1e-300
    safe_norm_squared = jnp.where(degenerate, 1.0, norm_squared)
    push = jnp.where(degenerate, jnp.array([0.0, 0.0, 1.0], difference.dtype), difference / jnp.sqrt(safe_norm_squared))
    point = -safe_div(offset_a - offset_b, safe_norm_squared) * difference
    vertices, count = slice_tet(tet_a, point, push)
    vertices, count = clip_polygon_by_tet_faces(vertices, count, tet_b)
    count = jnp.where(degenerate, 0, count)
    pressures = offset_a + vertices @ gradient_a
    keep = is_normal_along_gradient(push, gradient_a) & is_normal_along_gradient(-push, gradient_b)
    polygon = (vertices, pressures, count, *calc_polygon_integrals(vertices, count, pressures, push))
    return polygon, push, keep & ~degenerate


def calc_soft_soft_surface(
    field_A: PressureField, field_B: PressureField, X_SB: Pose, capacity: Capacity = Capacity(), brute_force: bool = False
) -> ContactSurface:
    """The contact surface of soft body A (frame S) and soft body B at pose X_SB
    (pure, jittable, vmappable over X_SB, differentiable). `brute_force` tries every
    pair of tets (the reference for the broad phase).

    Convention (Drake's soft-volume / soft-volume query): a polygon counts only where
    its push direction lies within 5 pi / 8 of both tets' pressure gradients
    (:func:`is_normal_along_gradient`, in opposite senses for the two bodies)."""
    points_A = field_A.vertices[field_A.tets]
    points_B = X_SB.apply(field_B.vertices.astype(field_A.vertices.dtype))[field_B.tets]
    offsets_A, gradients_A = calc_tet_pressure_planes(field_A)
    offsets_B_local, gradients_B_local = calc_tet_pressure_planes(field_B)
    # p_B(x_S) = c + g . (X_BS x_S) = (c - (R g) . p_SB) + (R g) . x_S.
    gradients_B = X_SB.rotate(gradients_B_local)
    offsets_B = offsets_B_local - gradients_B @ X_SB.translation

    lo_A, hi_A = calc_boxes(points_A)
    lo_B, hi_B = calc_boxes(points_B)
    region_lo = jnp.maximum(jnp.min(lo_A, axis=0), jnp.min(lo_B, axis=0))
    region_hi = jnp.minimum(jnp.max(hi_A, axis=0), jnp.max(hi_B, axis=0))
    if brute_force:
        a = jnp.repeat(jnp.arange(points_A.shape[0]), points_B.shape[0])
        b = jnp.tile(jnp.arange(points_B.shape[0]), points_A.shape[0])
        pair_valid = jnp.ones(a.shape, dtype=bool)
        overflow, needed = jnp.asarray(False), jnp.array([points_A.shape[0], points_B.shape[0], 0, a.shape[0]])
    else:
        tets_A, valid_A, num_A = compact_indices(boxes_overlap(lo_A, hi_A, region_lo[None], region_hi[None]), capacity.tets)
        tets_B, valid_B, num_B = compact_indices(boxes_overlap(lo_B, hi_B, region_lo[None], region_hi[None]), capacity.others)
        safe_A, safe_B = jnp.maximum(tets_A, 0), jnp.maximum(tets_B, 0)
        # Every overlapping pair is a polygon slot: the pairs go straight to that buffer.
        i, j, pair_valid, num_pairs = select_pairs(lo_A[safe_A], hi_A[safe_A], valid_A, lo_B[safe_B], hi_B[safe_B], valid_B, capacity.polygons)
        a, b = safe_A[i], safe_B[j]
        needed = jnp.array([num_A, num_B, 0, num_pairs])
        overflow = jnp.any(needed > jnp.array([capacity.tets, capacity.others, capacity.pairs, capacity.polygons]))
    polygons, normals, keep = jax.vmap(_pair_polygon)(
        points_A[a], points_B[b], offsets_A[a], gradients_A[a], offsets_B[b], gradients_B[b]
    )
    return assemble_surface(polygons, normals, pair_valid, keep, a, b, overflow, needed)
