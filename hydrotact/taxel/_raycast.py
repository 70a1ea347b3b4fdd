"""Rays against triangles: the Moller-Trumbore test, and the contact surface as a
triangle soup carrying pressure at its corners."""

import jax.numpy as jnp
import numpy as np

from .._math import safe_div, safe_sqrt

PARALLEL_TOLERANCE = 1e-12  # |sin| of the ray-to-plane angle below which a ray is parallel
EDGE_TOLERANCE = 1e-9  # barycentric slack: a ray along a shared edge hits at least one side


def _minus(a, b):
    return [a[k] - b[k] for k in range(3)]


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def intersect_ray_triangle(origin, direction, v0, v1, v2):
    """Where a ray meets a triangle (Moller and Trumbore, 1997).

    Solves origin + t direction = (1 - u - v) v0 + u v1 + v v2. Both faces count (a
    contact surface is an open sheet, and rays reach it from either side); a ray
    (nearly) parallel to the triangle's plane misses, and so does a degenerate
    triangle. Points on edges and corners hit, with a barycentric slack of
    EDGE_TOLERANCE: the plain test is not watertight, and a ray exactly along an edge
    shared by two triangles (common: the Vogel spiral's first ray lies on the taxel's
    x axis, the fan triangulations and the structured meshes have edges there) could
    miss both by round-off. Such a ray hits both, at the same t to round-off, and the
    caller takes the nearest. Only t > 0 counts. Values and gradients stay finite in
    every case.

    Coordinates run along the first axis: (3,) vectors for one ray and one triangle,
    or (3, ...) columns for many at once that broadcast against each other (rays
    (3, P, R) against triangles (3, P, 1)); the results have the trailing shape. The
    products are written per coordinate, so that many rays and triangles make one
    elementwise loop on the CPU.

    **Returns:** (hit, t, u, v); t is +inf where there is no hit.
    """
    e1, e2 = _minus(v1, v0), _minus(v2, v0)
    pvec = _cross(direction, e2)
    det = _dot(e1, pvec)
    # |det| = |d . (e1 x e2)|: compare with |d| |e1 x e2| to judge parallel rays.
    normal = _cross(e1, e2)
    scale = safe_sqrt(_dot(direction, direction)) * safe_sqrt(_dot(normal, normal))
    parallel = jnp.abs(det) <= PARALLEL_TOLERANCE * scale
    inverse = safe_div(1.0, jnp.where(parallel, 0.0, det))
    tvec = _minus(origin, v0)
    u = _dot(tvec, pvec) * inverse
    qvec = _cross(tvec, e1)
    v = _dot(direction, qvec) * inverse
    t = _dot(e2, qvec) * inverse
    slack = EDGE_TOLERANCE
    hit = ~parallel & (u >= -slack) & (v >= -slack) & (u + v <= 1.0 + slack) & (t > 0.0)
    return hit, jnp.where(hit, t, jnp.inf), u, v


def calc_surface_triangles(surface):
    """Fan-triangulate every polygon of a ContactSurface from its vertex 0.

    Polygon k with c vertices gives triangles (0, j + 1, j + 2) for j < c - 2; the
    slots are (capacity, 6) with a validity mask (the polygon is valid and j + 2 < c).

    **Returns:** (corners (capacity * 6, 3, 3) in frame S, corner pressures
    (capacity * 6, 3), valid (capacity * 6,)).
    """
    vertices, pressures = surface.vertices_S, surface.pressures
    capacity, polygon_capacity = pressures.shape
    fan = jnp.arange(1, polygon_capacity - 1)
    corners = jnp.stack(
        [jnp.broadcast_to(vertices[:, :1], (capacity, fan.shape[0], 3)), vertices[:, fan], vertices[:, fan + 1]], axis=2
    )
    corner_pressures = jnp.stack(
        [jnp.broadcast_to(pressures[:, :1], (capacity, fan.shape[0])), pressures[:, fan], pressures[:, fan + 1]], axis=2
    )
    valid = surface.valid[:, None] & (fan[None, :] + 1 < surface.counts[:, None])
    return corners.reshape(-1, 3, 3), corner_pressures.reshape(-1, 3), valid.reshape(-1)


def calc_first_hits(origins, directions, vertices, faces, tolerance: float, chunk: int = 256) -> np.ndarray:
    """How far each ray origins[i] + t directions[i] goes (t > tolerance) before it
    first meets a triangle of the mesh (`vertices`, `faces`): every ray against every
    triangle with :func:`intersect_ray_triangle`, `chunk` rays at a time (host; NumPy
    in, NumPy out). **Returns:** t (n,), +inf where a ray meets none."""
    triangles = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    corners = [triangles[:, k].T[:, None, :] for k in range(3)]  # (3, 1, triangles) each
    origins, directions = np.asarray(origins, dtype=np.float64), np.asarray(directions, dtype=np.float64)
    nearest = np.full(len(origins), np.inf)
    for start in range(0, len(origins), chunk):
        part = slice(start, start + chunk)
        hit, t, _, _ = intersect_ray_triangle(origins[part].T[:, :, None], directions[part].T[:, :, None], *corners)
        nearest[part] = np.where(np.asarray(hit) & (np.asarray(t) > tolerance), np.asarray(t), np.inf).min(axis=1)
    return nearest
