"""Whether a trajectory can touch the sensor at all: the check that catches a unit
slip (positions in mm read as metres) or a probe on the wrong side of the board
before a simulation writes a log of zeros."""

import numpy as np

from .._errors import HydrotactError, where
from ..contact import HalfSpace


def calc_probe_reach(probe) -> float:
    """The radius (m) of the ball about the probe frame's origin that holds the probe
    (inf for a half-space)."""
    if isinstance(probe, HalfSpace):
        return float("inf")
    return float(np.max(np.linalg.norm(np.asarray(probe.vertices_R), axis=1)))


def check_reach(spec, probe, trajectory, source: str | None = None) -> None:
    """Refuse a trajectory along which the probe never comes near the sensor.

    Cheap and conservative: each pose's probe is bounded by a ball (a plate by its
    plane) and the elastomer by its bounding box; a trajectory is refused only when
    no ball meets the box. The message gives the closest approach and, when the
    positions are far larger than the sensor, the likely unit.

    **Arguments:** `spec` a SensorSpec; `probe` a probe object; `trajectory` a
    Trajectory; `source` the file named in the message.
    """
    from ..sensors import calc_sensor_surface

    vertices, _ = calc_sensor_surface(spec)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    size = float(np.linalg.norm(high - low))
    tips = np.asarray(trajectory.translations)
    if isinstance(probe, HalfSpace):
        # the plate is the half-space {p : n . (p - tip) >= 0}, n its frame's +z: it
        # meets the box when the box's farthest corner along n lies in it
        normals = _plate_normals(np.asarray(trajectory.rotation_vectors))
        corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
        depth = np.max(np.einsum("ti,ci->tc", normals, corners), axis=1) - np.einsum("ti,ti->t", normals, tips)
        gaps = np.maximum(-depth, 0.0)
    else:
        nearest = np.clip(tips, low, high)
        gaps = np.maximum(np.linalg.norm(tips - nearest, axis=1) - calc_probe_reach(probe), 0.0)
    if np.any(gaps <= 0.0):
        return
    closest = int(np.argmin(gaps))
    message = (
        f"{where(source)}no pose comes near the sensor: the probe stays {gaps[closest] * 1e3:.4g} mm or more from the elastomer "
        f"({(high - low)[0] * 1e3:.3g} x {(high - low)[1] * 1e3:.3g} x {(high - low)[2] * 1e3:.3g} mm; closest at row {closest + 1}, "
        f"tip ({', '.join(f'{v:.4g}' for v in tips[closest])}) m)"
    )
    extent = float(np.max(np.abs(tips)))
    if extent > 20.0 * size:
        message += f"; the positions reach {extent:.3g} m against a sensor {size * 1e3:.3g} mm across: in mm? (--units mm)"
    elif np.all(tips[:, 2] < low[2]):
        message += "; every pose is below the sensor's base (z = 0 is the board, +z the skin side)"
    raise HydrotactError(message)


def _plate_normals(rotation_vectors):
    """+z of the probe frame in S for each rotation vector (Rodrigues)."""
    angles = np.linalg.norm(rotation_vectors, axis=1, keepdims=True)
    axes = np.where(angles > 0.0, rotation_vectors / np.where(angles > 0.0, angles, 1.0), 0.0)
    z = np.array([0.0, 0.0, 1.0])
    cos, sin = np.cos(angles), np.sin(angles)
    return z * cos + np.cross(axes, z) * sin + axes * (axes @ z)[:, None] * (1.0 - cos)
