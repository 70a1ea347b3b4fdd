"""What each taxel reads: its rays' footprints cast at the contact surface, aggregated.

Each ray stands for a small square footprint of its receptive field (its share of
the field's area, or of its solid angle; :func:`calc_taxel_footprints`) and reads the
mean pressure over that square of the nearest sheet of the contact surface, the
uncovered part reading 0: the exact integral of each triangle's linear pressure over
the part of the square inside the triangle (:mod:`._footprint`). A point sample would
jump as a polygon's rim with p > 0 (a flat probe's edge, where the visible sheet
ends) crosses the ray; the footprint's covered area, and so the reading, moves
continuously with the surface, and pieces of adjacent triangles tile the square, so
interior edges and tiny or degenerate triangles count exactly. As N grows the
footprints shrink to points and the reading converges to the point-sampled weighted
mean. The taxel reads p = sum_i w_i p_i / sum_i w_i over all its rays, with the
receptive field's weights w_i = (r - d_i)^2.

Occlusion is decided per (ray, triangle) piece, not per point: a piece counts if the
distance along the ray at its centroid is within SHEET_SLOPE footprint diagonals of
the nearest piece's (the pieces of one sheet lie within its slope times the
footprint's size of each other; distinct sheets are further apart). This is the
approximate part: a second sheet closer than that band is added rather than hidden
(e.g. a tilted flat probe's side wall, over a sliver of area proportional to the
tilt), and where two sheets overlap within one footprint the nearer one hides all
of the other's pieces whose centroids lie behind the band.

Two paths compute the same thing:

- **culled** (default): each fan triangle's bounding sphere is tested against each
  taxel's receptive volume (a half-cylinder for a disk, a cone for a cone, widened by
  the footprints' reach); only the (taxel, triangle) pairs that pass, compacted into
  a fixed-capacity buffer with an overflow flag, are projected into the taxel's ray
  plane; of their (pair, ray) combinations only those whose footprint meets the
  projected triangle's bounding box (a cheap test; a few rays per pair), compacted
  into a second buffer, are clipped, and the nearest sheet of each ray is found by a
  segment minimum over its pieces. Cost ~ pairs x rays for the box test, pieces for
  the clip.
- **brute force**: every ray of every taxel against every triangle (the reference).
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._buffers import AbstractCapacity, compact_indices, run_growing
from .._math import safe_div, safe_norm, safe_sqrt
from .._types import Array, Bool, Float, Int
from ._footprint import calc_footprint_hits, calc_pair_geometry
from ._patterns import TaxelLayout, calc_footprint_scale, calc_perpendicular_frame, calc_taxel_footprints
from ._raycast import calc_surface_triangles

# Relative slack on the nearest distance (round-off between the pieces of one sheet).
TIE_TOLERANCE = 1e-9
# Pieces of the same sheet seen by one footprint lie within this many footprint
# diagonals of each other along the ray (a sheet up to ~63 degrees from facing it).
SHEET_SLOPE = 2.0
# A piece covering less than this fraction of its footprint cannot set the nearest
# distance (its centroid, and so its distance, is round-off); it still counts if it
# lies on the nearest sheet.
AREA_FLOOR = 1e-12


class TaxelCapacity(AbstractCapacity):
    """Buffer sizes of the culled taxel sampler (static: changing one recompiles), in
    the order of :attr:`TaxelReadings.needed`.

    - `pairs`: candidate (taxel, surface triangle) pairs, those whose triangle's
      bounding sphere meets the taxel's receptive volume.
    - `pieces`: (pair, ray) combinations whose footprint meets the pair's projected
      triangle's bounding box; each is clipped (a few per pair: the triangles are
      about a footprint's size).

    Grown by the one rule of :meth:`hydrotact._buffers.AbstractCapacity.grown_to`.
    """

    purpose: ClassVar[str] = "taxel sampling"
    advice: ClassVar[str] = "the contact surface has too many triangles near the taxels"

    pairs: int = eqx.field(static=True, default=4096)
    pieces: int = eqx.field(static=True, default=8192)


class TaxelReadings(eqx.Module):
    """Taxel values for one contact surface.

    **Fields:**

    - `pressures`: (num_taxels,) the weighted mean pressure over each receptive field,
      Pa (in the units of the surface's pressure).
    - `coverage`: (num_taxels,) the weight fraction of rays that hit, in [0, 1].
    - `did_overflow`: True when the culled path had more candidate pairs or pieces
      than their buffers (the readings are then incomplete).
    - `needed`: (2,) the entries each buffer of :class:`TaxelCapacity` needed (the
      candidate pairs, the pieces).
    """

    pressures: Float[Array, " num_taxels"]
    coverage: Float[Array, " num_taxels"]
    did_overflow: Bool[Array, ""]
    needed: Int[Array, " 2"]


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


def _see(pair_args, centres_x, centres_y, halves, is_cone):
    """Footprints against triangles (:func:`calc_footprint_hits`; pair arguments of
    :func:`calc_pair_geometry`, broadcast against the rays' centres and half sides,
    each coordinate its own array):
    (touched, the pressure integral, the distance, the distance where the piece is large
    enough to set the nearest sheet (+inf elsewhere), the covered area)."""
    pair = calc_pair_geometry(*pair_args)
    area, pressure_integral, depth = calc_footprint_hits(pair, centres_x, centres_y, halves, is_cone)
    depth = jax.lax.stop_gradient(depth)
    covered = jax.lax.stop_gradient(area > AREA_FLOOR)
    return area > 0.0, pressure_integral, depth, jnp.where(covered, depth, jnp.inf), area


def _sheet_limit(nearest_depth, halves, is_cone):
    """The farthest distance of a piece on the sheet nearest the ray: within
    SHEET_SLOPE footprint diagonals (scaled to the distance on a cone) of the nearest
    piece's centroid, plus the relative TIE_TOLERANCE."""
    scale = jnp.where(is_cone, nearest_depth, 1.0)
    band = SHEET_SLOPE * 2.0 * jnp.sqrt(2.0) * halves * scale + TIE_TOLERANCE * nearest_depth
    return jax.lax.stop_gradient(nearest_depth + band)


def _aggregate(ray_pressure_integrals, ray_areas, weights):
    """Taxel value and coverage from per-ray integrals over the visible parts of the
    footprints, per unit of the footprint's area (a footprint's uncovered part reads 0)."""
    total = jnp.sum(weights, axis=-1)
    pressures = jnp.sum(weights * ray_pressure_integrals, axis=-1)
    coverage = jnp.sum(weights * ray_areas, axis=-1)
    return safe_div(pressures, total), safe_div(coverage, total)


def calc_taxel_pressures(
    layout: TaxelLayout, surface, num_rays: int = 64, capacity: TaxelCapacity = TaxelCapacity(), brute_force: bool = False
) -> TaxelReadings:
    """Taxel readings of a contact surface (pure; jittable, vmappable, and
    differentiable in the surface's vertices and pressures and in the layout).

    **Arguments:**

    - `layout`: the taxels (positions, axes, receptive fields), frame S.
    - `surface`: a :class:`hydrotact.contact.ContactSurface` in frame S.
    - `num_rays`: rays per receptive field (static).
    - `capacity`: the culled path's buffers of candidate (taxel, triangle) pairs and
      of (pair, ray) pieces (static); check `.did_overflow` or use :func:`sample_taxels`, which grows it.
    - `brute_force`: every ray against every triangle (the reference; never overflows).
    """
    corners, corner_pressures, valid = calc_surface_triangles(surface)
    centres, halves, weights = jax.vmap(calc_taxel_footprints, in_axes=(0, 0, None))(layout.field_sizes, layout.is_cone, num_rays)
    axes = layout.axes_S / safe_norm(layout.axes_S, axis=1, keepdims=True)
    us, vs = jax.vmap(calc_perpendicular_frame)(axes)
    # (positions, u, v, axes) per taxel, coordinates first: (4, 3, num_taxels)
    frames = jnp.stack([layout.positions_S.T, us.T, vs.T, axes.T])
    if brute_force:

        def one_taxel(args):
            frame, is_cone, taxel_centres, taxel_halves = args
            pair_args = (*frame[..., None, None], jnp.transpose(corners, (1, 2, 0))[..., None, :], corner_pressures.T[:, None], is_cone, valid[None])
            touched, integral, depth, sized_depth, area = _see(pair_args, *taxel_centres[..., None], taxel_halves[:, None], is_cone)  # (num_rays, M)
            nearest = touched & (depth <= _sheet_limit(jnp.min(sized_depth, axis=1, keepdims=True), taxel_halves[:, None], is_cone))
            return jnp.sum(jnp.where(nearest, integral, 0.0), axis=1), jnp.sum(jnp.where(nearest, area, 0.0), axis=1)

        integrals, areas = jax.lax.map(one_taxel, (jnp.moveaxis(frames, 2, 0), layout.is_cone, jnp.moveaxis(centres, 2, 1), halves))
        pressures, coverage = _aggregate(integrals, areas, weights)
        return TaxelReadings(pressures, coverage, jnp.asarray(False), jnp.asarray([valid.shape[0] * layout.num_taxels, valid.shape[0] * layout.num_taxels * num_rays]))

    num_taxels = layout.num_taxels
    triangle_centres = jnp.mean(corners, axis=1)
    radii = jnp.max(safe_norm(corners - triangle_centres[:, None], axis=-1), axis=1)
    # The footprints reach past the field by half a footprint's diagonal.
    reach = calc_footprint_scale(layout.field_sizes, layout.is_cone, num_rays) / jnp.sqrt(2.0)
    cone_sizes = jnp.arctan(jnp.tan(jnp.where(layout.is_cone, layout.field_sizes, 0.0)) + reach)
    sizes = jnp.where(layout.is_cone, cone_sizes, layout.field_sizes + reach)
    meets = _meets_receptive_field(layout.positions_S.T, axes.T, sizes, layout.is_cone, triangle_centres.T, radii)
    meets = jax.lax.stop_gradient(meets & valid[None, :])
    flat, pair_valid, needed = compact_indices(meets, capacity.pairs)
    safe = jnp.maximum(flat, 0)
    taxel_of_pair = safe // corners.shape[0]
    triangle_of_pair = safe % corners.shape[0]

    # Each pair's triangle in its taxel's ray plane, once per pair ((capacity,) arrays).
    pair_frames = frames[:, :, taxel_of_pair]  # (4, 3, capacity)
    triangles = jnp.transpose(corners[triangle_of_pair], (1, 2, 0))  # (3 corners, 3, capacity)
    pair = calc_pair_geometry(*pair_frames, triangles, corner_pressures[triangle_of_pair].T, layout.is_cone[taxel_of_pair], pair_valid)
    # Pieces: the (pair, ray) combinations whose footprint meets the projected
    # triangle's bounding box, compacted in turn (in the order of the pairs, then of
    # the rays); elsewhere the footprint's piece is empty. Only they are clipped.
    centres_x, centres_y = centres[..., 0][taxel_of_pair], centres[..., 1][taxel_of_pair]  # (capacity, num_rays)
    pair_halves = halves[taxel_of_pair]

    def overlaps(coordinates, ray_centres):
        lowest = jnp.minimum(jnp.minimum(coordinates[0], coordinates[1]), coordinates[2])[:, None]
        highest = jnp.maximum(jnp.maximum(coordinates[0], coordinates[1]), coordinates[2])[:, None]
        return (lowest <= ray_centres + pair_halves) & (highest >= ray_centres - pair_halves)

    touches = pair.valid[:, None] & overlaps(pair.corners_x, centres_x) & overlaps(pair.corners_y, centres_y)
    flat_piece, piece_valid, pieces_needed = compact_indices(jax.lax.stop_gradient(touches), capacity.pieces)
    safe_piece = jnp.maximum(flat_piece, 0)
    pair_of_piece, ray_of_piece = safe_piece // num_rays, safe_piece % num_rays
    taxel_of_piece = taxel_of_pair[pair_of_piece]
    piece_pair = jax.tree_util.tree_map(lambda a: a[pair_of_piece], pair)
    piece_pair = piece_pair._replace(valid=piece_pair.valid & piece_valid)
    is_cone = layout.is_cone[taxel_of_piece]
    at = (pair_of_piece, ray_of_piece)
    area, integral, depth = calc_footprint_hits(piece_pair, centres_x[at], centres_y[at], pair_halves[at], is_cone)
    depth = jax.lax.stop_gradient(depth)
    covered = jax.lax.stop_gradient(area > AREA_FLOOR)
    # Segments: (taxel, ray), flattened; pieces come sorted by pair, not by segment.
    ray_of_segment = taxel_of_piece * num_rays + ray_of_piece
    segments = {"segment_ids": ray_of_segment, "num_segments": num_taxels * num_rays}
    nearest_depth = jax.ops.segment_min(jnp.where(covered, depth, jnp.inf), **segments).reshape(num_taxels, num_rays)
    limit = _sheet_limit(nearest_depth, halves, layout.is_cone[:, None]).reshape(-1)
    nearest = (area > 0.0) & (depth <= limit[ray_of_segment])
    integrals = jax.ops.segment_sum(jnp.where(nearest, integral, 0.0), **segments).reshape(num_taxels, num_rays)
    areas = jax.ops.segment_sum(jnp.where(nearest, area, 0.0), **segments).reshape(num_taxels, num_rays)
    pressures, coverage = _aggregate(integrals, areas, weights)
    did_overflow = (needed > capacity.pairs) | (pieces_needed > capacity.pieces)
    return TaxelReadings(pressures, coverage, did_overflow, jnp.stack([needed, pieces_needed]))


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
