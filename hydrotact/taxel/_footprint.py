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
each a segment on which F is a polynomial integrated exactly. Everything that depends
on the pair alone (the edges' reciprocal slopes, the edge functions, the pressure's
and the distance's affine coefficients, the clamps) is computed once per pair
(:func:`calc_pair_geometry`); per (pair, ray) it is products, comparisons and a few
divisions (by the footprint's area, the centroid's, the perspective division's),
elementwise. The pieces of
adjacent triangles tile the square (a shared edge is traversed once each way), so a
footprint covered by a sheet of triangles sees exactly its area, however small the
triangles are; a degenerate triangle has a piece of zero area.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._math import safe_div, safe_sqrt
from ._raycast import PARALLEL_TOLERANCE, _cross, _dot  # rays (nearly) parallel to a plane miss, as in intersect_ray_triangle

FRONT_TOLERANCE = 1e-12  # a disk's corner must be this far in front of the taxel (relative to its distance)
# A cone's triangle counts only with every corner within acos(CONE_FRONT_COSINE) = 85
# degrees of the axis: nearer the horizon its gnomonic projection runs off to
# infinity, and the clip's round-off (relative to the footprint) grows with it.
# Contact-surface triangles are far smaller than the 45-degree span from a field's
# rim (< 90 degrees) out to there, so no visible triangle is lost in practice.
CONE_FRONT_COSINE = 0.08715574274765817


class PairGeometry(NamedTuple):
    """A triangle in a taxel's ray plane (one pair, or broadcastable columns of them),
    with everything the footprints need that depends on the pair alone.

    - `corners_x`, `corners_y`: 3 lists of the projected corners' coordinates.
    - `steps_x`, `steps_y`: 3 lists, edge j's vector from corner j to corner j + 1.
    - `inverse_steps_x`, `inverse_steps_y`: their reciprocals (HUGE for a zero step:
      the clip's all-or-nothing limit, clamped to [0, 1]).
    - `edges`: 3 lists of the edge functions' affine coefficients (constant, along X,
      along Y), oriented to be >= 0 inside; edge j is opposite corner j.
    - `root_scales`, `root_offsets`: 3 lists: the root in Y of edge function j along a
      vertical line is at * root_scale - root_offset, `at` its value at the line's
      centre_y: the scale is -1 / (the Y coefficient), the offset 0; for a zero Y
      coefficient, -HUGE and sqrt(HUGE), so that the clamped root is the bottom of the
      line where at >= 0 (no bound) and the top where at < 0 (empty).
    - `numerator`, `denominator`, `axial`: affine coefficients (constant, X, Y) of the
      perspective-correct pressure's numerator and denominator and of the distance
      along the axis's numerator: p = N / D, z = Z / D.
    - `orientation`: +1 for a counter-clockwise projected triangle, -1 otherwise.
    - `pressure_range`, `depth_range`: (lowest, highest) over the corners.
    - `valid`: the pair can be hit (valid triangle, in front, not seen edge-on).
    """

    corners_x: list
    corners_y: list
    steps_x: list
    steps_y: list
    inverse_steps_x: list
    inverse_steps_y: list
    edges: list
    root_scales: list
    root_offsets: list
    numerator: list
    denominator: list
    axial: list
    orientation: object
    pressure_range: tuple
    depth_range: tuple
    valid: object


# A reciprocal standing in for 1 / 0: any nonzero offset it multiplies (footprints are
# >> 1e-100 wide) lands far outside the clamp's range, giving the slope-0 limit.
HUGE = 1e200


def _reciprocal(value):
    is_zero = value == 0.0
    return jnp.where(is_zero, HUGE, 1.0 / jnp.where(is_zero, 1.0, value))


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
    orientation = jnp.where(doubled_area >= 0.0, 1.0, -1.0)
    steps_x = [corners_x[(j + 1) % 3] - corners_x[j] for j in range(3)]
    steps_y = [corners_y[(j + 1) % 3] - corners_y[j] for j in range(3)]
    # Edge function j: twice the signed area of (corner j+1, corner j+2, (X, Y)), the
    # projected triangle's barycentric coordinate j times its doubled area.
    edges, raw_edges = [], []
    for j in range(3):
        k, m = (j + 1) % 3, (j + 2) % 3
        along_x, along_y = -(corners_y[m] - corners_y[k]), corners_x[m] - corners_x[k]
        constant = -along_x * corners_x[k] - along_y * corners_y[k]
        raw_edges.append((constant, along_x, along_y))
        edges.append(tuple(orientation * c for c in raw_edges[-1]))
    # Perspective-correct interpolation: on a cone the barycentric coordinates over the
    # corners' depths, normalised (D = sum_j b_j / z_j); on a disk D = 1.
    inverse_area = safe_div(1.0, doubled_area)
    scales = [jnp.where(is_cone, safe_div(inverse_area, depths[j]), inverse_area) for j in range(3)]
    pressures = [corner_pressures[j] for j in range(3)]
    numerator = [sum(scales[j] * pressures[j] * raw_edges[j][c] for j in range(3)) for c in range(3)]
    denominator = [sum(scales[j] * raw_edges[j][c] for j in range(3)) for c in range(3)]
    axial = [sum(scales[j] * depths[j] * raw_edges[j][c] for j in range(3)) for c in range(3)]

    def corner_range(values):
        return jnp.minimum(jnp.minimum(values[0], values[1]), values[2]), jnp.maximum(jnp.maximum(values[0], values[1]), values[2])

    return PairGeometry(
        corners_x,
        corners_y,
        steps_x,
        steps_y,
        [_reciprocal(step) for step in steps_x],
        [_reciprocal(step) for step in steps_y],
        edges,
        [-_reciprocal(edge[2]) for edge in edges],
        [jnp.where(edge[2] == 0.0, HUGE**0.5, 0.0) for edge in edges],
        numerator,
        denominator,
        axial,
        orientation,
        corner_range(pressures),
        corner_range(depths),
        valid,
    )


def _clip_interval(start, inverse_slope, half):
    """[lo, hi] of lambda with |start + lambda slope| <= half (lo > hi: empty), before
    clamping to [0, 1]. A zero slope's HUGE reciprocal gives huge bounds whose clamp
    is the slope-0 answer (all or nothing), continuously in the slope."""
    first, second = (-half - start) * inverse_slope, (half - start) * inverse_slope
    return jnp.minimum(first, second), jnp.maximum(first, second)


def _complex_dtype(value):
    return jnp.result_type(value, jnp.complex64)


def _affine(coefficients, x, y):
    return coefficients[0] + coefficients[1] * x + coefficients[2] * y


def calc_footprint_moments(pair: PairGeometry, centre_x, centre_y, half):
    """Area and first moments (about the ray) of the part of the square
    |X - centre_x|, |Y - centre_y| <= half inside the pair's triangle.

    **Returns:** (area, int (X - centre_x), int (Y - centre_y)), 0 for invalid pairs.
    """
    # The triangle's edges inside the square, counter-clockwise (contour int F dY with
    # F = X, X^2 / 2, X Y for the area and the moments, exact on a segment; their
    # constant factors and the orientation are applied to the sums).
    edge_area, edge_x, edge_y = 0.0, 0.0, 0.0
    for j in range(3):
        start_x, start_y = pair.corners_x[j] - centre_x, pair.corners_y[j] - centre_y
        step_x, step_y = pair.steps_x[j], pair.steps_y[j]
        lo_x, hi_x = _clip_interval(start_x, pair.inverse_steps_x[j], half)
        lo_y, hi_y = _clip_interval(start_y, pair.inverse_steps_y[j], half)
        # Clamped to [0, 1] so that a near-parallel edge's huge bounds never reach the
        # arithmetic below (compiled code contracts it into fused multiply-adds, whose
        # round-off is relative to the operands).
        lo = jnp.clip(jnp.maximum(lo_x, lo_y), 0.0, 1.0)
        hi = jnp.maximum(jnp.clip(jnp.minimum(hi_x, hi_y), 0.0, 1.0), lo)
        ax, ay = start_x + lo * step_x, start_y + lo * step_y
        bx, by = start_x + hi * step_x, start_y + hi * step_y
        rise = by - ay
        edge_area = edge_area + rise * (ax + bx)
        edge_x = edge_x + rise * (ax * ax + ax * bx + bx * bx)
        edge_y = edge_y + rise * (2.0 * ax * ay + ax * by + bx * ay + 2.0 * bx * by)
    # The square's vertical sides inside the triangle (its horizontal ones add nothing
    # to contour int F dY): the right one upwards, the left one downwards.
    # The edge function along a side (>= 0 inside) is at + slope_y (Y - centre_y): a
    # lower bound on Y where slope_y >= 0, an upper one where slope_y < 0. The root is
    # clamped to the side, so a near-parallel edge (a tiny slope, a huge root) gives
    # the slope-0 answer (all of the side or none, as at >= 0 or not) continuously,
    # and no huge value reaches the moments below.
    at_centre = [_affine(pair.edges[j], centre_x, centre_y) for j in range(3)]
    lengths, squares = [], 0.0
    for side in (1.0, -1.0):
        lo, hi = -half, half
        for j in range(3):
            slope_y = pair.edges[j][2]
            at = at_centre[j] + side * half * pair.edges[j][1]
            root = jnp.clip(at * pair.root_scales[j] - pair.root_offsets[j], -half, half)
            lo = jnp.where(slope_y >= 0.0, jnp.maximum(lo, root), lo)
            hi = jnp.where(slope_y < 0.0, jnp.minimum(hi, root), hi)
        hi = jnp.maximum(hi, lo)
        lengths.append(hi - lo)
        squares = squares + (hi - lo) * (hi + lo)
    area = 0.5 * pair.orientation * edge_area + half * (lengths[0] + lengths[1])
    moment_x = (1.0 / 6.0) * pair.orientation * edge_x + 0.5 * half * half * (lengths[0] - lengths[1])
    moment_y = (1.0 / 6.0) * pair.orientation * edge_y + 0.5 * half * squares
    return jnp.where(pair.valid, area, 0.0), moment_x, moment_y


def calc_footprint_hits(pair: PairGeometry, centre_x, centre_y, half, is_cone):
    """What a ray's footprint sees of a triangle (pairs broadcast against rays).

    The pressure and distance are those at the covered part's centroid: on a disk p
    is affine in the ray plane, so the covered area times the centroid's pressure is
    its exact integral; on a cone the centroid's (perspective-correct) pressure is a
    midpoint rule, exact for a uniform pressure and otherwise off by the square of
    the footprint's size. Both are clamped to the corners' range, which the exact
    values respect, so that a sliver (a triangle seen nearly edge-on, whose
    centroid's round-off is large beside its width) cannot extrapolate.

    **Returns:** (covered area, the pressure integral over it, both per unit of the
    footprint's area, and the distance along the ray at the covered part's centroid).
    """
    # Per unit of the footprint's area, the first moment as one complex number
    # int (X + i Y): XLA's CPU fusion repeats cheap elementwise work inside every
    # consumer of a result (here the clip, most of the work, five times over: the
    # centroid's coordinates, the sheet's minimum, the sums), but not an expensive
    # operation such as a division, and one complex result computes both moments in
    # one pass. The clip is done twice, not five times.
    footprint = 4.0 * half * half
    area, moment_x, moment_y = calc_footprint_moments(pair, centre_x, centre_y, half)
    area, moment = area / footprint, jax.lax.complex(moment_x, moment_y) / footprint.astype(_complex_dtype(moment_x))
    inverse_area = safe_div(1.0, area)
    x, y = centre_x + jnp.real(moment) * inverse_area, centre_y + jnp.imag(moment) * inverse_area
    inverse_denominator = safe_div(1.0, _affine(pair.denominator, x, y))
    pressure = jnp.clip(_affine(pair.numerator, x, y) * inverse_denominator, *pair.pressure_range)
    axial = jnp.clip(_affine(pair.axial, x, y) * inverse_denominator, *pair.depth_range)
    depth = jnp.where(is_cone, axial * safe_sqrt(x * x + y * y + 1.0), axial)
    return area, area * pressure, depth
