"""Is a point inside an elastomer? Winding numbers for closed surfaces, barycentric
coordinates for tet meshes (host, numpy; a few points against a few thousand cells)."""

import numpy as np


def _segment_distances(points, a, b):
    ab = b - a
    t = np.clip(np.einsum("pti,ti->pt", points[:, None] - a, ab) / np.maximum(np.einsum("ti,ti->t", ab, ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1)


def calc_surface_distances(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Distance from each point (n, 3) to the nearest of `triangles` (k, 3, 3), (n,).

    The numpy twin of `hydrotact._geometry.calc_distance_to_triangles` for a handful of
    points on the host, where compiling the JAX kernel would cost more than the work.
    """
    points = np.asarray(points, dtype=np.float64)
    a, b, c = (np.asarray(triangles, dtype=np.float64)[:, i] for i in range(3))
    n = np.cross(b - a, c - a)
    area2 = np.einsum("ti,ti->t", n, n)
    safe = np.where(area2 > 0.0, area2, 1.0)
    rel = points[:, None] - a
    w_b = np.einsum("pti,ti->pt", np.cross(rel, c - a), n) / safe
    w_c = np.einsum("pti,ti->pt", np.cross(b - a, rel), n) / safe
    inside = (area2 > 0.0) & (w_b >= 0.0) & (w_c >= 0.0) & (w_b + w_c <= 1.0)
    plane = np.abs(np.einsum("pti,ti->pt", rel, n)) / np.sqrt(safe)
    edges = np.minimum(np.minimum(_segment_distances(points, a, b), _segment_distances(points, b, c)), _segment_distances(points, c, a))
    return np.where(inside, plane, edges).min(axis=1)


def calc_winding_numbers(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, chunk_size: int = 64) -> np.ndarray:
    """Generalised winding number of each point with respect to a closed, outward-wound
    triangle surface: 1 inside, 0 outside, 1/2 on a smooth part of the boundary.

    Sum over triangles of the signed solid angle (Van Oosterom and Strackee) over 4 pi.
    `points` (n, 3), `vertices` (m, 3), `faces` (k, 3); returns (n,).
    """
    triangles = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    numbers = []
    for chunk in np.array_split(np.asarray(points, dtype=np.float64), max(1, len(points) // chunk_size)):
        a, b, c = (triangles[None, :, i] - chunk[:, None] for i in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
        det = np.einsum("pti,pti->pt", a, np.cross(b, c))
        dot = lambda u, v: np.einsum("pti,pti->pt", u, v)
        denominator = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb
        numbers.append(2.0 * np.arctan2(det, denominator).sum(axis=1) / (4.0 * np.pi))
    return np.concatenate(numbers) if numbers else np.zeros(0)


def find_points_outside_surface(points, vertices, faces, tolerance: float) -> np.ndarray:
    """Indices of the points neither within `tolerance` (metres) of the closed surface
    nor inside it (winding number above 1/2, which is reliable off the surface)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    off = np.flatnonzero(calc_surface_distances(points, triangles) > tolerance)
    if len(off) == 0:
        return off
    return off[calc_winding_numbers(points[off], vertices, faces) < 0.5]


def find_points_outside_tets(points, vertices, tets, boundary_faces, tolerance: float) -> np.ndarray:
    """Indices of the points in no tet (barycentric coordinates >= -1e-9) and farther
    than `tolerance` (metres) from the mesh's boundary faces."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    vertices = np.asarray(vertices, dtype=np.float64)
    corners = vertices[np.asarray(tets)]
    edges = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1))
    inverse = np.linalg.inv(edges)
    inside = np.zeros(len(points), dtype=bool)
    for index, point in enumerate(points):
        local = np.einsum("tij,tj->ti", inverse, point - corners[:, 0])
        bary = np.concatenate([1.0 - local.sum(-1, keepdims=True), local], axis=-1)
        inside[index] = bool(np.any(np.all(bary >= -1e-9, axis=-1)))
    suspect = np.flatnonzero(~inside)
    if len(suspect) == 0:
        return suspect
    distances = calc_surface_distances(points[suspect], vertices[np.asarray(boundary_faces)])
    return suspect[distances > tolerance]
