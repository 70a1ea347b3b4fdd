"""A tet mesh from what a user names: a built-in sensor, a closed surface file or a
tet mesh file."""

from pathlib import Path

import numpy as np

from .._errors import HydrotactError
from .._units import LENGTH_UNITS
from ._io import MESH_SUFFIXES, read_mesh
from ._mould import make_mould_cavity
from ._seeds import SEED_SENSORS, make_seed_mesh
from ._surface import SURFACE_SUFFIXES, load_surface
from ._tags import Plane
from ._tetmesh import TetMesh
from ._tetrahedralize import tetrahedralize


def load_tet_mesh(
    spec: str | list,
    *,
    edge_length: float | None = None,
    units: str = "m",
    core_plane_z: float | None = None,
    board: str = "zmin",
) -> TetMesh:
    """A tet mesh from a seed sensor name, a closed surface file, a mesh file, or a
    mould (`spec` a list of a mould's part files: the elastomer is its cavity, see
    :func:`make_mould_cavity`, with the cavity's `board` side on the board).

    Surfaces are meshed by fTetWild with their core on the plane z = `core_plane_z`
    (default: the lowest z of the surface, where it sits on the PCB). `edge_length`,
    `core_plane_z` and a surface file's coordinates are in `units`.
    """
    if units not in LENGTH_UNITS:
        raise HydrotactError(f"--units: unknown length unit {units!r}; use one of {', '.join(LENGTH_UNITS)}")
    if edge_length is not None:
        edge_length = float(edge_length) * LENGTH_UNITS[units]
    if isinstance(spec, list | tuple):
        surface, _ = make_mould_cavity(spec, units=units, board=board)
        source = f"the cavity of {', '.join(map(str, spec))}"
        return _mesh_surface(surface, edge_length, units, core_plane_z, source)
    if spec in SEED_SENSORS:
        return make_seed_mesh(spec, edge_length)
    path = Path(spec)
    suffix = path.suffix.lower()
    if suffix in MESH_SUFFIXES:
        if edge_length is not None:
            raise HydrotactError(f"{path}: --edge-length applies to sensors and surfaces, not to an existing tet mesh")
        core = None if core_plane_z is None else Plane((0.0, 0.0, core_plane_z), tolerance=1e-9)
        return read_mesh(path, core=core)[0]
    if suffix in SURFACE_SUFFIXES:
        return _mesh_surface(load_surface(path, units), edge_length, units, core_plane_z, str(path))
    if path.exists():
        raise HydrotactError(
            f"{path}: unknown file type {suffix!r}; give a surface ({', '.join(SURFACE_SUFFIXES)}) "
            f"or a tet mesh ({', '.join(MESH_SUFFIXES)})"
        )
    raise HydrotactError(f"{spec}: neither a built-in sensor ({', '.join(SEED_SENSORS)}) nor an existing file")


def _mesh_surface(surface, edge_length: float | None, units: str, core_plane_z: float | None, source: str) -> TetMesh:
    lo, hi = surface.bounds
    if edge_length is None:
        edge_length = float(np.linalg.norm(hi - lo)) / 20.0
    z = float(lo[2]) if core_plane_z is None else core_plane_z * LENGTH_UNITS[units]
    return tetrahedralize(surface, edge_length, core=Plane((0.0, 0.0, z)), source=source)
