"""What each taxel reads: its rays cast at the contact surface, aggregated.

Each ray takes the pressure at its first hit on the contact surface (barycentric
interpolation of the polygon's linear pressure; several triangles hit at the same
distance, as through a shared edge, are averaged); a ray that misses reads 0. The
taxel reads p = sum_i w_i p_i / sum_i w_i over all its rays (misses included), with
the receptive field's weights w_i = (r - d_i)^2.

Two paths compute the same thing:

- **culled** (default): each fan triangle's bounding sphere is tested against each
  taxel's receptive volume (a half-cylinder for a disk, a cone for a cone); only the
  (taxel, triangle) pairs that pass, compacted into a fixed-capacity buffer with an
  overflow flag, are ray-cast, and the nearest hit of each ray is found by a segment
  minimum over its taxel's pairs. Cost ~ pairs x rays.
- **brute force**: every ray of every taxel against every triangle (the reference).
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._buffers import AbstractCapacity, compact_indices, run_growing
from .._math import safe_div, safe_norm, safe_sqrt
from .._types import Array, Bool, Float, Int
from ._patterns import TaxelLayout, calc_taxel_rays
from ._raycast import calc_surface_triangles, intersect_ray_triangle

# A ray's hits within this relative distance of its nearest one count as the nearest
# too, and are averaged: a ray along an edge shared by two triangles (see
# intersect_ray_triangle) hits both at the same t up to round-off, which exact
# equality would split by the last bit, one-sidedly and differently from one
# compilation to the next; the average gives the edge's pressure and the symmetric
# derivative. (Distinct sheets of a contact surface are far further apart.)
TIE_TOLERANCE = 1e-9


class TaxelCapacity(AbstractCapacity):
    """Buffer sizes of the culled taxel sampler (static: changing one recompiles), in
    the order of :attr:`TaxelReadings.needed`.

    - `pairs`: candidate (taxel, surface triangle) pairs, those whose triangle's
      bounding sphere meets the taxel's receptive volume; each is ray-cast.

    Grown by the one rule of :meth:`hydrotact._buffers.AbstractCapacity.grown_to`.
    """

    purpose: ClassVar[str] = "taxel sampling"
    advice: ClassVar[str] = "the contact surface has too many triangles near the taxels"

    pairs: int = eqx.field(static=True, default=4096)


class TaxelReadings(eqx.Module):
    """Taxel values for one contact surface.

    **Fields:**

    - `pressures`: (num_taxels,) the weighted mean pressure over each receptive field,
      Pa (in the units of the surface's pressure).
    - `coverage`: (num_taxels,) the weight fraction of rays that hit, in [0, 1].
    - `did_overflow`: True when the culled path had more candidate pairs than its
      buffer (the readings are then incomplete).
    - `needed`: (1,) the entries each buffer of :class:`TaxelCapacity` needed (the
      candidate pairs).
    """

    pressures: Float[Array, " num_taxels"]
    coverage: Float[Array, " num_taxels"]
    did_overflow: Bool[Array, ""]
    needed: Int[Array, " 1"]


def _meets_receptive_field(position, axis, size, is_cone, centres, radii):
    """Whether spheres can meet taxels' rays: a conservative test against the
    half-cylinder (disk) or the cone (cone).

    Taxels' `position`, `axis` (3, T), `size`, `is_cone` (T,) against spheres'
    `centres` (3, M), `radii` (M,): a (T, M) mask, written per coordinate as
    elementwise (T, 1) against (1, M) rows. (Reductions over a 3-long coordinate axis
    run as separate, much slower operations on the CPU: the pad's 25 x 6,912 test
    took 7 ms a frame that way, 0.2 ms this way.)

    With a sphere centre at height h along the axis and radial distance q from it,
    its distance from a cone of half-angle a is q cos a - h sin a while it lies
    beside the cone's surface (h cos a + q sin a >= 0), and its distance from the
    apex otherwise; inside the cone that expression is negative. No trigonometry per
    sphere."""
    axis = axis / safe_norm(axis, axis=0)[None]
    offsets = [centres[k][None, :] - position[k][:, None] for k in range(3)]
    along = offsets[0] * axis[0][:, None] + offsets[1] * axis[1][:, None] + offsets[2] * axis[2][:, None]
    across = [offsets[k] - along * axis[k][:, None] for k in range(3)]
    radial = safe_sqrt(across[0] * across[0] + across[1] * across[1] + across[2] * across[2])
    size, radii = size[:, None], radii[None, :]
    slack = 1e-9 * (size + radii) + 1e-12
    disk = (radial <= size + radii + slack) & (along >= -radii - slack)
    cos_a, sin_a = jnp.cos(size), jnp.sin(size)
    beside = along * cos_a + radial * sin_a >= 0.0
    apex = safe_sqrt(offsets[0] * offsets[0] + offsets[1] * offsets[1] + offsets[2] * offsets[2])
    distance = jnp.where(beside, radial * cos_a - along * sin_a, apex)
    cone = distance <= radii + slack
    return jnp.where(is_cone[:, None], cone, disk)


def _cast(origin, direction, triangle, pressures, is_valid):
    """Rays against triangles (one against one, or columns that broadcast, as
    :func:`intersect_ray_triangle` takes them; `triangle` (3 corners, 3, ...),
    `pressures` (3 corners, ...)): (hit, distance t (+inf on a miss), pressure
    interpolated at the hit (0 on a miss))."""
    hit, t, u, v = intersect_ray_triangle(origin, direction, triangle[0], triangle[1], triangle[2])
    hit = hit & is_valid
    pressure = (1.0 - u - v) * pressures[0] + u * pressures[1] + v * pressures[2]
    return hit, jnp.where(hit, t, jnp.inf), jnp.where(hit, pressure, 0.0)


def _is_nearest(t, nearest_t):
    """Whether hits at distances t count as the nearest (nearest_t broadcast against t)."""
    return jax.lax.stop_gradient(t <= nearest_t * (1.0 + TIE_TOLERANCE))


def _aggregate(ray_pressure_sums, ray_hit_counts, weights):
    """Taxel value and coverage from per-ray sums of nearest-hit pressures and counts."""
    ray_pressures = safe_div(ray_pressure_sums, ray_hit_counts)
    total = jnp.sum(weights, axis=-1)
    hit_weight = jnp.sum(jnp.where(ray_hit_counts > 0, weights, 0.0), axis=-1)
    return safe_div(jnp.sum(weights * ray_pressures, axis=-1), total), safe_div(hit_weight, total)


def calc_taxel_pressures(
    layout: TaxelLayout, surface, num_rays: int = 64, capacity: TaxelCapacity = TaxelCapacity(), brute_force: bool = False
) -> TaxelReadings:
    """Taxel readings of a contact surface (pure; jittable, vmappable, and
    differentiable in the surface's vertices and pressures and in the layout).

    **Arguments:**

    - `layout`: the taxels (positions, axes, receptive fields), frame S.
    - `surface`: a :class:`hydrotact.contact.ContactSurface` in frame S.
    - `num_rays`: rays per receptive field (static).
    - `capacity`: the culled path's buffer of candidate (taxel, triangle) pairs
      (static); check `.did_overflow` or use :func:`sample_taxels`, which grows it.
    - `brute_force`: every ray against every triangle (the reference; never overflows).
    """
    corners, corner_pressures, valid = calc_surface_triangles(surface)
    origins, directions, weights = jax.vmap(calc_taxel_rays, in_axes=(0, 0, 0, 0, None))(
        layout.positions_S, layout.axes_S, layout.field_sizes, layout.is_cone, num_rays
    )
    if brute_force:

        def one_taxel(args):
            rays_vs_triangles = jax.vmap(jax.vmap(_cast, in_axes=(None, None, 0, 0, 0)), in_axes=(0, 0, None, None, None))
            hit, t, pressure = rays_vs_triangles(*args, corners, corner_pressures, valid)  # (num_rays, M)
            nearest = hit & _is_nearest(t, jnp.min(t, axis=1, keepdims=True))
            return jnp.sum(jnp.where(nearest, pressure, 0.0), axis=1), jnp.sum(nearest, axis=1)

        sums, counts = jax.lax.map(one_taxel, (origins, directions))
        pressures, coverage = _aggregate(sums, counts, weights)
        return TaxelReadings(pressures, coverage, jnp.asarray(False), jnp.asarray([valid.shape[0] * layout.num_taxels]))

    num_taxels = layout.num_taxels
    centres = jnp.mean(corners, axis=1)
    radii = jnp.max(safe_norm(corners - centres[:, None], axis=-1), axis=1)
    meets = _meets_receptive_field(layout.positions_S.T, layout.axes_S.T, layout.field_sizes, layout.is_cone, centres.T, radii)
    meets = jax.lax.stop_gradient(meets & valid[None, :])
    flat, pair_valid, needed = compact_indices(meets, capacity.pairs)
    safe = jnp.maximum(flat, 0)
    # Compaction keeps row-major order, so pairs come sorted by taxel; padding goes to
    # the last taxel (with no hits) to keep them sorted for the segment reductions.
    taxel_of_pair = jnp.where(pair_valid, safe // corners.shape[0], num_taxels - 1)
    triangle_of_pair = safe % corners.shape[0]

    # Pairs x rays, each coordinate a (capacity, num_rays) row: the test is elementwise.
    ray_origins = jnp.transpose(origins, (2, 0, 1))[:, taxel_of_pair]  # (3, capacity, num_rays)
    ray_directions = jnp.transpose(directions, (2, 0, 1))[:, taxel_of_pair]
    triangles = jnp.transpose(corners[triangle_of_pair], (1, 2, 0))[..., None]  # (3 corners, 3, capacity, 1)
    hit, t, pressure = _cast(ray_origins, ray_directions, triangles, corner_pressures[triangle_of_pair].T[..., None], pair_valid[:, None])
    segments = {"segment_ids": taxel_of_pair, "num_segments": num_taxels, "indices_are_sorted": True}
    nearest_t = jax.ops.segment_min(jax.lax.stop_gradient(t), **segments)
    nearest = hit & _is_nearest(t, nearest_t[taxel_of_pair])
    sums = jax.ops.segment_sum(jnp.where(nearest, pressure, 0.0), **segments)
    counts = jax.ops.segment_sum(nearest.astype(jnp.int32), **segments)
    pressures, coverage = _aggregate(sums, counts, weights)
    return TaxelReadings(pressures, coverage, needed > capacity.pairs, needed[None])


_readings = eqx.filter_jit(calc_taxel_pressures)
_batched_readings = eqx.filter_jit(eqx.filter_vmap(calc_taxel_pressures, in_axes=(None, 0, None, None)))


def sample_taxels(
    layout: TaxelLayout, surface, num_rays: int = 64, capacity: TaxelCapacity | None = None
) -> tuple[TaxelReadings, TaxelCapacity]:
    """Taxel readings of one surface or a batch (a surface with a leading axis),
    growing the pair buffer until nothing overflows (host;
    :func:`hydrotact._buffers.run_growing`).

    **Returns:** (readings, the capacity that sufficed).
    """
    run = _batched_readings if surface.counts.ndim == 2 else _readings
    return run_growing(lambda size: run(layout, surface, num_rays, size), capacity or TaxelCapacity())
