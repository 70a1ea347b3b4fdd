"""Contact events: where on the skin, from which direction, how hard, how long (host).

Points are uniform *by area* over the touchable skin: the elastomer's free boundary
faces whose centroids lie within the sensor's contact-angle ranges where it defines
them (seen from its contact centre), every free face otherwise. A face is drawn with
probability proportional to its area, then a point uniformly inside it. Uniform in
(θ, φ) would crowd the poles of a sphere; uniform by area is what a gantry that picks
"random places on the skin" does. A stage (the `stage` regime) presses straight down
on the skin faces that face up, within its x and y ranges.
"""

import dataclasses

import numpy as np

from .._errors import HydrotactError
from ..mesh import FREE
from ._config import STAGE_FACE_COS, DatasetConfig


@dataclasses.dataclass(frozen=True)
class Skin:
    """The touchable skin: triangles `corners` (k, 3, 3) m, outward unit `normals`
    (k, 3) and `areas` (k,) m^2, in the sensor frame S; and the elastomer's whole
    closed boundary (`boundary_vertices` (n, 3), `boundary_faces` (f, 3)), through
    which an approach's thickness of elastomer is measured."""

    corners: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    boundary_vertices: np.ndarray
    boundary_faces: np.ndarray

    @property
    def area(self) -> float:
        return float(self.areas.sum())


def find_touchable_skin(spec, mesh) -> Skin:
    """The free faces of `mesh` within `spec`'s contact-angle ranges (all free faces
    for a sensor without them), as a :class:`Skin`."""
    from ..sim import calc_contact_angles

    faces = mesh.faces_tagged(FREE)
    corners = np.asarray(mesh.vertices)[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    doubled = np.linalg.norm(cross, axis=1)
    keep = doubled > 0.0
    if spec.contact_center_S is not None:
        theta, phi = (np.asarray(a) for a in calc_contact_angles(corners.mean(axis=1), np.asarray(spec.contact_center_S)))
        keep &= (spec.theta_range[0] <= theta) & (theta <= spec.theta_range[1]) & (spec.phi_range[0] <= phi) & (phi <= spec.phi_range[1])
    if not keep.any():
        raise HydrotactError(f"sensor {spec.name}: no free skin face lies within its contact-angle ranges; nothing to touch")
    return Skin(
        corners=corners[keep], normals=cross[keep] / doubled[keep, None], areas=0.5 * doubled[keep],
        boundary_vertices=np.asarray(mesh.vertices), boundary_faces=np.asarray(mesh.boundary_faces),
    )


def calc_approach_thickness(skin: Skin, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The elastomer's thickness along each approach (m): from the skin point along the
    unit direction into the elastomer to where the line first leaves it again (the
    board, the core, or the far side), by casting rays at the closed boundary with the
    taxels' Möller-Trumbore test."""
    from ..taxel import calc_first_hits

    skip = 1e-6 * float(np.ptp(skin.boundary_vertices, axis=0).max())  # past the skin point's own face
    thickness = calc_first_hits(points, directions, skin.boundary_vertices, skin.boundary_faces, skip)
    if not np.all(np.isfinite(thickness)):
        raise HydrotactError(f"{int(np.sum(~np.isfinite(thickness)))} approach lines never leave the elastomer: its boundary is not closed")
    return thickness


def sample_skin_points(skin: Skin, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`count` points uniform by area over the skin: (points (n, 3), their faces'
    outward normals (n, 3), face indices (n,))."""
    face = rng.choice(len(skin.areas), size=count, p=skin.areas / skin.areas.sum())
    r1, r2 = rng.random(count), rng.random(count)
    root = np.sqrt(r1)
    a, b, c = (skin.corners[face, k] for k in range(3))
    points = (1.0 - root)[:, None] * a + (root * (1.0 - r2))[:, None] * b + (root * r2)[:, None] * c
    return points, skin.normals[face], face


def _tilt(directions: np.ndarray, max_tilt: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Each unit direction tilted by an angle uniform over the cone's solid angle up to
    `max_tilt` (rad), towards a uniform azimuth: (tilted (n, 3), angles (n,))."""
    count = len(directions)
    cos_tilt = 1.0 - rng.random(count) * (1.0 - np.cos(max_tilt))
    azimuth = rng.uniform(0.0, 2.0 * np.pi, count)
    helper = np.where(np.abs(directions[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    u = np.cross(directions, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(directions, u)
    sin_tilt = np.sqrt(np.clip(1.0 - cos_tilt**2, 0.0, None))
    tilted = cos_tilt[:, None] * directions + sin_tilt[:, None] * (np.cos(azimuth)[:, None] * u + np.sin(azimuth)[:, None] * v)
    return tilted / np.linalg.norm(tilted, axis=1, keepdims=True), np.arccos(np.clip(cos_tilt, -1.0, 1.0))


def pressing_rotation_vectors(directions: np.ndarray) -> np.ndarray:
    """Rotation vectors turning the probe frame R so that it presses along each unit
    direction: R's -z (the way a built-in probe presses) onto `directions` (n, 3)."""
    target = -directions  # R's +z
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, target)
    sine = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(sine, target @ z)
    safe = sine > 1e-12
    unit = np.where(safe[:, None], axis / np.where(safe, sine, 1.0)[:, None], np.array([[1.0, 0.0, 0.0]]))  # antiparallel: half a turn about x
    return unit * angle[:, None]


@dataclasses.dataclass(frozen=True)
class EventPlan:
    """The drawn events (arrays of length N, frame S, SI units): `points` on the skin
    and its outward `normals`; the approach `directions` (into the skin) and the
    probe's `rotation_vectors`; `tilts` (rad) from the inward normal; `target_forces`
    (N) or, where the config's target is depth, `target_depths` (m past the skin
    point; the other is NaN); `speeds` (m/s); `holds` and `gaps` (s); `thickness` (m) of elastomer along
    the approach and `max_depths` (m), the deepest the approach goes: the smaller of
    `max_depth` and `max_depth_fraction` of the thickness."""

    points: np.ndarray
    normals: np.ndarray
    directions: np.ndarray
    rotation_vectors: np.ndarray
    tilts: np.ndarray
    target_forces: np.ndarray
    target_depths: np.ndarray
    speeds: np.ndarray
    holds: np.ndarray
    gaps: np.ndarray
    thickness: np.ndarray
    max_depths: np.ndarray

    @property
    def num_events(self) -> int:
        return len(self.points)


def draw_target_forces(config: DatasetConfig, count: int, rng: np.random.Generator) -> np.ndarray:
    """Target forces along the approach (N) from the configured distribution."""
    low, high = config.force_range
    if config.force_distribution == "loguniform":
        return np.exp(rng.uniform(np.log(low), np.log(high), count))
    return rng.uniform(low, high, count)


def draw_hold_targets(config: DatasetConfig, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(target forces N, target depths m) of `count` holds, as the config's target
    says (:data:`TARGETS`): the one not drawn is NaN. One draw in the force's place, so
    a force-target regime draws as it did before depths were offered."""
    nothing = np.full(count, np.nan)
    if config.target == "depth":
        return nothing, rng.uniform(*config.depth_range, count)
    return draw_target_forces(config, count, rng), nothing


def stage_skin(skin: Skin, config: DatasetConfig) -> Skin:
    """The part of `skin` a stage presses: the faces that face up (:data:`STAGE_FACE_COS`)
    with a corner inside the configured x and y ranges (their points are then kept
    inside the ranges by :func:`sample_stage_points`); an error naming the option when
    none is left."""
    keep = skin.normals[:, 2] >= STAGE_FACE_COS
    for axis, name in ((0, "stage_x_range"), (1, "stage_y_range")):
        span = getattr(config, name)
        if span is not None:
            low, high = skin.corners[:, :, axis].min(axis=1), skin.corners[:, :, axis].max(axis=1)
            keep &= (high >= span[0]) & (low <= span[1])
    if not keep.any():
        extent = np.ptp(skin.corners.reshape(-1, 3), axis=0)
        raise HydrotactError(
            "--regime stage: no skin face faces up (+z)" + ("" if config.stage_x_range is None and config.stage_y_range is None else " within --stage-x-range and --stage-y-range")
            + f" (the skin spans {1e3 * extent[0]:.1f} x {1e3 * extent[1]:.1f} mm in x and y); a stage presses straight down"
        )
    return dataclasses.replace(skin, corners=skin.corners[keep], normals=skin.normals[keep], areas=skin.areas[keep])


def sample_stage_points(skin: Skin, config: DatasetConfig, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """`count` points uniform by area over the up-facing skin within the stage's
    ranges (drawn on its faces, those outside the ranges drawn again; at most 200
    rounds): (points (n, 3), the faces' outward normals (n, 3))."""
    skin = stage_skin(skin, config)
    points, normals = np.empty((0, 3)), np.empty((0, 3))
    for _ in range(200):
        drawn, drawn_normals, _ = sample_skin_points(skin, count, rng)
        inside = np.ones(count, bool)
        for axis, name in ((0, "stage_x_range"), (1, "stage_y_range")):
            span = getattr(config, name)
            if span is not None:
                inside &= (span[0] <= drawn[:, axis]) & (drawn[:, axis] <= span[1])
        points, normals = np.vstack([points, drawn[inside]]), np.vstack([normals, drawn_normals[inside]])
        if len(points) >= count:
            return points[:count], normals[:count]
    raise HydrotactError("--stage-x-range, --stage-y-range: too little up-facing skin lies inside them to draw the events from")


def sample_events(skin: Skin, config: DatasetConfig, rng: np.random.Generator) -> EventPlan:
    """Draw `config.events` events (see :class:`EventPlan`), in a fixed order of draws."""
    count = config.events
    if config.regime == "stage":
        points, normals = sample_stage_points(skin, config, count, rng)
        directions, tilts = np.tile([0.0, 0.0, -1.0], (count, 1)), np.arccos(np.clip(normals[:, 2], -1.0, 1.0))
    else:
        points, normals, _ = sample_skin_points(skin, count, rng)
        directions, tilts = _tilt(-normals, np.radians(config.max_tilt_deg), rng)
    thickness = calc_approach_thickness(skin, points, directions)
    forces, depths = draw_hold_targets(config, count, rng)
    return EventPlan(
        points=points,
        normals=normals,
        directions=directions,
        rotation_vectors=pressing_rotation_vectors(directions),
        tilts=tilts,
        target_forces=forces,
        target_depths=depths,
        speeds=rng.uniform(*config.speed_range, count),
        holds=rng.uniform(*config.hold_range, count),
        gaps=rng.uniform(*config.gap_range, count),
        thickness=thickness,
        max_depths=np.minimum(config.max_depth, config.max_depth_fraction * thickness),
    )
