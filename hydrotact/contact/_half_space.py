"""Soft body against a rigid half-space: slice the tets by the plane (fast path).

The rigid half-space fills z >= 0 of its frame R. In frame S its face is the plane
through p_SR with inward normal m = R_SR z; the contact surface is that plane's
section through the soft body, one convex polygon (3 or 4 vertices) per cut tet,
pushed along -m.
"""

import jax
import jax.numpy as jnp

from ..field import PressureField
from ._broadphase import Capacity, select
from ._polygon import calc_polygon_integrals, clip_polygon_by_tet_faces
from ._pose import Pose
from ._soft_rigid import calc_tet_pressure_planes, is_normal_along_gradient
from ._surface import POLYGON_CAPACITY, ContactSurface


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
    """The section of a tet by the plane (point, normal): (polygon buffer, count),
    wound counter-clockwise about `normal`."""
    centre = jnp.mean(tet_vertices, axis=0)
    half_size = 2.0 * jnp.max(jnp.sqrt(jnp.sum((tet_vertices - centre[None]) ** 2, axis=-1))) + 1e-300
    square = plane_square(point, normal, centre, half_size)
    return clip_polygon_by_tet_faces(square, jnp.asarray(4), tet_vertices)


def calc_half_space_surface(field: PressureField, X_SR: Pose, capacity: Capacity = Capacity(), brute_force: bool = False) -> ContactSurface:
    """The contact surface of a soft body and the rigid half-space z >= 0 of frame R
    (pure, jittable, vmappable over X_SR, differentiable). `brute_force` slices every
    tet (the reference for the culling)."""
    inward = X_SR.rotate(jnp.array([0.0, 0.0, 1.0], field.vertices.dtype))
    point = X_SR.translation.astype(field.vertices.dtype)
    push = -inward  # the force on the soft body points out of the rigid body
    tet_points = field.vertices[field.tets]
    heights = jnp.einsum("tkd,d->tk", tet_points, inward) - jnp.dot(point, inward)
    cut = (jnp.min(heights, axis=1) <= 0.0) & (jnp.max(heights, axis=1) >= 0.0)
    size = tet_points.shape[0] if brute_force else capacity.pairs
    tets, tets_valid, num_tets = select(jnp.ones_like(cut) if brute_force else cut, size)
    tet_index = jnp.maximum(tets, 0)
    offsets, gradients = calc_tet_pressure_planes(field)

    def polygon(tet_vertices, offset, gradient):
        vertices, count = slice_tet(tet_vertices, point, push)
        pressures = offset + vertices @ gradient
        return (vertices, pressures, count, *calc_polygon_integrals(vertices, count, pressures, push))

    vertices, pressures, counts, areas, integrals, first_moments, pressure_moments = jax.vmap(polygon)(
        tet_points[tet_index], offsets[tet_index], gradients[tet_index]
    )
    normals = jnp.broadcast_to(push[None], (size, 3))
    keep = jax.vmap(is_normal_along_gradient, in_axes=(None, 0))(push, gradients[tet_index])
    valid = tets_valid & (counts >= 3) & (areas > 0.0) & keep
    return ContactSurface(
        vertices_S=vertices,
        pressures=pressures,
        counts=counts,
        normals_S=normals,
        valid=valid,
        areas=areas,
        pressure_integrals=integrals,
        first_moments_S=first_moments,
        pressure_moments_S=pressure_moments,
        tet_index=jnp.where(tets_valid, tet_index, -1),
        other_index=jnp.full(size, -1),
        overflow=num_tets > size,
        num_candidates=num_tets,
    )
