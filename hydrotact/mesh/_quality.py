"""Mesh quality figures: counts, volume, dihedral angles, aspect ratios."""

import numpy as np

from ._tetmesh import CORE, FREE, INSULATED, TET_FACES, TetMesh, calc_signed_volumes

_EDGE_PAIRS = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])


def calc_dihedral_angles(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The six interior dihedral angles (radians) of each tet, shape (num_tets, 6).

    The angle at the edge shared by faces i and j is pi minus the angle between their
    outward normals.
    """
    p = vertices[tets]
    faces = p[:, TET_FACES]  # (T, 4, 3, 3)
    normals = np.cross(faces[:, :, 1] - faces[:, :, 0], faces[:, :, 2] - faces[:, :, 0])
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    # The edge (a, b) is shared by the faces opposite the two other vertices.
    pairs = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]])
    cosines = np.einsum("tij,tij->ti", normals[:, pairs[:, 0]], normals[:, pairs[:, 1]])
    return np.pi - np.arccos(np.clip(cosines, -1.0, 1.0))


def calc_radius_ratios(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Aspect ratio R / (3 r) of each tet (circumradius over three inradii): 1 for a
    regular tet, growing without bound as a tet flattens."""
    p = vertices[tets]
    volume = np.abs(calc_signed_volumes(vertices, tets))
    faces = p[:, TET_FACES]
    areas = 0.5 * np.linalg.norm(
        np.cross(faces[:, :, 1] - faces[:, :, 0], faces[:, :, 2] - faces[:, :, 0]), axis=-1
    ).sum(axis=1)
    inradius = 3.0 * volume / areas
    # Circumcentre c solves 2 (p_i - p_0) . c = |p_i|^2 - |p_0|^2 (relative to p_0).
    edges = p[:, 1:] - p[:, :1]
    rhs = 0.5 * np.sum(edges**2, axis=-1)
    centre = np.linalg.solve(edges, rhs[..., None])[..., 0]
    circumradius = np.linalg.norm(centre, axis=-1)
    return circumradius / (3.0 * inradius)


def calc_mesh_quality(mesh: TetMesh) -> dict:
    """Counts and quality figures of a mesh, as plain numbers (SI units, degrees)."""
    vertices = np.asarray(mesh.vertices)
    tets = np.asarray(mesh.tets)
    tags = np.asarray(mesh.face_tags)
    p = vertices[tets]
    edge_lengths = np.linalg.norm(p[:, _EDGE_PAIRS[:, 1]] - p[:, _EDGE_PAIRS[:, 0]], axis=-1)
    dihedral = np.degrees(calc_dihedral_angles(vertices, tets))
    ratios = calc_radius_ratios(vertices, tets)
    faces = vertices[np.asarray(mesh.boundary_faces)]
    face_areas = 0.5 * np.linalg.norm(np.cross(faces[:, 1] - faces[:, 0], faces[:, 2] - faces[:, 0]), axis=-1)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return {
        "num_vertices": int(len(vertices)),
        "num_tets": int(len(tets)),
        "num_boundary_faces": int(len(tags)),
        "num_free_faces": int(np.sum(tags == FREE)),
        "num_core_faces": int(np.sum(tags == CORE)),
        "num_insulated_faces": int(np.sum(tags == INSULATED)),
        "volume_m3": float(calc_signed_volumes(vertices, tets).sum()),
        "free_area_m2": float(face_areas[tags == FREE].sum()),
        "core_area_m2": float(face_areas[tags == CORE].sum()),
        "bounding_box_m": [lo.tolist(), hi.tolist()],
        "edge_length_m": {
            "min": float(edge_lengths.min()),
            "mean": float(edge_lengths.mean()),
            "max": float(edge_lengths.max()),
        },
        "min_dihedral_deg": float(dihedral.min()),
        "max_dihedral_deg": float(dihedral.max()),
        "worst_aspect_ratio": float(ratios.max()),
        "mean_aspect_ratio": float(ratios.mean()),
    }
