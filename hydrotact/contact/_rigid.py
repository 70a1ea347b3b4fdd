"""Rigid bodies as closed triangle surfaces, and the built-in probes.

A rigid surface lives in its own frame R. Built-in probes follow one convention: the
probe's tip touches R's origin and its body extends along +z, so a probe pressing
straight down onto a sensor whose top is at height h, to depth d, sits at
X_SR = (identity, (x, y, h - d)). The half-space probe is the same: rigid material
fills z >= 0 of R, its face the plane z = 0 with outward normal -z.
"""

import equinox as eqx
import numpy as np
import trimesh

from .._errors import HydrotactError
from .._files import atomic_path
from .._types import Array, Float, Int
from ..mesh import check_surface


class RigidSurface(eqx.Module):
    """A closed, outward-wound triangle surface of a rigid body, in its frame R.

    **Fields:**

    - `vertices_R`: (num_vertices, 3) in metres.
    - `faces`: (num_faces, 3), counter-clockwise seen from outside.
    """

    vertices_R: Float[Array, "num_vertices 3"]
    faces: Int[Array, "num_faces 3"]

    @property
    def num_faces(self) -> int:
        return self.faces.shape[0]

    def to_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(np.asarray(self.vertices_R), np.asarray(self.faces), process=False)

    def write_obj(self, path) -> None:
        """Write the surface as OBJ with every coordinate at full double precision
        (trimesh's default keeps 8 decimals, 10 nm: too coarse to compare with Drake)."""
        with atomic_path(path) as tmp:
            self.to_trimesh().export(str(tmp), file_type="obj", digits=17)


class HalfSpace(eqx.Module):
    """The rigid half-space z >= 0 of frame R (a flat plate pressing along -z of R).

    It has no fields: its pose says where it is. Contact with it takes the fast path
    that slices tets by the plane instead of clipping triangles.
    """


def make_rigid_surface(surface, source: str | None = None) -> RigidSurface:
    """A rigid surface from a trimesh or (vertices, faces), checked closed (host)."""
    vertices, faces = (surface.vertices, surface.faces) if hasattr(surface, "faces") else surface
    vertices, faces = check_surface(vertices, faces, source)
    return RigidSurface(vertices_R=np.asarray(vertices, dtype=np.float64), faces=np.asarray(faces, dtype=np.int64))


def _positive(name, value):
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise HydrotactError(f"probe {name} must be a positive length in metres, got {value!r}")
    return value


def make_cylinder_probe(diameter: float, length: float | None = None, num_sides: int = 48) -> RigidSurface:
    """A flat-ended cylinder (the 5x5-array probe is 2 mm across), tip face on z = 0,
    axis along +z; `length` defaults to 5 diameters."""
    radius = _positive("diameter", diameter) / 2
    length = 5 * 2 * radius if length is None else _positive("length", length)
    if num_sides < 3:
        raise HydrotactError(f"a cylinder needs at least 3 sides, got {num_sides}")
    angles = np.linspace(0.0, 2 * np.pi, num_sides, endpoint=False)
    ring = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    bottom = np.column_stack([ring, np.zeros(num_sides)])
    top = np.column_stack([ring, np.full(num_sides, length)])
    vertices = np.concatenate([bottom, top, [[0, 0, 0], [0, 0, length]]])
    i = np.arange(num_sides)
    j = (i + 1) % num_sides
    centre_bottom, centre_top = 2 * num_sides, 2 * num_sides + 1
    faces = np.concatenate(
        [
            np.column_stack([np.full(num_sides, centre_bottom), j, i]),  # tip face, normal -z
            np.column_stack([np.full(num_sides, centre_top), num_sides + i, num_sides + j]),
            np.column_stack([i, j, num_sides + j]),
            np.column_stack([i, num_sides + j, num_sides + i]),
        ]
    )
    return make_rigid_surface((vertices, faces), source="cylinder probe")


def make_sphere_probe(radius: float, subdivisions: int = 3) -> RigidSurface:
    """A sphere (icosphere) of `radius` whose lowest point is R's origin."""
    radius = _positive("radius", radius)
    surface = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    surface.apply_translation([0.0, 0.0, radius])
    return make_rigid_surface(surface, source="sphere probe")


def make_box_probe(size: tuple[float, float, float]) -> RigidSurface:
    """A box with the given edge lengths, its bottom face centred on R's origin."""
    size = [_positive("box size", s) for s in size]
    surface = trimesh.creation.box(extents=size)
    surface.apply_translation([0.0, 0.0, size[2] / 2])
    return make_rigid_surface(surface, source="box probe")
