"""Probes: the rigid bodies pressed into a sensor, and the spec strings that name them.

Every probe is an :class:`AbstractProbe`: a frozen pytree that computes its own
contact surface with a soft body (:meth:`AbstractProbe.calc_contact_surface`) and
carries a `spec` string that :func:`parse_probe` turns back into an equal probe:
'cylinder:d=2mm[,length=10mm][,sides=48]', 'sphere:r=3mm[,subdivisions=3]',
'box:x=4mm,y=4mm,z=2mm' (:class:`RigidSurface`, closed triangle surfaces) and
'plane' (:class:`HalfSpace`). Lengths take any unit of `hydrotact._units`.

A probe lives in its own frame R. Built-in probes follow one convention: the
probe's tip touches R's origin and its body extends along +z, so a probe pressing
straight down onto a sensor whose top is at height h, to depth d, sits at
X_SR = (identity, (x, y, h - d)). The half-space probe is the same: rigid material
fills z >= 0 of R, its face the plane z = 0 with outward normal -z.
"""

import abc

import equinox as eqx
import numpy as np
import trimesh

from .._errors import HydrotactError
from .._files import atomic_path
from .._types import Array, Float, Int
from .._units import format_length, parse_length
from ..field import PressureField
from ..mesh import check_surface
from ._broadphase import Capacity, TetClusters
from ._half_space import calc_half_space_surface
from ._pose import Pose
from ._soft_rigid import calc_soft_rigid_surface
from ._surface import ContactSurface

CYLINDER_SIDES = 48
SPHERE_SUBDIVISIONS = 3
PIECE_LENGTH = 0.5
"""The longest piece of a built-in probe's flat faces, in units of its middle extent
(a cylinder's diameter, a box's middle edge): the side wall of the 2 mm cylinder is
rings 1 mm high, a 4 x 4 x 2 mm box's faces a grid of 2 mm squares. Smaller pieces
give the broad phase tighter boxes (fewer candidate pairs) and more triangles to
transform and test; the end faces' fans (edges half a diameter) set the scale."""


class AbstractProbe(eqx.Module):
    """A rigid probe (abstract): a body in its frame R whose contact with a soft body
    it computes itself.

    **Fields:**

    - `spec`: the probe's spec string (static), which :func:`parse_probe` reads back
      as an equal probe; '' for a probe not made from one (a loaded mesh).
    """

    spec: eqx.AbstractVar[str]

    @abc.abstractmethod
    def calc_contact_surface(
        self, soft: PressureField, X_SR: Pose, capacity: Capacity = Capacity(), clusters: TetClusters | None = None
    ) -> ContactSurface:
        """The contact surface of the soft body `soft` (frame S) and this probe at pose
        X_SR (pure; jittable, vmappable over X_SR, differentiable).

        Normals point out of the probe, the direction of the force on the soft body.

        **Arguments:**

        - `soft`: the soft body's pressure field, frame S.
        - `X_SR`: the probe's pose in S.
        - `capacity`: the broad phase's buffer sizes (static); check
          `.did_overflow` on the result, or use
          :func:`hydrotact.contact.compute_contact_surface`, which grows them.
        - `clusters`: from :func:`make_tet_clusters` on the soft mesh, for a
          hierarchical tet search.

        **Returns:** a :class:`ContactSurface` in frame S.
        """


class RigidSurface(AbstractProbe):
    """A closed, outward-wound triangle surface of a rigid body, in its frame R.

    Contact with it clips the rigid triangles by the soft tets
    (:func:`calc_soft_rigid_surface`).

    **Fields:**

    - `vertices_R`: (num_vertices, 3) in metres.
    - `faces`: (num_faces, 3), counter-clockwise seen from outside.
    - `spec`: the spec it was made from (static), '' for any other surface.
    """

    vertices_R: Float[Array, "num_vertices 3"]
    faces: Int[Array, "num_faces 3"]
    spec: str = eqx.field(static=True, default="")

    def calc_contact_surface(
        self, soft: PressureField, X_SR: Pose, capacity: Capacity = Capacity(), clusters: TetClusters | None = None
    ) -> ContactSurface:
        return calc_soft_rigid_surface(soft, self, X_SR, capacity, clusters=clusters)

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


class HalfSpace(AbstractProbe):
    """The rigid half-space z >= 0 of frame R (a flat plate pressing along -z of R),
    spec 'plane'.

    It has no fields: its pose says where it is. Contact with it takes the fast path
    that slices tets by the plane instead of clipping triangles
    (:func:`calc_half_space_surface`).
    """

    @property
    def spec(self) -> str:
        return "plane"

    def calc_contact_surface(
        self, soft: PressureField, X_SR: Pose, capacity: Capacity = Capacity(), clusters: TetClusters | None = None
    ) -> ContactSurface:
        return calc_half_space_surface(soft, X_SR, capacity, clusters=clusters)


def make_rigid_surface(surface, source: str | None = None, spec: str = "") -> RigidSurface:
    """A rigid surface from a trimesh or (vertices, faces), checked closed (host);
    `spec` is the spec string it was made from, if any."""
    vertices, faces = (surface.vertices, surface.faces) if hasattr(surface, "faces") else surface
    vertices, faces = check_surface(vertices, faces, source)
    return RigidSurface(vertices_R=np.asarray(vertices, dtype=np.float64), faces=np.asarray(faces, dtype=np.int64), spec=spec)


def _positive(name, value):
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise HydrotactError(f"probe {name} must be a positive length in metres, got {value!r}")
    return value


def make_cylinder_probe(diameter: float, length: float | None = None, num_sides: int = CYLINDER_SIDES) -> RigidSurface:
    """A flat-ended cylinder (the 5x5-array probe is 2 mm across), tip face on z = 0,
    axis along +z; `length` defaults to 5 diameters. Spec
    'cylinder:d=2mm[,length=10mm][,sides=48]'.

    The end faces are fans of `num_sides` triangles from their centres; the side wall
    is a stack of rings, none longer than :data:`PIECE_LENGTH` diameters, each ring
    `num_sides` quads split into two triangles. A wall of single full-length
    triangles is the same surface, but a tilted probe's long triangles have boxes
    that reach far into the soft body, and the broad phase pairs each with every tet
    in its box.
    """
    spec = f"cylinder:d={format_length(_positive('diameter', diameter))}"
    spec += "" if length is None else f",length={format_length(_positive('length', length))}"
    spec += "" if num_sides == CYLINDER_SIDES else f",sides={num_sides}"
    radius = _positive("diameter", diameter) / 2
    length = 5 * 2 * radius if length is None else _positive("length", length)
    if num_sides < 3:
        raise HydrotactError(f"a cylinder needs at least 3 sides, got {num_sides}")
    num_rings = int(np.ceil(length / (PIECE_LENGTH * 2 * radius) - 1e-9))
    angles = np.linspace(0.0, 2 * np.pi, num_sides, endpoint=False)
    ring = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    heights = np.linspace(0.0, length, num_rings + 1)
    heights[-1] = length
    rings = [np.column_stack([ring, np.full(num_sides, z)]) for z in heights]
    vertices = np.concatenate([*rings, [[0, 0, 0], [0, 0, length]]])
    i = np.arange(num_sides)
    j = (i + 1) % num_sides
    centre_bottom, centre_top = (num_rings + 1) * num_sides, (num_rings + 1) * num_sides + 1
    top = num_rings * num_sides
    walls = []
    for level in range(num_rings):
        low, high = level * num_sides, (level + 1) * num_sides
        walls += [np.column_stack([low + i, low + j, high + j]), np.column_stack([low + i, high + j, high + i])]
    faces = np.concatenate(
        [
            np.column_stack([np.full(num_sides, centre_bottom), j, i]),  # tip face, normal -z
            np.column_stack([np.full(num_sides, centre_top), top + i, top + j]),
            *walls,
        ]
    )
    return make_rigid_surface((vertices, faces), source="cylinder probe", spec=spec)


def make_sphere_probe(radius: float, subdivisions: int = SPHERE_SUBDIVISIONS) -> RigidSurface:
    """A sphere (icosphere) of `radius` whose lowest point is R's origin. Spec
    'sphere:r=3mm[,subdivisions=3]'."""
    radius = _positive("radius", radius)
    spec = f"sphere:r={format_length(radius)}"
    spec += "" if subdivisions == SPHERE_SUBDIVISIONS else f",subdivisions={subdivisions}"
    surface = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    surface.apply_translation([0.0, 0.0, radius])
    return make_rigid_surface(surface, source="sphere probe", spec=spec)


def make_box_probe(size: tuple[float, float, float]) -> RigidSurface:
    """A box with the given edge lengths (x, y, z), its bottom face centred on R's
    origin. Spec 'box:x=4mm,y=4mm,z=2mm'.

    Each face is a grid of squares split into two triangles each, the grid's pieces
    no longer than :data:`PIECE_LENGTH` times the box's middle edge length (a 4 x 4 x
    2 mm box: 2 x 2 squares of 2 mm on its 4 x 4 mm faces, 2 x 1 on the others): the same surface as two
    triangles a face, but a box pressed edge or corner first then pairs each tet
    only with the pieces near it (see :func:`make_cylinder_probe`).
    """
    size = [_positive("box size", s) for s in size]
    spec = "box:" + ",".join(f"{axis}={format_length(s)}" for axis, s in zip("xyz", size))
    piece = PIECE_LENGTH * sorted(size)[1]
    counts = [int(np.ceil(s / piece - 1e-9)) for s in size]
    ticks = [np.linspace(-s / 2, s / 2, n + 1) for s, n in zip(size, counts)]
    vertices, faces = [], []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3  # (u, v, axis) right-handed
        for side in (-1.0, 1.0):
            grid_u, grid_v = np.meshgrid(ticks[u], ticks[v], indexing="ij")
            points = np.zeros(grid_u.shape + (3,))
            points[..., u], points[..., v], points[..., axis] = grid_u, grid_v, side * size[axis] / 2
            index = len(vertices) + np.arange(grid_u.size).reshape(grid_u.shape)
            vertices += points.reshape(-1, 3).tolist()
            a, b, c, d = index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]
            quads = [a, b, c, d] if side > 0 else [a, d, c, b]  # counter-clockwise seen from outside
            faces += np.stack([quads[0], quads[1], quads[2]], axis=-1).reshape(-1, 3).tolist()
            faces += np.stack([quads[0], quads[2], quads[3]], axis=-1).reshape(-1, 3).tolist()
    surface = trimesh.Trimesh(np.asarray(vertices), np.asarray(faces), process=True)  # merges the shared edges' vertices
    surface.apply_translation([0.0, 0.0, size[2] / 2])
    return make_rigid_surface(surface, source="box probe", spec=spec)


_COUNTS = {"sides", "subdivisions"}  # options that are whole numbers, not lengths


def _read_count(key: str, value: str) -> int:
    try:
        return int(value.strip())
    except ValueError:
        raise HydrotactError(f"--probe {key}: cannot read {value!r} as a whole number") from None


MAX_PROBE_SIZE = 0.1
"""The largest probe length (m) a probe spec may give: beyond it a bare number was
surely meant in mm."""


def parse_probe(spec: str) -> AbstractProbe:
    """The probe a spec string names (host): 'cylinder:d=2mm[,length=10mm][,sides=48]',
    'sphere:r=3mm[,subdivisions=3]', 'box:x=4mm,y=4mm,z=2mm' or 'plane'.

    Lengths read as :func:`hydrotact._units.parse_length` does (a bare number is
    metres). `parse_probe(probe.spec)` gives back a probe equal to `probe`.

    **Returns:** a :class:`RigidSurface` or a :class:`HalfSpace`.

    **Raises:** :class:`HydrotactError` naming the spec (or the option at fault).
    """
    kind, _, rest = spec.partition(":")
    unknown = f"--probe: unknown probe {spec!r}; use cylinder:d=2mm, sphere:r=3mm, box:x=4mm,y=4mm,z=2mm or plane"
    if kind not in ("plane", "cylinder", "sphere", "box"):
        raise HydrotactError(unknown)
    options = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        key = key.strip()
        options[key] = _read_count(key, value) if key in _COUNTS else parse_length(value, f"--probe {key}")
        if key not in _COUNTS and not 0.0 < options[key] <= MAX_PROBE_SIZE:
            problem = "must be positive" if not options[key] > 0.0 else f"is no tactile probe (over {MAX_PROBE_SIZE:g} m; a bare number is metres: write {key}={value.strip()}mm?)"
            raise HydrotactError(f"--probe {key}: {options[key]:g} m {problem}")
    if kind == "plane" and not options:
        return HalfSpace()
    if kind == "cylinder" and set(options) <= {"d", "length", "sides"} and "d" in options:
        return make_cylinder_probe(options["d"], options.get("length"), options.get("sides", CYLINDER_SIDES))
    if kind == "sphere" and {"r"} <= set(options) <= {"r", "subdivisions"}:
        return make_sphere_probe(options["r"], options.get("subdivisions", SPHERE_SUBDIVISIONS))
    if kind == "box" and set(options) == {"x", "y", "z"}:
        return make_box_probe((options["x"], options["y"], options["z"]))
    raise HydrotactError(unknown)
