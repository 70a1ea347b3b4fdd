"""What one ray's footprint sees of one triangle, exactly: the area and first moments
of the part of its square inside the triangle, and from them the integral of the
triangle's pressure over that part.

Every ray of a taxel is a point (X, Y) of the taxel's ray plane (see
:func:`hydrotact.taxel.calc_taxel_footprints`: the disk's plane for parallel rays,
the gnomonic plane at unit distance along the axis for a cone). In those coordinates
the Moller-Trumbore barycentric coordinates of the point where the ray meets a
triangle's plane are affine (disk) or homogeneous-affine (cone): with the corners
w_j = (x_j, y_j, z_j) in the taxel frame (u, v, axis) and m_j = (x_j, y_j, 1) on a
disk, m_j = w_j on a cone, the ray (X, Y) meets the triangle's plane at
sum_j E_j w_j / sum_j E_j, where E = M^-1 (X, Y, 1) and M = [m_0 m_1 m_2] (on a disk
sum_j E_j = 1 and E are the barycentric coordinates u, v of intersect_ray_triangle;
on a cone they are those coordinates divided by the hit's distance along the axis).
The ray hits the triangle iff every E_j >= 0: the Moller-Trumbore test, written once
per (taxel, triangle) pair as three half-planes of the ray plane. The triangle is the
projected triangle bounded by them, its pressure is p = N / D with N = sum_j E_j p_j
and D = sum_j E_j both affine, and its distance along the ray is z = sum_j E_j z_j
(disk, affine) or |(X, Y, 1)| / D (cone).

The part of a footprint square inside that triangle is a convex polygon; its area A
and first moments (int X, int Y) are boundary integrals (Green's theorem,
int int f = contour int F dY with dF/dX = f): the triangle's edges clipped to the
square (Liang-Barsky) plus the square's two vertical sides clipped to the triangle,
each a segment on which F is a polynomial integrated exactly. Divisions happen once
per pair; per (pair, ray) it is products and comparisons, elementwise. The pieces of
adjacent triangles tile the square (a shared edge is traversed once each way), so a
footprint covered by a sheet of triangles sees exactly its area, however small the
triangles are; a degenerate triangle has a piece of zero area.
"""

from typing import NamedTuple

import jax.numpy as jnp

from .._math import safe_div, safe_sqrt

PARALLEL_TOLERANCE = 1e-12  # as in intersect_ray_triangle: rays (nearly) parallel to the plane miss
FRONT_TOLERANCE = 1e-12  # a disk's corner must be this far in front of the taxel (relative to its distance)
# A cone's triangle counts only with every corner within acos(CONE_FRONT_COSINE) = 85
# degrees of the axis: nearer the horizon its gnomonic projection runs off to
# infinity, and the clip's round-off (relative to the footprint) grows with it.
# Contact-surface triangles are far smaller than the 45-degree span from a field's
# rim (< 90 degrees) out to there, so no visible triangle is lost in practice.
CONE_FRONT_COSINE = 0.08715574274765817


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


class PairGeometry(NamedTuple):
    """A triangle in a taxel's ray plane (one pair, or broadcastable columns of them).

    - `corners_x`, `corners_y`: 3 lists of the projected corners' coordinates.
    - `corner_depths`: 3 lists of the corners' distances along the taxel's axis.
    - `corner_pressures`: 3 lists of the corners' pressures.
    - `doubled_area`: the projected triangle's signed doubled area (> 0 counter-clockwise).
    - `valid`: the pair can be hit (valid triangle, in front, not seen edge-on).
    """

    corners_x: list
    corners_y: list
    corner_depths: list
    corner_pressures: list
    doubled_area: object
    valid: object


def calc_pair_geometry(origin, u, v, axis, corners, corner_pressures, is_cone, valid) -> PairGeometry:
    """Project triangles into taxels' ray planes (per pair; broadcastable columns).

    `origin`, `u`, `v`, `axis`: (3, ...) the taxel's position and frame; `corners`
    (3 corners, 3, ...), `corner_pressures` (3 corners, ...), `is_cone`, `valid` (...).
    """
    local = []
    for j in range(3):
        offset = [corners[j][k] - origin[k] for k in range(3)]
        local.append([_dot(offset, u), _dot(offset, v), _dot(offset, axis)])
    depths = [w[2] for w in local]
    corners_x = [jnp.where(is_cone, safe_div(w[0], w[2]), w[0]) for w in local]
    corners_y = [jnp.where(is_cone, safe_div(w[1], w[2]), w[1]) for w in local]
    # Edge-on: the triangle's plane contains the rays (disk: parallel to the axis;
    # cone: through the apex), judged as intersect_ray_triangle does.
    normal = _cross([local[1][k] - local[0][k] for k in range(3)], [local[2][k] - local[0][k] for k in range(3)])
    normal_length = safe_sqrt(_dot(normal, normal))
    facing = jnp.where(is_cone, _dot(local[0], normal), normal[2])
    reach = jnp.where(is_cone, safe_sqrt(_dot(local[0], local[0])), 1.0)
    sizes = [safe_sqrt(_dot(w, w)) for w in local]
    front = jnp.where(is_cone, CONE_FRONT_COSINE, FRONT_TOLERANCE)
    in_front = (depths[0] > front * sizes[0]) & (depths[1] > front * sizes[1]) & (depths[2] > front * sizes[2])
    valid = valid & in_front & (jnp.abs(facing) > PARALLEL_TOLERANCE * normal_length * reach)
    doubled_area = (corners_x[1] - corners_x[0]) * (corners_y[2] - corners_y[0]) - (corners_y[1] - corners_y[0]) * (corners_x[2] - corners_x[0])
    return PairGeometry(corners_x, corners_y, depths, [corner_pressures[j] for j in range(3)], doubled_area, valid)


def _edge_function(pair: PairGeometry, j, x, y):
    """Twice the signed area of (corner j+1, corner j+2, (x, y)): the projected
    triangle's barycentric coordinate j times its doubled area."""
    k, m = (j + 1) % 3, (j + 2) % 3
    return (pair.corners_x[m] - pair.corners_x[k]) * (y - pair.corners_y[k]) - (pair.corners_y[m] - pair.corners_y[k]) * (x - pair.corners_x[k])


def _clip_interval(start, slope, half):
    """[lo, hi] of lambda in [0, 1] with |start + lambda slope| <= half (lo > hi: empty).

    Continuous in the slope through 0: a tiny slope gives huge bounds, the caller
    clamps them to [0, 1], and the limit is the slope-0 answer (all or nothing)."""
    inverse = 1.0 / jnp.where(slope == 0.0, 1.0, slope)
    first, second = (-half - start) * inverse, (half - start) * inverse
    inside = jnp.abs(start) <= half
    lo = jnp.where(slope == 0.0, jnp.where(inside, 0.0, 1.0), jnp.minimum(first, second))
    hi = jnp.where(slope == 0.0, jnp.where(inside, 1.0, 0.0), jnp.maximum(first, second))
    return lo, hi


def calc_footprint_moments(pair: PairGeometry, centre_x, centre_y, half):
    """Area and first moments (about the ray) of the part of the square
    |X - centre_x|, |Y - centre_y| <= half inside the pair's triangle.

    **Returns:** (area, int (X - centre_x), int (Y - centre_y)), 0 for invalid pairs.
    """
    area, moment_x, moment_y = 0.0, 0.0, 0.0
    orientation = jnp.where(pair.doubled_area >= 0.0, 1.0, -1.0)
    # The triangle's edges inside the square, counter-clockwise (contour int F dY with
    # F = X, X^2 / 2, X Y for the area and the moments, exact on a segment).
    for j in range(3):
        k = (j + 1) % 3
        start_x, start_y = pair.corners_x[j] - centre_x, pair.corners_y[j] - centre_y
        step_x, step_y = pair.corners_x[k] - pair.corners_x[j], pair.corners_y[k] - pair.corners_y[j]
        lo_x, hi_x = _clip_interval(start_x, step_x, half)
        lo_y, hi_y = _clip_interval(start_y, step_y, half)
        # Clamped to [0, 1] so that a near-parallel edge's huge bounds never reach the
        # arithmetic below (compiled code contracts it into fused multiply-adds, whose
        # round-off is relative to the operands).
        lo = jnp.clip(jnp.maximum(lo_x, lo_y), 0.0, 1.0)
        hi = jnp.maximum(jnp.clip(jnp.minimum(hi_x, hi_y), 0.0, 1.0), lo)
        ax, ay = start_x + lo * step_x, start_y + lo * step_y
        bx, by = start_x + hi * step_x, start_y + hi * step_y
        rise = orientation * (by - ay)
        area = area + rise * (ax + bx) * 0.5
        moment_x = moment_x + rise * (ax * ax + ax * bx + bx * bx) * (1.0 / 6.0)
        moment_y = moment_y + rise * (2.0 * ax * ay + ax * by + bx * ay + 2.0 * bx * by) * (1.0 / 6.0)
    # The square's vertical sides inside the triangle (its horizontal ones add nothing
    # to contour int F dY): the right one upwards, the left one downwards.
    for side in (1.0, -1.0):
        lo, hi = -half, half
        for j in range(3):
            # The edge function along the side, oriented to be >= 0 inside, is
            # at + slope_y (Y - centre_y): a lower bound on Y where slope_y >= 0, an
            # upper one where slope_y < 0. The root is clamped to the side, so a
            # near-parallel edge (a tiny slope, a huge root) gives the slope-0 answer
            # (all of the side or none, as at >= 0 or not) continuously, and no huge
            # value reaches the moments below.
            k, m = (j + 1) % 3, (j + 2) % 3
            at = orientation * _edge_function(pair, j, centre_x + side * half, centre_y)
            slope_y = orientation * (pair.corners_x[m] - pair.corners_x[k])
            root = jnp.clip(-at / jnp.where(slope_y == 0.0, 1.0, slope_y), -half, half)
            root = jnp.where(slope_y == 0.0, jnp.where(at >= 0.0, -half, half), root)
            lo = jnp.where(slope_y >= 0.0, jnp.maximum(lo, root), lo)
            hi = jnp.where(slope_y < 0.0, jnp.minimum(hi, root), hi)
        hi = jnp.maximum(hi, lo)
        area = area + half * (hi - lo)
        moment_x = moment_x + side * 0.5 * half * half * (hi - lo)
        moment_y = moment_y + 0.5 * half * (hi - lo) * (hi + lo)
    return tuple(jnp.where(pair.valid, m, 0.0) for m in (area, moment_x, moment_y))


def _clamp_to_corners(value, corner_values):
    lo = jnp.minimum(jnp.minimum(corner_values[0], corner_values[1]), corner_values[2])
    hi = jnp.maximum(jnp.maximum(corner_values[0], corner_values[1]), corner_values[2])
    return jnp.clip(value, lo, hi)


def calc_footprint_hits(pair: PairGeometry, centre_x, centre_y, half, is_cone):
    """What a ray's footprint sees of a triangle (pairs broadcast against rays).

    The pressure and distance are those at the covered part's centroid: on a disk p
    is affine in the ray plane, so the covered area times the centroid's pressure is
    its exact integral; on a cone the centroid's (perspective-correct) pressure is a
    midpoint rule, exact for a uniform pressure and otherwise off by the square of
    the footprint's size. Both are clamped to the corners' range, which the exact
    values respect, so that a sliver (a triangle seen nearly edge-on, whose
    centroid's round-off is large beside its width) cannot extrapolate.

    **Returns:** (covered area, the pressure integrated over it, the distance along
    the ray at the covered part's centroid).
    """
    area, moment_x, moment_y = calc_footprint_moments(pair, centre_x, centre_y, half)
    x, y = centre_x + safe_div(moment_x, area), centre_y + safe_div(moment_y, area)
    inverse_area = safe_div(1.0, pair.doubled_area)
    barycentric = [_edge_function(pair, j, x, y) * inverse_area for j in range(3)]
    # On a cone the 3-D barycentric coordinates are those of the projection over the
    # corners' depths, normalised (perspective-correct interpolation).
    weights = [jnp.where(is_cone, safe_div(barycentric[j], pair.corner_depths[j]), barycentric[j]) for j in range(3)]
    total = weights[0] + weights[1] + weights[2]
    pressure = safe_div(weights[0] * pair.corner_pressures[0] + weights[1] * pair.corner_pressures[1] + weights[2] * pair.corner_pressures[2], total)
    axial = safe_div(weights[0] * pair.corner_depths[0] + weights[1] * pair.corner_depths[1] + weights[2] * pair.corner_depths[2], total)
    pressure = _clamp_to_corners(pressure, pair.corner_pressures)
    axial = _clamp_to_corners(axial, pair.corner_depths)
    depth = jnp.where(is_cone, axial * safe_sqrt(x * x + y * y + 1.0), axial)
    return area, area * pressure, depth
