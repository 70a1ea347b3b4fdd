"""Reading and writing tet meshes: VTK XML (.vtu) and legacy ASCII VTK (.vtk).

The .vtu goes through pyvista; the legacy ASCII .vtk through meshio, which writes every
coordinate at full double precision (VTK's own legacy writer keeps 11 digits), so
Drake loads exactly the mesh hydrotact has. The .vtk holds points and tetrahedra
only, which is what Drake's `Mesh` shape loads as a compliant hydroelastic geometry. The .vtu file
also keeps the boundary faces and their tags (as field data) and any point fields
(the strain, the pressure), so hydrotact can read its own meshes back unchanged.
"""

import contextlib
import io
from pathlib import Path

import meshio
import numpy as np
import pyvista as pv

from .._errors import HydrotactError
from .._files import atomic_path
from ._tags import Plane, make_face_tagger
from ._tetmesh import TetMesh, make_tet_mesh

VTK_TETRA = 10
MESH_SUFFIXES = (".vtu", ".vtk")


def to_pyvista(mesh: TetMesh, point_data: dict | None = None, scale: float = 1.0) -> pv.UnstructuredGrid:
    """The mesh as a pyvista UnstructuredGrid of tetrahedra, with optional point data;
    coordinates multiplied by `scale` (1e3 for millimetres)."""
    tets = np.asarray(mesh.tets)
    cells = np.column_stack([np.full(len(tets), 4), tets]).reshape(-1)
    grid = pv.UnstructuredGrid(cells, np.full(len(tets), VTK_TETRA, dtype=np.uint8), np.asarray(mesh.vertices, dtype=np.float64) * scale)
    for name, values in (point_data or {}).items():
        grid.point_data[name] = np.asarray(values)
    return grid


def write_mesh(mesh: TetMesh, path, point_data: dict | None = None) -> Path:
    """Write `mesh` to `path` (.vtu: with tags and point data; .vtk: legacy ASCII for
    Drake), atomically. Returns the path."""
    path = Path(path)
    if path.suffix not in MESH_SUFFIXES:
        raise HydrotactError(f"{path}: mesh files must end in .vtu or .vtk")
    if path.suffix == ".vtk":
        legacy = meshio.Mesh(np.asarray(mesh.vertices, dtype=np.float64), [("tetra", np.asarray(mesh.tets, dtype=np.int64))])
        with atomic_path(path) as tmp, contextlib.redirect_stderr(io.StringIO()):  # meshio's "ASCII is for debugging" notice
            meshio.write(str(tmp), legacy, file_format="vtk42", binary=False)
        return path
    grid = to_pyvista(mesh, point_data)
    grid.field_data["boundary_faces"] = np.asarray(mesh.boundary_faces, dtype=np.int64)
    grid.field_data["face_tags"] = np.asarray(mesh.face_tags, dtype=np.int64)
    with atomic_path(path) as tmp:
        grid.save(str(tmp), binary=True)
    return path


def read_mesh(path, core: Plane | None = None) -> tuple[TetMesh, dict]:
    """Read a tet mesh (.vtu or .vtk) and its point data (host).

    Face tags come from the file when hydrotact wrote it; otherwise faces on `core`
    (default: the plane z = min z, the PCB) are tagged core and the rest free.
    """
    path = Path(path)
    if not path.is_file():
        raise HydrotactError(f"{path}: no such file")
    try:
        grid = pv.read(str(path))
    except Exception as error:  # VTK readers raise several kinds
        raise HydrotactError(f"{path}: cannot read as a VTK mesh ({error})") from None
    if not isinstance(grid, pv.UnstructuredGrid):
        grid = grid.cast_to_unstructured_grid()
    cell_types = np.asarray(grid.celltypes)
    if grid.n_cells == 0 or np.any(cell_types != VTK_TETRA):
        others = sorted(set(cell_types.tolist()) - {VTK_TETRA})
        raise HydrotactError(f"{path}: only tetrahedral meshes are supported (found VTK cell types {others or 'none'})")
    tets = np.asarray(grid.cells_dict[VTK_TETRA], dtype=np.int64)
    vertices = np.asarray(grid.points, dtype=np.float64)
    if "face_tags" in grid.field_data and "boundary_faces" in grid.field_data:
        stored_faces = np.asarray(grid.field_data["boundary_faces"]).reshape(-1, 3)
        stored_tags = np.asarray(grid.field_data["face_tags"]).reshape(-1)
        lookup = {tuple(sorted(f)): t for f, t in zip(stored_faces.tolist(), stored_tags.tolist())}

        def face_tags(faces, _):
            try:
                return np.array([lookup[tuple(sorted(f))] for f in faces.tolist()])
            except KeyError:
                raise HydrotactError(f"{path}: the stored face tags do not match the mesh's boundary") from None

    else:
        finite_z = vertices[np.all(np.isfinite(vertices), axis=1), 2]
        plane = core or Plane((0.0, 0.0, float(finite_z.min()) if finite_z.size else 0.0), tolerance=1e-9)
        face_tags = make_face_tagger(core=plane, source=str(path), require_core=False)
    mesh = make_tet_mesh(vertices, tets, face_tags, source=str(path))
    point_data = {name: np.asarray(grid.point_data[name]) for name in grid.point_data.keys()}
    return mesh, point_data
