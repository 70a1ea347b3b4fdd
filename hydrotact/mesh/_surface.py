"""Closed triangle surfaces: loading, checking, and checking for self-intersection."""

from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from .._errors import HydrotactError, where
from .._units import LENGTH_UNITS
from ._tetmesh import check_vertices

SURFACE_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")
SURFACE_SIZE_M = (1e-4, 1.0)
"""The bounding-box diagonals (m) of the elastomers hydrotact meshes: a surface outside
is a unit slip (a pad in mm read as metres is 10 m across)."""


def load_surface(path, units: str = "m") -> trimesh.Trimesh:
    """Read a closed surface (STL, OBJ, PLY, ...) and scale it to metres (host)."""
    path = Path(path)
    if units not in LENGTH_UNITS:
        raise HydrotactError(f"{path}: unknown units {units!r}; use one of {sorted(LENGTH_UNITS)}")
    if not path.is_file():
        raise HydrotactError(f"{path}: no such file")
    try:
        surface = trimesh.load(str(path), force="mesh", process=False)
    except Exception as error:  # trimesh raises many kinds for unreadable files
        raise HydrotactError(f"{path}: cannot read as a surface mesh ({str(error)[:100]})") from None
    if not isinstance(surface, trimesh.Trimesh) or len(surface.faces) == 0:
        raise HydrotactError(f"{path}: contains no triangles")
    check_vertices(surface.vertices, str(path))  # before processing, which would drop a NaN vertex and report holes
    surface.process()
    surface.apply_scale(LENGTH_UNITS[units])
    check_surface_size(surface, str(path), units)
    return surface


def check_surface_size(surface: trimesh.Trimesh, source: str, units: str) -> None:
    """Refuse an elastomer (in metres) whose size says its file's units were misread."""
    size = float(np.linalg.norm(np.ptp(surface.vertices, axis=0)))
    low, high = SURFACE_SIZE_M
    if not low <= size <= high:
        hint = "in mm? (--units mm)" if size > high else "is --units right? (the file's numbers are read in --units)"
        raise HydrotactError(f"{source}: a surface {size:.3g} m across (in --units {units}) is no tactile sensor's elastomer ({low * 1e3:g} mm to {high:g} m): {hint}")


def find_self_intersections(vertices: np.ndarray, faces: np.ndarray, max_pairs: int = 1) -> np.ndarray:
    """Pairs of non-adjacent triangles that cross each other (host).

    Broad phase: triangles whose bounding spheres (about their centroids) overlap.
    Narrow phase: an edge of one triangle passes through the interior of the other
    (Moller-Trumbore with t in (0, 1)). Triangles sharing a vertex are skipped, and so
    are coplanar overlaps. Returns up to `max_pairs` pairs (k, 2).
    """
    triangles = vertices[faces]
    centroids = triangles.mean(axis=1)
    radii = np.linalg.norm(triangles - centroids[:, None], axis=-1).max(axis=1)
    tree = cKDTree(centroids)
    pairs = tree.query_pairs(r=2.0 * float(radii.max()), output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    gap = np.linalg.norm(centroids[pairs[:, 0]] - centroids[pairs[:, 1]], axis=1)
    pairs = pairs[gap <= radii[pairs[:, 0]] + radii[pairs[:, 1]]]
    shares = (faces[pairs[:, 0], :, None] == faces[pairs[:, 1], None, :]).any(axis=(1, 2))
    pairs = pairs[~shares]
    found = []
    for chunk in np.array_split(pairs, max(1, len(pairs) // 200_000)):
        hit = _edges_cross(triangles[chunk[:, 0]], triangles[chunk[:, 1]]) | _edges_cross(
            triangles[chunk[:, 1]], triangles[chunk[:, 0]]
        )
        found.append(chunk[hit])
        if sum(len(f) for f in found) >= max_pairs:
            break
    return np.concatenate(found)[:max_pairs]


def _edges_cross(edge_triangles: np.ndarray, target: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """Whether any edge of `edge_triangles[i]` passes through `target[i]`."""
    hit = np.zeros(len(target), dtype=bool)
    a, b, c = target[:, 0], target[:, 1], target[:, 2]
    e1, e2 = b - a, c - a
    for start, end in ((0, 1), (1, 2), (2, 0)):
        origin = edge_triangles[:, start]
        direction = edge_triangles[:, end] - origin
        pvec = np.cross(direction, e2)
        det = np.einsum("ij,ij->i", e1, pvec)
        scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(direction, axis=1)
        ok = np.abs(det) > eps * scale
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tvec = origin - a
        u = np.einsum("ij,ij->i", tvec, pvec) * inv
        qvec = np.cross(tvec, e1)
        v = np.einsum("ij,ij->i", direction, qvec) * inv
        t = np.einsum("ij,ij->i", e2, qvec) * inv
        hit |= ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > eps) & (t < 1 - eps)
    return hit


def check_surface(vertices, faces, source: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Check that a triangle surface can be meshed: finite, closed, consistently wound,
    not self-intersecting, enclosing a positive volume. Returns (vertices, faces)."""
    vertices = check_vertices(vertices, source)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 4:
        raise HydrotactError(f"{where(source)}a closed surface needs at least 4 triangles, got faces of shape {faces.shape}")
    triangles = vertices[faces]
    areas = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    if np.any(areas <= 1e-12 * areas.sum()):  # before the closedness test, which a degenerate triangle would fail
        k = int(np.argmin(areas))
        at = np.round(triangles[k].mean(axis=0), 9).tolist()
        raise HydrotactError(f"{where(source)}triangle {k} has zero area (vertices {faces[k].tolist()}, near {at}); remove degenerate triangles first")
    surface = trimesh.Trimesh(vertices, faces, process=True)
    if not surface.is_watertight:
        edges = surface.edges_sorted
        unique, counts = np.unique(edges, axis=0, return_counts=True)
        open_edges = unique[counts == 1]
        detail = f"{len(open_edges)} edges belong to one triangle only"
        if len(open_edges):
            detail += f", e.g. the edge at {np.round(surface.vertices[open_edges[0, 0]], 9).tolist()}"
        raise HydrotactError(f"{where(source)}the surface is not closed ({detail}); close its holes first")
    if not surface.is_winding_consistent:
        raise HydrotactError(f"{where(source)}the surface's triangles are not wound consistently")
    crossing = find_self_intersections(np.asarray(surface.vertices), np.asarray(surface.faces))
    if len(crossing):
        i, j = (int(k) for k in crossing[0])
        at = np.round(surface.vertices[surface.faces[i]].mean(axis=0), 9).tolist()
        raise HydrotactError(f"{where(source)}the surface intersects itself (triangles {i} and {j}, near {at})")
    if abs(surface.volume) <= 0:
        raise HydrotactError(f"{where(source)}the surface encloses no volume")
    if surface.volume < 0:
        surface.invert()
    return np.asarray(surface.vertices), np.asarray(surface.faces)
