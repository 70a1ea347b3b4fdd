"""Sensor specs: a JSON document (data_schemas/sensor.schema.json) read into SI units.

A spec says what the elastomer is (a built-in seed or a closed surface file), which
barometer part every taxel is, where each barometer's sensing port sits in frame S
(the PCB is the plane z = 0, +z the pad normal), which way it senses (its axis, from
the port into the elastomer) and how its receptive field is sampled: a disk of
parallel rays (flat arrays) or a cone of rays fanning from the port (curved sensors).
"""

import dataclasses
import functools
import json
import math
from importlib.resources import files
from pathlib import Path

import numpy as np

from .._defaults import DEFAULT_POISSON_RATIO, DEFAULT_PORT_RADIUS
from .._errors import HydrotactError
from .._schemas import format_path, load_schema, parse_json, read_json, validate
from .._units import LENGTH_UNITS, UNITS
from ..mesh import SEED_SENSORS, SURFACE_SUFFIXES, TetMesh, load_surface, load_tet_mesh, make_mould_cavity, make_seed_mesh, seed_surface
from ._builtins import BUILTIN_SENSORS
from ._inside import find_points_outside_surface, find_points_outside_tets

_DATA = files("hydrotact.sensors") / "data"
# The length units a sensor file may use (its schema lists the same ones).
LENGTH_SCALES = {name: LENGTH_UNITS[name] for name in ("m", "mm", "um")}
ANGLE_SCALES = UNITS["angle"]
# A port on the elastomer's boundary counts as inside: the surface check allows this
# fraction of the bounding-box diagonal (round-off), the tet-mesh check fTetWild's
# default envelope (1e-3 of the diagonal: its skin may move that far from the input).
_SURFACE_TOLERANCE = 1e-6
_MESH_TOLERANCE = 1e-3


@dataclasses.dataclass(frozen=True)
class Part:
    """A barometer part: resolution, noise, output rate and range (Pa, Hz)."""

    name: str
    lsb_pa: float
    noise_rms_pa: float
    rate_hz: float
    range_pa: tuple[float, float]
    ambient_pa: float
    description: str = ""

    def to_json(self) -> dict:
        document = {
            "name": self.name,
            "lsb_pa": self.lsb_pa,
            "noise_rms_pa": self.noise_rms_pa,
            "rate_hz": self.rate_hz,
            "range_pa": list(self.range_pa),
            "ambient_pa": self.ambient_pa,
        }
        if self.description:
            document["description"] = self.description
        return document


@dataclasses.dataclass(frozen=True)
class Geometry:
    """Where the elastomer comes from, in SI units.

    `kind` "seed": the built-in elastomer `seed` (at `edge_length` metres, or the
    shipped resolution when None). `kind` "surface": the closed surface file `path`
    (absolute; coordinates in `surface_units`) meshed at `edge_length` metres with the
    faces on z = `core_plane_z` metres bonded. `kind` "mould": the cavity of the mould
    whose part files are `paths` (absolute; coordinates in `surface_units`), its
    `board` side down on z = 0 (`core_plane_z`), bonded there
    (:func:`hydrotact.mesh.make_mould_cavity`).
    """

    kind: str
    seed: str | None = None
    path: str | None = None
    surface_units: str = "m"
    core_plane_z: float | None = None
    edge_length: float | None = None
    paths: tuple[str, ...] | None = None
    board: str = "zmin"

    def to_json(self) -> dict:
        if self.kind == "seed":
            document = {"kind": "seed", "seed": self.seed}
            if self.edge_length is not None:
                document["edge_length"] = self.edge_length
            return document
        if self.kind == "mould":
            return {"kind": "mould", "paths": list(self.paths), "mould_units": self.surface_units, "board": self.board, "edge_length": self.edge_length}
        return {
            "kind": "surface",
            "path": self.path,
            "surface_units": self.surface_units,
            "core_plane_z": self.core_plane_z,
            "edge_length": self.edge_length,
        }


@dataclasses.dataclass(frozen=True, eq=False)
class SensorSpec:
    """A barometric tactile sensor, in SI units (host-side data, numpy arrays).

    Build it with :func:`load_sensor`. Arrays are read-only; specs compare by identity
    (compare `to_json()` documents for equality).

    **Fields:**

    - `name`, `description`: from the document; `source`: the file it was read from,
      or "built-in NAME".
    - `geometry`: the elastomer (:class:`Geometry`); `part`: the barometer (:class:`Part`).
    - `taxel_names`: (n,) channel names, in channel order.
    - `taxel_positions_S`: (n, 3) sensing ports, metres, frame S.
    - `taxel_axes_S`: (n, 3) unit sensing axes, from the port into the elastomer.
    - `taxel_field_kinds`: (n,) "disk", "cone" or "elastic".
    - `taxel_field_sizes`: (n,) disk radius (m), cone half-angle (rad) or an elastic
      barometer's port radius (m).
    - `taxel_elastic_readings`: (n,) what an elastic barometer reads, "pressure" or
      "normal_stress" ("pressure" for the others, where it means nothing).
    - `poisson_ratio`: the elastomer's nu, for the elastic barometers.
    - `contact_center_S`: (3,) the point contact angles are measured from, or None;
      `theta_range`, `phi_range`: (low, high) in rad, or None. For the unit vector n
      from the centre to the contact point, theta = asin(-n_y), phi = atan2(n_x, n_z).
    """

    name: str
    description: str
    source: str
    geometry: Geometry
    part: Part
    taxel_names: tuple[str, ...]
    taxel_positions_S: np.ndarray
    taxel_axes_S: np.ndarray
    taxel_field_kinds: tuple[str, ...]
    taxel_field_sizes: np.ndarray
    contact_center_S: np.ndarray | None = None
    theta_range: tuple[float, float] | None = None
    phi_range: tuple[float, float] | None = None
    taxel_elastic_readings: tuple[str, ...] | None = None
    poisson_ratio: float = DEFAULT_POISSON_RATIO

    def __post_init__(self):
        if self.taxel_elastic_readings is None:
            object.__setattr__(self, "taxel_elastic_readings", ("pressure",) * len(self.taxel_names))

    @property
    def num_taxels(self) -> int:
        return len(self.taxel_names)

    @property
    def is_elastic(self) -> np.ndarray:
        """(n,) True for the barometers that read the elastomer's stress."""
        return np.array([kind == "elastic" for kind in self.taxel_field_kinds], dtype=bool)

    def make_mesh(self, check: bool = True) -> TetMesh:
        """The elastomer's tet mesh (host; fTetWild for surfaces, cached by input).

        With `check`, every taxel port must lie inside the mesh or on its skin
        (see :meth:`check_against_mesh`).
        """
        geometry = self.geometry
        if geometry.kind == "seed":
            mesh = make_seed_mesh(geometry.seed, geometry.edge_length)
        else:
            scale = LENGTH_UNITS[geometry.surface_units]
            mesh = load_tet_mesh(
                list(geometry.paths) if geometry.kind == "mould" else geometry.path,
                edge_length=None if geometry.edge_length is None else geometry.edge_length / scale,  # in the file's units, as core_plane_z
                units=geometry.surface_units,
                core_plane_z=geometry.core_plane_z / scale,
                board=geometry.board,
            )
        if check:
            self.check_against_mesh(mesh)
        return mesh

    def check_against_mesh(self, mesh: TetMesh) -> None:
        """Raise unless every taxel port is in a tet of `mesh` or within fTetWild's
        envelope (1e-3 of the bounding-box diagonal) of its boundary."""
        vertices = np.asarray(mesh.vertices)
        tolerance = _MESH_TOLERANCE * float(np.linalg.norm(np.ptp(vertices, axis=0)))
        outside = find_points_outside_tets(
            self.taxel_positions_S, vertices, np.asarray(mesh.tets), np.asarray(mesh.boundary_faces), tolerance
        )
        if len(outside):
            raise HydrotactError(_outside_message(self, outside[0], "its mesh"))

    def to_json(self) -> dict:
        """The spec as a schema-valid document in SI units (m, rad); :func:`load_sensor`
        reads it back to an equal spec. A surface path is written absolute."""
        taxels = []
        for name, position, axis, kind, size, reading in zip(
            self.taxel_names, self.taxel_positions_S, self.taxel_axes_S, self.taxel_field_kinds, self.taxel_field_sizes, self.taxel_elastic_readings, strict=True
        ):
            if kind == "elastic":
                field = {"kind": "elastic", "port_radius": float(size), "reading": reading}
            else:
                field = {"kind": "disk", "radius": float(size)} if kind == "disk" else {"kind": "cone", "half_angle": float(size)}
            taxels.append(
                {"name": name, "position": position.tolist(), "axis": axis.tolist(), "receptive_field": field}
            )
        document = {
            "name": self.name,
            "description": self.description,
            "units": {"length": "m", "angle": "rad"},
            "geometry": self.geometry.to_json(),
            "part": self.part.to_json(),
        }
        if self.poisson_ratio != DEFAULT_POISSON_RATIO or self.is_elastic.any():
            document["elastomer"] = {"poisson_ratio": float(self.poisson_ratio)}
        if self.contact_center_S is not None:
            document["contact_angles"] = {
                "center": self.contact_center_S.tolist(),
                "theta_range": list(self.theta_range),
                "phi_range": list(self.phi_range),
            }
        document["taxels"] = taxels
        return document


def load_sensor(sensor, source: str | None = None) -> SensorSpec:
    """A sensor spec: a built-in name (see `BUILTIN_SENSORS`), a path to a JSON file
    (str or Path), or an already parsed document (dict; relative surface paths are then
    taken from the working directory).

    Validates the document against data_schemas/sensor.schema.json, converts it to SI
    units, normalises the axes and checks what the schema cannot say (unique names,
    non-zero axes, half-angles, the part, that every port lies in the elastomer). Any
    problem is one :class:`HydrotactError` naming the file and the field.
    """
    if isinstance(sensor, dict):
        return _from_document(sensor, source or "sensor document", Path.cwd())
    if isinstance(sensor, str) and sensor in BUILTIN_SENSORS:
        text = (_DATA / f"{sensor}.json").read_text(encoding="utf-8")
        source = source or f"built-in {sensor}"
        return _from_document(parse_json(text, source), source, None)
    if not isinstance(sensor, str | Path):
        raise HydrotactError(f"a sensor is a built-in name, a JSON file or a dict, got {type(sensor).__name__}")
    path = Path(sensor)
    if not path.is_file():
        raise HydrotactError(f"{sensor}: neither a built-in sensor ({', '.join(BUILTIN_SENSORS)}) nor an existing file")
    source = source or str(path)
    return _from_document(read_json(path, source), source, path.parent)


@functools.cache
def known_parts() -> dict[str, Part]:
    """The barometer parts specs may name, from hydrotact/sensors/data/parts.json."""
    source = "hydrotact/sensors/data/parts.json"
    document = parse_json((_DATA / "parts.json").read_text(encoding="utf-8"), source)
    validate(document, "sensor", source, definition="parts_file")
    parts = {}
    for index, entry in enumerate(document["parts"]):
        part = _make_part(entry, source, ["parts", index])
        if part.name in parts:
            raise HydrotactError(f"{source}: parts[{index}].name: {part.name!r} is listed twice")
        parts[part.name] = part
    return parts


def _fail(source: str, path, message: str):
    raise HydrotactError(f"{source}: {format_path(path)}: {message}")


def _make_part(entry, source: str, path) -> Part:
    if isinstance(entry, str):
        parts = known_parts()
        if entry not in parts:
            _fail(source, path, f"unknown part {entry!r}; the known parts are {', '.join(sorted(parts))}")
        return parts[entry]
    low, high = (float(v) for v in entry["range_pa"])
    if not low < high:
        _fail(source, [*path, "range_pa"], f"low end {low:g} Pa must be below high end {high:g} Pa")
    ambient = float(entry["ambient_pa"])
    if not low <= ambient <= high:
        _fail(source, [*path, "ambient_pa"], f"{ambient:g} Pa is outside range_pa [{low:g}, {high:g}] Pa")
    return Part(
        name=entry["name"],
        lsb_pa=float(entry["lsb_pa"]),
        noise_rms_pa=float(entry["noise_rms_pa"]),
        rate_hz=float(entry["rate_hz"]),
        range_pa=(low, high),
        ambient_pa=ambient,
        description=entry.get("description", ""),
    )


def _make_geometry(entry: dict, length: float, length_unit: str, source: str, base: Path | None) -> Geometry:
    edge_length = entry.get("edge_length")
    edge_length = None if edge_length is None else float(edge_length) * length
    if entry["kind"] == "seed":
        return Geometry(kind="seed", seed=entry["seed"], edge_length=edge_length)
    if entry["kind"] == "mould":
        paths = tuple(str(_surface_path(name, ["geometry", "paths", k], source, base)) for k, name in enumerate(entry["paths"]))
        return Geometry(kind="mould", paths=paths, surface_units=entry.get("mould_units", length_unit), core_plane_z=0.0, edge_length=edge_length, board=entry.get("board", "zmin"))
    path = _surface_path(entry["path"], ["geometry", "path"], source, base)
    return Geometry(
        kind="surface",
        path=str(path.resolve()),
        surface_units=entry.get("surface_units", length_unit),
        core_plane_z=float(entry["core_plane_z"]) * length,
        edge_length=edge_length,
    )


def _surface_path(name: str, field: list, source: str, base: Path | None) -> Path:
    """A surface file named in a spec: absolute, resolved, a surface's suffix, there."""
    path = Path(name).expanduser()
    if not path.is_absolute():
        path = (base or Path.cwd()) / path
    if path.suffix.lower() not in SURFACE_SUFFIXES:
        _fail(source, field, f"{path.name} is not a surface file; use one of {', '.join(SURFACE_SUFFIXES)}")
    if not path.is_file():
        _fail(source, field, f"surface file {path} does not exist")
    return path.resolve()


@functools.cache
def _reserved_names() -> frozenset:
    """The column names of a barometer log other than channels (its schema's list)."""
    return frozenset(load_schema("barometer_log")["$defs"]["columns"]["default"])


def _read_taxels(taxels: list, length: float, angle: float, angle_unit: str, source: str):
    names, positions, axes, kinds, sizes, readings = [], [], [], [], [], []
    seen = {}
    reserved = _reserved_names()
    for index, taxel in enumerate(taxels):
        here = ["taxels", index]
        name = taxel["name"]
        if name in reserved:
            _fail(source, [*here, "name"], f"{name!r} is a reserved log column (time, probe, wrench and label columns); a channel needs another name")
        if name in seen:
            _fail(source, [*here, "name"], f"{name!r} is already the name of taxels[{seen[name]}]")
        seen[name] = index
        axis = np.asarray(taxel["axis"], dtype=np.float64)
        norm = float(np.linalg.norm(axis))
        if not norm > 0.0:
            _fail(source, [*here, "axis"], "must not be zero (it is the sensing direction)")
        field = taxel["receptive_field"]
        if field["kind"] == "disk":
            size = float(field["radius"]) * length
        elif field["kind"] == "elastic":
            size = float(field.get("port_radius", DEFAULT_PORT_RADIUS / length)) * length
        else:
            half_angle = float(field["half_angle"])
            limit = 90.0 if angle_unit == "deg" else math.pi / 2
            if not 0.0 < half_angle < limit:
                _fail(source, [*here, "receptive_field", "half_angle"], f"{half_angle:g} {angle_unit} is not in (0, {limit:g})")
            size = half_angle * angle
        names.append(name)
        positions.append(np.asarray(taxel["position"], dtype=np.float64) * length)
        axes.append(axis / norm)
        kinds.append(field["kind"])
        sizes.append(size)
        readings.append(field.get("reading", "pressure"))
    return tuple(names), np.stack(positions), np.stack(axes), tuple(kinds), np.asarray(sizes, dtype=np.float64), tuple(readings)


def _read_contact_angles(entry: dict, length: float, angle: float, angle_unit: str, source: str):
    center = np.asarray(entry["center"], dtype=np.float64) * length
    ranges = []
    for key, low_limit, high_limit in (("theta_range", -90.0, 90.0), ("phi_range", -180.0, 180.0)):
        low, high = (float(v) for v in entry[key])
        scale = 1.0 if angle_unit == "deg" else 180.0 / math.pi
        if not low < high:
            _fail(source, ["contact_angles", key], f"low end {low:g} must be below high end {high:g}")
        if not (low_limit <= low * scale and high * scale <= high_limit):
            bounds = f"[{low_limit:g}, {high_limit:g}] deg" if angle_unit == "deg" else f"[{low_limit / scale:.6g}, {high_limit / scale:.6g}] rad"
            _fail(source, ["contact_angles", key], f"[{low:g}, {high:g}] {angle_unit} is not within {bounds}")
        ranges.append((low * angle, high * angle))
    return center, ranges[0], ranges[1]


def _from_document(document, source: str, base: Path | None) -> SensorSpec:
    validate(document, "sensor", source)
    units = document["units"]
    length, angle = LENGTH_SCALES[units["length"]], ANGLE_SCALES[units["angle"]]
    part = _make_part(document["part"], source, ["part"])
    geometry = _make_geometry(document["geometry"], length, units["length"], source, base)
    names, positions, axes, kinds, sizes, readings = _read_taxels(document["taxels"], length, angle, units["angle"], source)
    center = theta_range = phi_range = None
    if "contact_angles" in document:
        center, theta_range, phi_range = _read_contact_angles(document["contact_angles"], length, angle, units["angle"], source)
    for array in (positions, axes, sizes, center):
        if array is not None:
            array.setflags(write=False)
    spec = SensorSpec(
        name=document["name"],
        description=document["description"],
        source=source,
        geometry=geometry,
        part=part,
        taxel_names=names,
        taxel_positions_S=positions,
        taxel_axes_S=axes,
        taxel_field_kinds=kinds,
        taxel_field_sizes=sizes,
        contact_center_S=center,
        theta_range=theta_range,
        phi_range=phi_range,
        taxel_elastic_readings=readings,
        poisson_ratio=float(document.get("elastomer", {}).get("poisson_ratio", DEFAULT_POISSON_RATIO)),
    )
    _check_against_surface(spec)
    return spec


@functools.cache
def _seed_surface(name: str) -> tuple[np.ndarray, np.ndarray]:
    spec = SEED_SENSORS[name]
    if spec["shape"] == "box":
        import trimesh

        box = trimesh.creation.box(extents=spec["size_m"])
        box.apply_translation([0.0, 0.0, spec["size_m"][2] / 2])
        return np.asarray(box.vertices), np.asarray(box.faces)
    vertices, faces = seed_surface(name)
    return np.asarray(vertices), np.asarray(faces)


def calc_sensor_surface(spec: SensorSpec) -> tuple[np.ndarray, np.ndarray]:
    """The elastomer's closed surface (vertices (n, 3) m, faces (k, 3)), without
    meshing: for cheap checks (ports inside, where a probe can reach)."""
    geometry = spec.geometry
    if geometry.kind == "seed":
        return _seed_surface(geometry.seed)
    try:
        if geometry.kind == "mould":
            surface = make_mould_cavity(geometry.paths, units=geometry.surface_units, board=geometry.board)[0]
        else:
            surface = load_surface(geometry.path, geometry.surface_units)
    except HydrotactError as error:
        raise HydrotactError(f"{spec.source}: geometry.{'paths' if geometry.kind == 'mould' else 'path'}: {error}") from None
    if not surface.is_watertight:
        _fail(spec.source, ["geometry", "path"], f"{geometry.path} is not a closed surface")
    return np.asarray(surface.vertices), np.asarray(surface.faces)


def _first_exits(origins, directions, vertices, faces, tolerance):
    """Where each ray origins[i] + t directions[i] (t > tolerance) first meets the
    surface (the taxels' Möller-Trumbore test), NaN where it meets none."""
    from ..taxel import calc_first_hits

    nearest = calc_first_hits(origins, directions, vertices, faces, tolerance)
    return np.where(np.isfinite(nearest)[:, None], origins + np.where(np.isfinite(nearest), nearest, 0.0)[:, None] * directions, np.nan)


def _check_against_surface(spec: SensorSpec) -> None:
    """Every port inside the elastomer's closed surface or on it, and every axis
    pointing into it (cheap: no meshing)."""
    vertices, faces = calc_sensor_surface(spec)
    geometry = spec.geometry
    if geometry.kind == "seed":
        what = f"the {geometry.seed} elastomer"
    else:
        what = f"the cast of {', '.join(Path(p).name for p in geometry.paths)}" if geometry.kind == "mould" else f"the surface {Path(geometry.path).name}"
    diagonal = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    outside = find_points_outside_surface(spec.taxel_positions_S, vertices, faces, _SURFACE_TOLERANCE * diagonal)
    if len(outside):
        raise HydrotactError(_outside_message(spec, outside[0], what))
    # Along its axis a port must reach the skin, not the base it sits on (the PCB,
    # the lowest z): an axis pointing out of the elastomer, or down into the board,
    # reads nothing, ever.
    tolerance = _SURFACE_TOLERANCE * diagonal
    exits = _first_exits(spec.taxel_positions_S, spec.taxel_axes_S, vertices, faces, tolerance)
    base = float(np.min(vertices[:, 2]))
    wrong = np.flatnonzero(~np.isfinite(exits[:, 2]) | (exits[:, 2] <= base + 1e3 * tolerance))
    if len(wrong):
        index = int(wrong[0])
        axis = ", ".join(f"{v:.3g}" for v in spec.taxel_axes_S[index])
        raise HydrotactError(
            f"{spec.source}: taxels[{index}].axis: ({axis}) from the port does not reach the skin of {what} (it points out of it, or into the base): "
            "the barometer would read nothing, ever; the axis goes from the port into the elastomer, towards the skin"
        )


def _outside_message(spec: SensorSpec, index: int, what: str) -> str:
    position_mm = ", ".join(f"{v * 1e3:g}" for v in spec.taxel_positions_S[index])
    return f"{spec.source}: taxels[{index}].position: ({position_mm}) mm is outside {what}"


def document_text(spec: SensorSpec) -> str:
    """`spec.to_json()` as JSON text."""
    return json.dumps(spec.to_json(), indent=2) + "\n"


def with_receptive_fields(spec: SensorSpec, field: dict, name: str | None = None) -> SensorSpec:
    """`spec` with every barometer reading through `field` (a receptive-field entry of
    the sensor schema in SI units, m and rad, as `spec.to_json()` writes them: e.g.
    ``{"kind": "elastic"}`` or ``{"kind": "cone", "half_angle": math.radians(40)}``):
    the same elastomer, layout and part, validated as a loaded spec is. `name`
    defaults to the spec's name and the field's kind ("pad5x5-elastic"): a spec's
    name keys its caches and outputs."""
    document = spec.to_json()
    document["name"] = name or f"{spec.name}-{field.get('kind', 'field')}"
    for taxel in document["taxels"]:
        taxel["receptive_field"] = dict(field)
    return load_sensor(document, source=f"{spec.name} with {field.get('kind', 'other')} receptive fields")
