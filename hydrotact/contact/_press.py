"""One probe pressed straight down into a sensor, and what the contact reports."""

import numpy as np

from .._errors import HydrotactError
from ..field import make_pressure_field
from ..mesh import FREE, TetMesh
from ._api import compute_contact_surface
from ._pose import make_pose
from ._probes import parse_length, parse_probe


def calc_skin_height(mesh: TetMesh, x: float, y: float) -> float:
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


def parse_at(at: str) -> tuple[float, float, float]:
    """(x, y, depth) in metres from `--at` text "X,Y,DEPTH" (lengths with units; bare
    numbers are metres); a one-line error naming --at otherwise."""
    parts = at.split(",")
    if len(parts) != 3:
        raise HydrotactError(f"--at: expected X,Y,DEPTH (e.g. 0,2.2mm,0.5mm), got {at!r}")
    x, y, depth = (parse_length(p, "--at") for p in parts)
    if depth < 0:
        raise HydrotactError(f"--at: the depth must be >= 0, got {depth:g} m")
    return x, y, depth


def press_probe(mesh: TetMesh, strain, modulus: float, probe_spec: str, at: str):
    """Press the probe straight down (along -z of the sensor) at (x, y) to the depth,
    measured from the skin there.

    **Arguments:** `mesh` and its `strain` (num_vertices,); `modulus` E in Pa;
    `probe_spec` as `cylinder:d=2mm[,length=10mm]`, `sphere:r=3mm` or `plane`; `at` as
    "X,Y,DEPTH" (lengths with units; bare numbers are metres).

    **Returns:** (report dict, ContactSurface, probe, X_SP the probe's pose).
    """
    x, y, depth = parse_at(at)
    probe = parse_probe(probe_spec)
    top = calc_skin_height(mesh, x, y)
    base = float(np.min(np.asarray(mesh.vertices)[:, 2]))
    if depth >= top - base:
        raise HydrotactError(
            f"--at: depth {depth * 1e3:.4g} mm reaches the sensor's base: the skin over ({x * 1e3:.4g}, {y * 1e3:.4g}) mm is {(top - base) * 1e3:.4g} mm "
            "above it (is the depth measured from the skin, and in the right unit?)"
        )
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
