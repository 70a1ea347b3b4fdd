"""Soft-rigid contact: the rigid surface inside the soft body, with the soft body's
pressure on it (Drake's soft-volume / rigid-surface intersection).

For each candidate pair of a soft tet and a rigid triangle, the triangle is clipped by
the tet's four faces; the piece (a convex polygon of at most 7 vertices) carries the
tet's linear pressure and the triangle's outward normal, which is the direction the
pressure pushes the soft body.
"""

import jax
import jax.numpy as jnp

from ..field import PressureField
from ._broadphase import Capacity, TetClusters, box_meets_region, boxes_overlap, calc_boxes, select, select_clustered_tets, select_pairs
from ._polygon import calc_polygon_integrals, clip_polygon_by_tet_faces
from ._pose import Pose
from ._rigid import RigidSurface
from ._surface import POLYGON_CAPACITY, ContactSurface, assemble_surface


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


def _polygon_from_pair(tet_vertices, triangle, normal, offset, gradient):
    vertices = jnp.zeros((POLYGON_CAPACITY, 3), triangle.dtype).at[:3].set(triangle)
    vertices, count = clip_polygon_by_tet_faces(vertices, jnp.asarray(3), tet_vertices)
    pressures = offset + vertices @ gradient
    area, integral, first_moment, pressure_moment = calc_polygon_integrals(vertices, count, pressures, normal)
    return vertices, pressures, count, area, integral, first_moment, pressure_moment


def calc_soft_rigid_surface(
    field: PressureField,
    rigid: RigidSurface,
    X_SR: Pose,
    capacity: Capacity = Capacity(),
    brute_force: bool = False,
    clusters: TetClusters | None = None,
) -> ContactSurface:
    """The contact surface of a soft body and a rigid surface at pose X_SR (pure,
    jittable, vmappable over X_SR, differentiable in X_SR, E and the field).

    Normals point out of the rigid body, the direction of the force on the soft body.
    `brute_force` clips every tet against every triangle (the reference for the broad
    phase; its buffers hold num_tets x num_faces polygons and never overflow).
    `clusters` (from :func:`make_tet_clusters`) makes the tet search hierarchical.
    """
    vertices_S = X_SR.apply(jnp.asarray(rigid.vertices_R, field.vertices.dtype))
    triangles = vertices_S[rigid.faces]
    triangle_normals = jnp.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    norms = jnp.sqrt(jnp.maximum(jnp.sum(triangle_normals**2, axis=-1, keepdims=True), 1e-300))
    triangle_normals = triangle_normals / norms
    tet_points = field.vertices[field.tets]

    tet_lo, tet_hi = calc_boxes(tet_points)
    tri_lo, tri_hi = calc_boxes(triangles)
    soft_lo, soft_hi = jnp.min(tet_lo, axis=0), jnp.max(tet_hi, axis=0)
    rigid_lo, rigid_hi = jnp.min(tri_lo, axis=0), jnp.max(tri_hi, axis=0)
    region_lo, region_hi = jnp.maximum(soft_lo, rigid_lo), jnp.minimum(soft_hi, rigid_hi)

    if brute_force:
        num_tets, num_tris = tet_points.shape[0], triangles.shape[0]
        tet_index = jnp.repeat(jnp.arange(num_tets), num_tris)
        tri_index = jnp.tile(jnp.arange(num_tris), num_tets)
        pair_valid = jnp.ones(tet_index.shape, dtype=bool)
        needed = jnp.array([num_tets, num_tris, tet_index.shape[0]])
        overflow = jnp.asarray(False)
    else:
        if clusters is None:
            tets, tets_valid, num_tets = select(boxes_overlap(tet_lo, tet_hi, region_lo[None], region_hi[None]), capacity.tets)
        else:
            meets = box_meets_region(region_lo, region_hi)
            tets, tets_valid, num_tets = select_clustered_tets(clusters, tet_lo, tet_hi, meets, capacity.tets)
        tris, tris_valid, num_tris = select(boxes_overlap(tri_lo, tri_hi, region_lo[None], region_hi[None]), capacity.others)
        safe_tets, safe_tris = jnp.maximum(tets, 0), jnp.maximum(tris, 0)
        # Separating plane: a tet wholly on one side of a triangle's plane cannot meet it.
        plane_offsets = jnp.sum(triangle_normals * triangles[:, 0], axis=-1)
        heights = jnp.einsum("tkd,rd->trk", tet_points[safe_tets], triangle_normals[safe_tris]) - plane_offsets[safe_tris][None, :, None]
        straddles = (jnp.min(heights, axis=-1) <= 0.0) & (jnp.max(heights, axis=-1) >= 0.0)
        i, j, pair_valid, num_pairs = select_pairs(
            tet_lo[safe_tets], tet_hi[safe_tets], tets_valid, tri_lo[safe_tris], tri_hi[safe_tris], tris_valid, capacity.pairs, straddles
        )
        tet_index, tri_index = safe_tets[i], safe_tris[j]
        needed = jnp.array([num_tets, num_tris, num_pairs])
        overflow = jnp.any(needed > jnp.array([tets.shape[0], capacity.others, capacity.pairs]))

    offsets, gradients = calc_tet_pressure_planes(field)
    normals = triangle_normals[tri_index]
    polygon = jax.vmap(_polygon_from_pair)(
        tet_points[tet_index], triangles[tri_index], normals, offsets[tet_index], gradients[tet_index]
    )
    keep = jax.vmap(is_normal_along_gradient)(normals, gradients[tet_index])
    return assemble_surface(polygon, normals, pair_valid, keep, tet_index, tri_index, overflow, needed)
