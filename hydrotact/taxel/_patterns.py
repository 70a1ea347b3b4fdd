"""Receptive fields and their ray patterns.

A taxel (one barometer) sits at `position_S`, senses along the unit `axis_S`, and
sees the contact surface through a receptive field sampled by `num_rays` rays:

- a **disk** of radius r (flat arrays, as in the hydroelastic tactile paper): parallel
  rays along the axis, starting from points of the disk of radius r about the
  position, perpendicular to the axis; ray i's distance from the axis is d_i;
- a **cone** of half-angle a (curved sensors): rays fanning from the position, ray i
  at angle d_i from the axis.

Rays are spread evenly and deterministically: a Vogel (golden-angle) spiral over the
disk's area, and its spherical twin (uniform in solid angle) over the cone's cap, so
each ray stands for the same area or solid angle whatever N is. Each ray carries the
weight w_i = (r - d_i)^2 (r the radius, or the half-angle for a cone) of the paper's
aggregation; because the rays are equal-area samples, sum w_i p_i / sum w_i converges
to the weighted mean of the pressure over the field as N grows.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._choices import Choice
from .._errors import HydrotactError
from .._math import safe_norm, safe_sqrt
from .._types import Array, Bool, Float

GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))
# A footprint's side over the side of the ray's share of the field: overlapping
# squares (1.5 x 1.5 shares) even out the gaps and overlaps between neighbours that a
# rim crossing the field would otherwise see as ripples.
FOOTPRINT_SCALE = 1.5
# Points per side of the midpoint grid over which a footprint's mean weight is taken.
WEIGHT_GRID = 8
# From this many rays per field, the deblurred weights are adjusted so that the
# kernel's first and second moments are the field's (:func:`_match_moments`); fewer
# rays leave the 5 x 5 system too thin (a single ray has no spread).
MOMENT_MATCH_RAYS = 16
MOMENT_NODES = 32


class ReceptiveFieldKind(Choice):
    """Receptive field kind: `disk`, parallel rays over a disk around the sensing
    axis (flat arrays, as in the hydroelastic tactile paper), or `cone`, rays fanning
    out from the embedded barometer (curved sensors)."""

    DISK = "disk"
    CONE = "cone"


class TaxelLayout(eqx.Module):
    """Where the taxels are and what they see (a pytree; differentiable in every
    float field, so layouts can be designed by gradient).

    **Fields:**

    - `positions_S`: (num_taxels, 3) barometer ports in the sensor frame S, metres.
    - `axes_S`: (num_taxels, 3) sensing axes (normalised where used).
    - `field_sizes`: (num_taxels,) disk radius in metres, or cone half-angle in radians.
    - `is_cone`: (num_taxels,) True for a cone field, False for a disk.
    """

    positions_S: Float[Array, "num_taxels 3"]
    axes_S: Float[Array, "num_taxels 3"]
    field_sizes: Float[Array, " num_taxels"]
    is_cone: Bool[Array, " num_taxels"]

    @property
    def num_taxels(self) -> int:
        return self.positions_S.shape[0]


def make_taxel_layout(positions_S, axes_S, field_kinds, field_sizes) -> TaxelLayout:
    """A TaxelLayout from host arrays, checked: finite positions, non-zero axes,
    kinds among "disk"/"cone", positive sizes, cone half-angles below 90 degrees."""
    positions = np.asarray(positions_S, dtype=np.float64)
    axes = np.array(axes_S, dtype=np.float64)
    sizes = np.asarray(field_sizes, dtype=np.float64)
    kinds = tuple(field_kinds)
    count = positions.shape[0] if positions.ndim == 2 else -1
    if positions.shape != (count, 3) or axes.shape != (count, 3) or sizes.shape != (count,) or len(kinds) != count:
        raise HydrotactError(
            f"taxel layout: positions {positions.shape}, axes {axes.shape}, sizes {sizes.shape} and "
            f"{len(kinds)} field kinds do not describe the same number of taxels"
        )
    for index in range(count):
        if kinds[index] not in tuple(ReceptiveFieldKind):
            raise HydrotactError(f"taxel {index}: receptive field kind must be 'disk' or 'cone', got {kinds[index]!r}")
        if not (np.all(np.isfinite(positions[index])) and np.all(np.isfinite(axes[index]))):
            raise HydrotactError(f"taxel {index}: position and axis must be finite")
        norm = np.linalg.norm(axes[index])
        if norm == 0.0:
            raise HydrotactError(f"taxel {index}: the axis is zero")
        limit = np.pi / 2 if kinds[index] == "cone" else np.inf
        if not (0.0 < sizes[index] < limit):
            what = "half-angle (rad) must be in (0, pi/2)" if kinds[index] == "cone" else "radius (m) must be positive"
            raise HydrotactError(f"taxel {index}: receptive field {what}, got {sizes[index]!r}")
        axes[index] /= norm
    return TaxelLayout(
        positions_S=jnp.asarray(positions),
        axes_S=jnp.asarray(axes),
        field_sizes=jnp.asarray(sizes),
        is_cone=jnp.asarray(np.array([kind == "cone" for kind in kinds], dtype=bool)),
    )


def calc_spiral(num_rays: int):
    """The unit Vogel spiral: radii sqrt((i + 1/2) / N) and golden angles (host).

    **Returns:** (fractions (N,) in (0, 1), the cumulative area fraction of each
    ray's ring; azimuths (N,) in radians).
    """
    if num_rays < 1:
        raise HydrotactError(f"a receptive field needs at least one ray, got {num_rays}")
    index = np.arange(num_rays, dtype=np.float64)
    return (index + 0.5) / num_rays, np.mod(index * GOLDEN_ANGLE, 2.0 * np.pi)


def calc_perpendicular_frame(axis):
    """Two unit vectors (u, v) with (u, v, axis) right-handed and orthonormal."""
    axis = axis / safe_norm(axis)
    helper = jnp.where(jnp.abs(axis[0]) < 0.9, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0])).astype(axis.dtype)
    u = jnp.cross(helper, axis)
    u = u / safe_norm(u)
    return u, jnp.cross(axis, u)


def calc_taxel_rays(position_S, axis_S, field_size, is_cone, num_rays: int):
    """The rays of one taxel (pure; differentiable in position, axis and size).

    **Returns:** (origins (N, 3), unit directions (N, 3), weights (N,) = (r - d_i)^2
    with r the field size and d_i the ray's distance from the axis, or its angle).
    """
    fractions, azimuths = (jnp.asarray(a, position_S.dtype) for a in calc_spiral(num_rays))
    axis = axis_S / safe_norm(axis_S)
    u, v = calc_perpendicular_frame(axis)
    around = jnp.cos(azimuths)[:, None] * u[None] + jnp.sin(azimuths)[:, None] * v[None]  # (N, 3)
    # Disk: equal-area rings, d = r sqrt(f); rays parallel to the axis.
    disk_offsets = field_size * jnp.sqrt(fractions)
    disk_origins = position_S[None] + disk_offsets[:, None] * around
    # Cone: equal-solid-angle rings, cos d = 1 - (1 - cos a) f; rays from the apex.
    cos_angles = 1.0 - (1.0 - jnp.cos(field_size)) * fractions
    cone_angles = jnp.arccos(jnp.clip(cos_angles, -1.0, 1.0))
    cone_directions = jnp.cos(cone_angles)[:, None] * axis[None] + jnp.sin(cone_angles)[:, None] * around
    origins = jnp.where(is_cone, jnp.broadcast_to(position_S[None], (num_rays, 3)), disk_origins)
    directions = jnp.where(is_cone, cone_directions, jnp.broadcast_to(axis[None], (num_rays, 3)))
    distances = jnp.where(is_cone, cone_angles, disk_offsets)
    return origins, directions, (field_size - distances) ** 2


def calc_footprint_scale(field_size, is_cone, num_rays: int):
    """The side of a ray's footprint square at the field's rim, in the taxel's ray
    coordinates (see :func:`calc_taxel_footprints`): the largest of the taxel's."""
    rim = jnp.where(is_cone, jnp.tan(jnp.where(is_cone, field_size, 0.0)), 0.0)
    return _footprint_side(field_size, is_cone, rim, num_rays)


def _footprint_side(field_size, is_cone, radius, num_rays):
    """Side of a footprint square whose area is the ray's share of the field: pi r^2 / N
    on a disk; on a cone the share 2 pi (1 - cos a) / N of solid angle, which the
    gnomonic plane stretches by (1 + rho^2)^(3/2) at radius rho = tan(angle)."""
    disk_area = jnp.pi * field_size**2 / num_rays
    cone_size = jnp.where(is_cone, field_size, 0.0)
    cone_area = 2.0 * jnp.pi * (1.0 - jnp.cos(cone_size)) / num_rays * (1.0 + radius**2) ** 1.5
    return FOOTPRINT_SCALE * jnp.sqrt(jnp.where(is_cone, cone_area, disk_area))


def _field_weights(field_size, is_cone, x, y):
    """The receptive field's weight max(r - d, 0)^2 at ray-plane points (x, y), d the
    distance from the axis (disk) or the angle from it (cone)."""
    rho = safe_sqrt(x * x + y * y)
    distance = jnp.where(is_cone, jnp.arctan(rho), rho)
    return jnp.maximum(field_size - distance, 0.0) ** 2


def calc_taxel_footprints(field_size, is_cone, num_rays: int):
    """Each ray's footprint in the taxel's ray coordinates (pure; differentiable in
    the size).

    A ray is a point (X, Y) of a plane: on a disk, the ray's origin in the disk's
    plane, X and Y along the (u, v) of :func:`calc_perpendicular_frame`; on a cone,
    the gnomonic (central) projection of its direction, (X, Y) = tan(d) (cos, sin) of
    its azimuth, where it meets the plane at unit distance along the axis. Its
    footprint is the axis-aligned square of that plane centred on it whose side is
    FOOTPRINT_SCALE times that of the ray's share of the field
    (:func:`_footprint_side`), so the squares overlap their neighbours; they shrink
    like N^-1/2.

    The taxel reads sum_i w_i m_i / sum_i w_i with m_i the mean pressure over square
    i: the pressure weighted by sum_i w_i box_i(X, Y), which blurs the field's weight
    w = (r - d)^2 by a footprint, an error of the order of the footprint's area (2 %
    of the peak at 64 rays on a rim sweep, converging like 1 / N). The weights are
    deblurred by one van Cittert step, w_i = 2 w(ray) - (mean of w over its square)
    (on a cone the mean per solid angle), clipped at 0, which leaves an error of the
    order of the area squared. From MOMENT_MATCH_RAYS rays on, the weights are then
    scaled by 1 + (a quadratic in the ray's position) so that the kernel
    sum_i w_i box_i has the field weight's first and second moments exactly
    (:func:`_match_moments`): a pressure quadratic across the field reads its exact
    weighted mean, and the pad's rim sweep comes within 0.8 % of the converged
    reading at 64 rays (1.2 % without). A uniform pressure reads exactly itself
    whatever the weights (they are normalised).

    **Returns:** (centres (N, 2), half sides (N,), weights (N,)).
    """
    fractions, azimuths = (jnp.asarray(a, jnp.result_type(field_size, float)) for a in calc_spiral(num_rays))
    cos_angles = 1.0 - (1.0 - jnp.cos(field_size)) * fractions
    cone_angles = jnp.arccos(jnp.clip(cos_angles, -1.0, 1.0))
    disk_offsets = field_size * jnp.sqrt(fractions)
    radii = jnp.where(is_cone, jnp.tan(jnp.where(is_cone, cone_angles, 0.0)), disk_offsets)
    centres = jnp.stack([radii * jnp.cos(azimuths), radii * jnp.sin(azimuths)], axis=-1)
    distances = jnp.where(is_cone, cone_angles, disk_offsets)
    halves = 0.5 * _footprint_side(field_size, is_cone, radii, num_rays)
    grid = (np.arange(WEIGHT_GRID) + 0.5) / WEIGHT_GRID * 2.0 - 1.0
    x = centres[:, 0, None, None] + halves[:, None, None] * grid[None, None, :]
    y = centres[:, 1, None, None] + halves[:, None, None] * grid[None, :, None]
    density = jnp.where(is_cone, (1.0 + x * x + y * y) ** -1.5, 1.0)  # solid angle per unit area of the plane
    mean = jnp.sum(density * _field_weights(field_size, is_cone, x, y), axis=(1, 2)) / jnp.sum(density, axis=(1, 2))
    weights = jnp.maximum(2.0 * (field_size - distances) ** 2 - mean, 0.0)
    if num_rays >= MOMENT_MATCH_RAYS:
        weights = _match_moments(field_size, is_cone, centres, halves, weights)
    return centres, halves, weights


def _match_moments(field_size, is_cone, centres, halves, weights):
    """Weights w_i (1 + lambda . g_i), lambda such that the kernel sum_i w_i box_i has
    the field's first and second moments: sum_i w_i g_i = 0 with g_i the moments (X,
    Y, X^2, XY, Y^2) of square i (its centre's plus the square's own s^2 / 12) less
    those of the field's weight, per unit of sum_i w_i (0, 0, m, 0, m; m half the mean
    of rho^2 weighted by w = (r - d)^2 over the field, per solid angle on a cone, by
    Gauss-Legendre in d). A 5 x 5 solve per taxel (differentiable), in units of the
    field's radius in the ray plane."""
    nodes, gauss = np.polynomial.legendre.leggauss(MOMENT_NODES)
    distances = 0.5 * (nodes + 1.0) * field_size
    cone_angles = jnp.where(is_cone, distances, 0.0)
    rim = jnp.where(is_cone, jnp.tan(jnp.where(is_cone, field_size, 0.0)), field_size)
    radii = jnp.where(is_cone, jnp.tan(cone_angles), distances) / rim
    measure = gauss * (field_size - distances) ** 2 * jnp.where(is_cone, jnp.sin(cone_angles), distances)  # w dOmega or w rho drho
    target = 0.5 * jnp.sum(measure * radii * radii) / jnp.sum(measure)
    x, y = centres[:, 0] / rim, centres[:, 1] / rim
    own = (2.0 * halves / rim) ** 2 / 12.0
    g = jnp.stack([x, y, x * x + own - target, x * y, y * y + own - target], axis=1)
    gram = jnp.einsum("i,ij,ik->jk", weights, g, g)
    lam = jnp.linalg.solve(gram, -(weights @ g))
    return weights * (1.0 + g @ lam)
