"""The `hydrotact contact` job: one probe pressed into one sensor, reported."""

import re

import numpy as np

from ._errors import HydrotactError
from .contact import HalfSpace, compute_contact_surface, make_cylinder_probe, make_pose, make_sphere_probe
from .field import make_pressure_field
from .mesh import FREE, TetMesh

_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(m|mm|um|cm)?\s*$")
_SCALE = {None: 1.0, "m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6}


def parse_length(text: str, what: str) -> float:
    """'2mm' -> 0.002; a bare number is metres."""
    match = _LENGTH.match(text)
    if not match:
        raise HydrotactError(f"{what}: cannot read {text!r} as a length (e.g. 2mm, 0.5e-3)")
    return float(match.group(1)) * _SCALE[match.group(2)]


def parse_probe(spec: str):
    """'cylinder:d=2mm[,length=10mm]', 'sphere:r=3mm' or 'plane' -> a rigid body."""
    kind, _, rest = spec.partition(":")
    options = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        options[key.strip()] = parse_length(value, f"--probe {key.strip()}")
    if kind == "plane" and not options:
        return HalfSpace()
    if kind == "cylinder" and set(options) <= {"d", "length"} and "d" in options:
        return make_cylinder_probe(options["d"], options.get("length"))
    if kind == "sphere" and set(options) == {"r"}:
        return make_sphere_probe(options["r"])
    raise HydrotactError(f"--probe: unknown probe {spec!r}; use cylinder:d=2mm, sphere:r=3mm or plane")


def skin_height(mesh: TetMesh, x: float, y: float) -> float:
    """The height of the sensor's free skin above (x, y): the highest crossing of the
    vertical line through (x, y) with a free face."""
    triangles = np.asarray(mesh.vertices)[mesh.faces_tagged(FREE)]
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = np.abs(det) > 0
    safe = np.where(ok, det, 1.0)
    u = ((x - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (y - a[:, 1])) / safe
    v = ((b[:, 0] - a[:, 0]) * (y - a[:, 1]) - (x - a[:, 0]) * (b[:, 1] - a[:, 1])) / safe
    inside = ok & (u >= -1e-12) & (v >= -1e-12) & (u + v <= 1 + 1e-12)
    if not inside.any():
        raise HydrotactError(f"--at: no part of the sensor lies under x = {x:g} m, y = {y:g} m")
    z = a[:, 2] + u * (b[:, 2] - a[:, 2]) + v * (c[:, 2] - a[:, 2])
    return float(np.max(z[inside]))


def run_contact(mesh: TetMesh, strain, modulus: float, probe_spec: str, at: str):
    """Press the probe straight down (along -z of the sensor) at (x, y) to the depth,
    measured from the skin there. Returns (report dict, surface, probe, X_SP)."""
    parts = at.split(",")
    if len(parts) != 3:
        raise HydrotactError(f"--at: expected X,Y,DEPTH (e.g. 0,2.2mm,0.5mm), got {at!r}")
    x, y, depth = (parse_length(p, "--at") for p in parts)
    if depth < 0:
        raise HydrotactError(f"--at: the depth must be >= 0, got {depth:g} m")
    probe = parse_probe(probe_spec)
    top = skin_height(mesh, x, y)
    X_SP = make_pose([x, y, top - depth])
    field = make_pressure_field(mesh, strain, modulus)
    surface, _ = compute_contact_surface(field, probe, X_SP)
    force, torque = surface.calc_wrench()
    used = np.asarray(surface.valid)[:, None] & (np.arange(surface.vertices_S.shape[1])[None] < np.asarray(surface.counts)[:, None])
    report = {
        "probe": probe_spec,
        "tip_position_m": [x, y, top - depth],
        "depth_m": depth,
        "modulus_Pa": modulus,
        "num_polygons": int(surface.num_polygons),
        "area_m2": float(surface.total_area),
        "force_N": np.asarray(force).tolist(),
        "torque_Nm": np.asarray(torque).tolist(),
        "centroid_m": np.asarray(surface.centroid_S).tolist(),
        "max_pressure_Pa": float(np.max(np.where(used, np.asarray(surface.pressures), 0.0), initial=0.0)),
    }
    return report, surface, probe, X_SP
