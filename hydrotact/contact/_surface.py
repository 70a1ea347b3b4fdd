"""The contact surface pytree and the wrench it exerts."""

import equinox as eqx
import jax.numpy as jnp

from .._math import safe_div
from .._types import Array, Bool, Float, Int

POLYGON_CAPACITY = 8  # a triangle clipped by a tet has <= 7 vertices; two tets' plane <= 8


class ContactSurface(eqx.Module):
    """Contact polygons in fixed-capacity buffers, with a validity mask.

    Each slot holds one convex polygon (one tet against one rigid triangle, one tet
    slice, or one pair of tets), its pressure at the vertices (linear across it), and
    the unit normal `normals_S` along which the pressure pushes the soft body
    (for soft-soft: body A). Units: m, Pa, N.

    `did_overflow` is True when more candidates existed than the buffers hold: the
    surface is then incomplete, and the host entry points retry with larger buffers
    or raise (see :func:`hydrotact._buffers.run_growing`); `needed` says how many
    entries each buffer (tets, others, pairs, polygons: :attr:`Capacity.sizes`)
    would have needed.

    **Fields:**

    - `vertices_S`: (capacity, 8, 3) polygon vertices, frame S.
    - `pressures`: (capacity, 8) pressure at those vertices, Pa.
    - `counts`: (capacity,) number of vertices of each polygon.
    - `normals_S`: (capacity, 3).
    - `valid`: (capacity,) the slot holds a polygon of positive area.
    - `areas`: (capacity,) m^2; `pressure_integrals`: (capacity,) int p dA, N.
    - `first_moments_S`: (capacity, 3) int x dA; `pressure_moments_S`: (capacity, 3) int p x dA.
    - `tet_index`, `other_index`: (capacity,) the soft tet, and the rigid triangle or
      the other body's tet (-1 for a half-space).
    - `did_overflow`: scalar; `needed`: (4,) entries needed by the tets, others, pairs and
      polygons buffers (see :class:`Capacity`).
    """

    vertices_S: Float[Array, "capacity 8 3"]
    pressures: Float[Array, "capacity 8"]
    counts: Int[Array, " capacity"]
    normals_S: Float[Array, "capacity 3"]
    valid: Bool[Array, " capacity"]
    areas: Float[Array, " capacity"]
    pressure_integrals: Float[Array, " capacity"]
    first_moments_S: Float[Array, "capacity 3"]
    pressure_moments_S: Float[Array, "capacity 3"]
    tet_index: Int[Array, " capacity"]
    other_index: Int[Array, " capacity"]
    did_overflow: Bool[Array, ""]
    needed: Int[Array, " 4"]

    @property
    def capacity(self) -> int:
        return self.counts.shape[-1]

    @property
    def num_polygons(self):
        return jnp.sum(self.valid, axis=-1)

    @property
    def total_area(self):
        """Contact area in m^2."""
        return jnp.sum(jnp.where(self.valid, self.areas, 0.0), axis=-1)

    @property
    def centroid_S(self):
        """Area-weighted centroid of the contact surface (0 when there is no contact)."""
        moments = jnp.sum(jnp.where(self.valid[..., None], self.first_moments_S, 0.0), axis=-2)
        return safe_div(moments, self.total_area[..., None])

    def calc_force(self):
        """Total force on the soft body (body A), N, frame S."""
        weights = jnp.where(self.valid, self.pressure_integrals, 0.0)
        return jnp.sum(weights[..., None] * self.normals_S, axis=-2)

    def calc_wrench(self, p_SC=(0.0, 0.0, 0.0)):
        """(force, torque about point C) on the soft body, frame S; torque in N m."""
        p_SC = jnp.asarray(p_SC, dtype=self.areas.dtype)
        weights = jnp.where(self.valid, self.pressure_integrals, 0.0)
        moments = jnp.where(self.valid[..., None], self.pressure_moments_S, 0.0) - weights[..., None] * jnp.reshape(p_SC, (1,) * (weights.ndim) + (3,))
        torque = jnp.sum(jnp.cross(moments, self.normals_S), axis=-2)
        return self.calc_force(), torque

    @property
    def pressure_centroid_S(self):
        """Centre of pressure: int p x dA / int p dA (0 without contact)."""
        weights = jnp.where(self.valid, self.pressure_integrals, 0.0)
        moments = jnp.sum(jnp.where(self.valid[..., None], self.pressure_moments_S, 0.0), axis=-2)
        return safe_div(moments, jnp.sum(weights, axis=-1)[..., None])


def assemble_surface(polygons, normals_S, pair_valid, keep, tet_index, other_index, did_overflow, needed) -> ContactSurface:
    """Fill a ContactSurface from the per-slot polygons of a kernel.

    `polygons` is (vertices, pressures, counts, areas, pressure integrals, first
    moments, pressure moments), as `calc_polygon_integrals` and the clippers give them.
    A slot is valid when its pair is real, it passes `keep` (the gradient filter) and
    its polygon has at least three vertices and no negative area. Zero-area polygons
    count: at a tie (a plane through a vertex, an edge or a face of a tet) they are
    the sections that open up as the pose moves, and their derivatives belong to the
    surface's. Indices of unused slots read -1.
    """
    vertices, pressures, counts, areas, integrals, first_moments, pressure_moments = polygons
    return ContactSurface(
        vertices_S=vertices,
        pressures=pressures,
        counts=counts,
        normals_S=normals_S,
        valid=pair_valid & keep & (counts >= 3) & (areas >= 0.0),
        areas=areas,
        pressure_integrals=integrals,
        first_moments_S=first_moments,
        pressure_moments_S=pressure_moments,
        tet_index=jnp.where(pair_valid, tet_index, -1),
        other_index=jnp.where(pair_valid, other_index, -1),
        did_overflow=did_overflow,
        needed=needed,
    )
