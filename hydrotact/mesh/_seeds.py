"""The three seed elastomers: pad5x5, sphere8 and ellipsoid8.

Geometry (metres, sensor frame S: the PCB is the plane z = 0, +z is the pad normal):

- `pad5x5`: the flat silicone block over the 5 x 5 BMP388 grid of the hydroelastic
  tactile paper (2.2 mm pitch). Its footprint is 13.2 mm square (the grid spans
  8.8 mm between outer cell centres, plus a 2.2 mm rim) and it is 4 mm thick; the
  papers give neither, so these are our choices. Bottom face bonded (core).
- `sphere8`: the cast sphere of the barometric estimation paper, radius 10 mm; a
  three-quarter sphere, i.e. its centre is R/2 = 5 mm above the PCB and the PCB cuts
  off the lowest quarter of its height. Flat base bonded (core).
- `ellipsoid8`: semi-axes a = 10.7 mm (x), b = 9 mm (y), c = 6.8 mm (z), cut the
  same way (centre c/2 = 3.4 mm above the PCB). Flat base bonded (core).

The pad is meshed by a deterministic structured grid. The curved ones are meshed by
fTetWild, which is not reproducible run to run, so their meshes at the default edge
length ship with the package (made once by `python -m hydrotact.mesh._seeds`, with a
SHA-256 checksum checked on load); other edge lengths are meshed on demand and cached.
"""

import json
import sys
from importlib.resources import files

import numpy as np

from .._errors import HydrotactError
from .._files import atomic_path, digest, write_text_atomic
from ._primitives import make_box, make_truncated_ellipsoid_surface
from ._tags import Plane
from ._tetmesh import TetMesh, make_tet_mesh
from ._tetrahedralize import tetrahedralize

SEED_SENSORS = {
    "pad5x5": {
        "shape": "box",
        "size_m": (13.2e-3, 13.2e-3, 4.0e-3),
        "edge_length_m": 0.55e-3,
    },
    "sphere8": {
        "shape": "truncated_ellipsoid",
        "semi_axes_m": (10e-3, 10e-3, 10e-3),
        "center_height_m": 5e-3,
        "edge_length_m": 1.2e-3,
    },
    "ellipsoid8": {
        "shape": "truncated_ellipsoid",
        "semi_axes_m": (10.7e-3, 9e-3, 6.8e-3),
        "center_height_m": 3.4e-3,
        "edge_length_m": 1.0e-3,
    },
}
_DATA = files("hydrotact.mesh") / "data"


def _mesh_digest(vertices, tets, face_tags) -> str:
    return digest(
        np.ascontiguousarray(vertices, dtype=np.float64).tobytes(),
        np.ascontiguousarray(tets, dtype=np.int64).tobytes(),
        np.ascontiguousarray(face_tags, dtype=np.int64).tobytes(),
    )


def seed_surface(name: str):
    """The closed surface (vertices, faces) of a curved seed sensor, in metres."""
    spec = SEED_SENSORS[name]
    return make_truncated_ellipsoid_surface(spec["semi_axes_m"], spec["center_height_m"], num_rings=48)


def _load_shipped(name: str) -> TetMesh:
    checksums = json.loads((_DATA / "checksums.json").read_text())
    with (_DATA / f"{name}.npz").open("rb") as handle, np.load(handle) as data:
        vertices, tets, tags = data["vertices"], data["tets"], data["face_tags"]
    if _mesh_digest(vertices, tets, tags) != checksums[name]:
        raise HydrotactError(f"the shipped mesh of {name} does not match its checksum: reinstall hydrotact")
    return make_tet_mesh(vertices, tets, lambda faces, _: tags, source=name)


def make_seed_mesh(name: str, edge_length: float | None = None) -> TetMesh:
    """The tet mesh of a seed sensor ("pad5x5", "sphere8", "ellipsoid8").

    `edge_length` (metres) defaults to the shipped resolution.
    """
    if name not in SEED_SENSORS:
        raise HydrotactError(f"unknown sensor {name!r}; the built-in ones are {sorted(SEED_SENSORS)}")
    spec = SEED_SENSORS[name]
    if spec["shape"] == "box":
        return make_box(spec["size_m"], spec["edge_length_m"] if edge_length is None else edge_length, source=name)
    if edge_length is None or float(edge_length) == spec["edge_length_m"]:
        return _load_shipped(name)
    return tetrahedralize(seed_surface(name), edge_length, core=Plane((0.0, 0.0, 0.0)), source=name)


def regenerate_shipped_meshes() -> None:
    """Mesh the curved seeds at their default edge length and write package data."""
    directory = _DATA
    checksums = {}
    for name, spec in SEED_SENSORS.items():
        if spec["shape"] == "box":
            continue
        mesh = tetrahedralize(
            seed_surface(name), spec["edge_length_m"], core=Plane((0.0, 0.0, 0.0)), use_cache=False, source=name
        )
        vertices, tets, tags = (np.asarray(a) for a in (mesh.vertices, mesh.tets, mesh.face_tags))
        with atomic_path(directory / f"{name}.npz") as tmp:
            np.savez_compressed(tmp, vertices=vertices, tets=tets.astype(np.int32), face_tags=tags.astype(np.int8))
        checksums[name] = _mesh_digest(vertices, tets, tags)
        print(f"{name}: {len(tets)} tets, {len(vertices)} vertices")
    write_text_atomic(directory / "checksums.json", json.dumps(checksums, indent=2) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        sys.exit("usage: python -m hydrotact.mesh._seeds --regenerate")
    regenerate_shipped_meshes()
