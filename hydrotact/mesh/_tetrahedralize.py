"""Tetrahedral meshes of closed surfaces with fTetWild (pytetwild), cached by input."""

import contextlib
import tempfile
from importlib.metadata import version

import numpy as np

from .._errors import HydrotactError, where
from .._files import atomic_path, cache_dir, digest
from .._geometry import calc_distance_to_triangles
from ._primitives import TETS_PER_CUBE, check_tet_budget
from ._surface import check_surface
from ._tags import FaceSelection, Plane, make_face_tagger
from ._tetmesh import CORE, TetMesh, make_tet_mesh, orient_tets


def _face_set_selection(vertices, faces, face_set, source):
    """A predicate selecting output faces nearest to the given input faces."""
    face_set = np.asarray(face_set)
    if face_set.dtype == bool:
        if face_set.shape != (len(faces),):
            raise HydrotactError(f"{where(source)}the core face mask has shape {face_set.shape}, expected ({len(faces)},)")
        face_set = np.flatnonzero(face_set)
    face_set = face_set.astype(np.int64).reshape(-1)
    if face_set.size == 0:
        raise HydrotactError(f"{where(source)}the core face set is empty")
    if face_set.min() < 0 or face_set.max() >= len(faces):
        raise HydrotactError(f"{where(source)}core face indices must lie in [0, {len(faces)})")
    triangles = vertices[faces]
    in_set = np.zeros(len(faces), dtype=bool)
    in_set[face_set] = True

    def is_core(centroids):
        _, nearest = calc_distance_to_triangles(centroids, triangles)
        return in_set[np.asarray(nearest)]

    return is_core


def _run_tetwild(vertices, faces, edge_length, epsilon, use_cache):
    import pytetwild

    key = digest(
        np.ascontiguousarray(vertices, dtype=np.float64).tobytes(),
        np.ascontiguousarray(faces, dtype=np.int64).tobytes(),
        float(edge_length),
        float(epsilon),
        version("pytetwild"),
    )
    path = cache_dir() / "meshes" / f"{key}.npz"
    if use_cache and path.is_file():
        with np.load(path) as data:
            return data["vertices"], data["tets"]
    # fTetWild writes a scratch file (__tracked_surface.stl) into the working
    # directory: run it in a temporary one so users' folders stay clean.
    with tempfile.TemporaryDirectory(prefix="hydrotact-tetwild-") as scratch, contextlib.chdir(scratch):
        tet_vertices, tets = pytetwild.tetrahedralize(
            np.asarray(vertices, dtype=np.float64),
            np.asarray(faces, dtype=np.int32),
            edge_length_abs=float(edge_length),
            epsilon=float(epsilon),
            quiet=True,
        )
    if use_cache:
        with atomic_path(path) as tmp:
            np.savez_compressed(tmp, vertices=tet_vertices, tets=tets)
    return tet_vertices, tets


def tetrahedralize(
    surface,
    edge_length: float,
    *,
    core: FaceSelection | np.ndarray | None = None,
    insulated: FaceSelection | None = None,
    epsilon: float = 1e-3,
    use_cache: bool = True,
    source: str | None = None,
) -> TetMesh:
    """Fill a closed surface with tets (fTetWild) and tag its boundary (host).

    fTetWild may return a different mesh for the same input on another run, so the
    result is cached on disk under the hash of the input and the settings: the same
    surface and settings give the same mesh on this machine.

    **Arguments:**

    - `surface`: a `trimesh.Trimesh` or a (vertices, faces) pair, in metres.
    - `edge_length`: target tet edge length in metres (> 0).
    - `core`: the faces bonded to the PCB or an insert: a :class:`Plane`, a predicate on
      face centroids, or a face set (indices or a boolean mask over the input faces).
      None leaves every face `free` (give `core_depth` to the field solve then).
    - `insulated`: faces with no boundary condition (a Plane or a predicate).
    - `epsilon`: fTetWild's envelope, relative to the bounding-box diagonal: the output
      skin lies within epsilon * diagonal of the input.
    - `use_cache`: read and write the mesh cache.
    - `source`: the name used in error messages.
    """
    try:
        edge_length = float(edge_length)
    except (TypeError, ValueError):
        raise HydrotactError(f"{where(source)}edge length must be a number, got {edge_length!r}") from None
    if not np.isfinite(edge_length) or edge_length <= 0:
        raise HydrotactError(f"{where(source)}edge length must be a positive length in metres, got {edge_length:g}")
    input_vertices, input_faces = (
        (surface.vertices, surface.faces) if hasattr(surface, "faces") else surface
    )
    input_vertices = np.asarray(input_vertices, dtype=np.float64)
    input_faces = np.asarray(input_faces, dtype=np.int64)
    if core is not None and not isinstance(core, Plane) and not callable(core):
        core = _face_set_selection(np.asarray(input_vertices, float), input_faces, core, source)
    vertices, faces = check_surface(input_vertices, input_faces, source)
    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    if edge_length > diagonal:
        raise HydrotactError(
            f"{where(source)}edge length {edge_length:g} m exceeds the surface's size ({diagonal:.3g} m diagonal)"
        )
    volume = float(np.prod(vertices.max(axis=0) - vertices.min(axis=0)))
    check_tet_budget(TETS_PER_CUBE * volume / edge_length**3, edge_length, volume, f"a surface {diagonal * 1e3:.3g} mm across", source)
    tet_vertices, tets = _run_tetwild(vertices, faces, edge_length, epsilon, use_cache)
    if len(tets) == 0:
        raise HydrotactError(f"{where(source)}fTetWild produced no tets (is the surface too thin for edge length {edge_length:g} m?)")
    tets = orient_tets(tet_vertices, tets)
    tolerance = 2.0 * epsilon * diagonal

    def widen(selection):
        if isinstance(selection, Plane):
            return selection._replace(tolerance=max(selection.tolerance, tolerance))
        return selection

    core, insulated = widen(core), widen(insulated)
    mesh = make_tet_mesh(
        tet_vertices, tets, make_face_tagger(core, insulated, source=source), source=source
    )
    if isinstance(core, Plane):
        mesh = _snap_to_plane(mesh, core, source)
    return mesh


def _snap_to_plane(mesh: TetMesh, plane: Plane, source: str | None) -> TetMesh:
    """Project the vertices of the core faces exactly onto the core plane (re-checked)."""
    vertices = np.array(mesh.vertices)
    on_core = mesh.vertices_tagged(CORE)
    normal = np.asarray(plane.normal_S, dtype=np.float64)
    normal /= np.linalg.norm(normal)
    offset = (vertices[on_core] - np.asarray(plane.point_S)) @ normal
    vertices[on_core] -= offset[:, None] * normal
    tags = np.asarray(mesh.face_tags)
    return make_tet_mesh(vertices, mesh.tets, lambda faces, _: tags, source=source)
