"""Where barometers may go: the feasible layouts of a sensor, the projection onto them,
random feasible layouts, and the check that a request can be met (host, numpy).

A layout is feasible when

- every port lies inside the elastomer at least `margin` from its boundary (placement
  `inside`: the part's package and the silicone over it), or on the board, the
  elastomer's base plane, at least `margin` from its side walls (placement `board`);
- with `max_height`, no port higher than that above the board (ports on risers of at
  most that height, as on sphere8's own board);
- every two ports are at least `spacing` apart;
- every axis is a unit vector within `max_tilt` of the board's normal +z (it then
  reaches the skin, never the board).

Steps of the optimiser are followed by the Euclidean projection onto these sets, done
by alternating projections (a port pushed inside, pairs pushed apart) until every
constraint holds to round-off; a layout that cannot be made feasible is an error,
never a silent clip.
"""

import dataclasses

import numpy as np

from .._choices import Choice
from .._errors import HydrotactError
from ..sensors._inside import calc_winding_numbers

PROJECTION_SWEEPS = 200
"""The most rounds of alternating projections before a layout is declared infeasible."""
SLACK = 1e-6
"""Relative slack with which a projection overshoots each bound (so round-off keeps
the projected point feasible)."""
CANDIDATES = 1500
"""Candidate ports drawn for random sequential packing."""
PACKING_TRIES = 4
"""Shuffles of the candidates tried before a count is declared impossible."""


class Placement(Choice):
    """Where ports go: `inside` the elastomer (cast in, or on risers) or on the `board`."""

    INSIDE = "inside"
    BOARD = "board"


def calc_closest_points(points, triangles, chunk_size: int = 32):
    """For each point (n, 3), the closest point on the triangles (k, 3, 3): (closest
    (n, 3), distance (n,), triangle index (n,)) by the Voronoi regions of each
    triangle's vertices, edges and face (points in chunks: memory ~ chunk x k)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) > chunk_size:
        parts = [_closest_points(points[start : start + chunk_size], triangles) for start in range(0, len(points), chunk_size)]
        return tuple(np.concatenate([part[k] for part in parts]) for k in range(3))
    return _closest_points(points, triangles)


def _closest_points(points, triangles):
    p = points[:, None]
    a, b, c = (np.asarray(triangles, dtype=np.float64)[None, :, i] for i in range(3))
    dot = lambda u, v: np.einsum("...i,...i->...", u, v)
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c
    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    safe = lambda x: np.where(np.abs(x) > 1e-300, x, 1e-300)
    total = safe(va + vb + vc)
    closest = a + ab * (vb / total)[..., None] + ac * (vc / total)[..., None]
    # Regions in reverse order of precedence, each overwriting the ones after it.
    edge_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    closest = np.where(edge_bc[..., None], b + (c - b) * ((d4 - d3) / safe((d4 - d3) + (d5 - d6)))[..., None], closest)
    edge_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    closest = np.where(edge_ac[..., None], a + ac * (d2 / safe(d2 - d6))[..., None], closest)
    closest = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, closest)
    edge_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    closest = np.where(edge_ab[..., None], a + ab * (d1 / safe(d1 - d3))[..., None], closest)
    closest = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, closest)
    closest = np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, closest)
    distances = np.linalg.norm(closest - p, axis=-1)
    index = np.argmin(distances, axis=1)
    rows = np.arange(len(index))
    return closest[rows, index], distances[rows, index], index


@dataclasses.dataclass(frozen=True)
class FeasibleRegion:
    """The feasible layouts of one elastomer (see the module): its closed boundary
    (`vertices`, outward-wound `faces`), its `tets` (point location), `placement`,
    `margin` and `spacing` (m), `max_tilt` (rad); `base_z` the board's height;
    `max_height` the highest a port may sit above the board (m; None: no limit)."""

    vertices: np.ndarray
    faces: np.ndarray
    tets: np.ndarray
    placement: Placement
    margin: float
    spacing: float
    max_tilt: float
    base_z: float
    max_height: float | None = None

    @property
    def _top(self) -> float:
        return np.inf if self.max_height is None else self.base_z + self.max_height

    @property
    def triangles(self) -> np.ndarray:
        return self.vertices[self.faces]

    @property
    def _inward(self) -> np.ndarray:
        t = self.triangles
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return -n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    def _lifted(self, positions):
        """Board ports are checked at `margin` above the board (a port on the board is
        inside its closure but on its boundary)."""
        lifted = np.array(positions, dtype=np.float64)
        if self.placement == Placement.BOARD:
            lifted[:, 2] = self.base_z + self.margin * (1.0 + SLACK)
        return lifted

    def clearances(self, positions) -> np.ndarray:
        """Each port's signed distance from the boundary (m; negative outside), lifted
        for board ports."""
        lifted = self._lifted(positions)
        _, distances, _ = calc_closest_points(lifted, self.triangles)
        inside = calc_winding_numbers(lifted, self.vertices, self.faces) > 0.5
        return np.where(inside, distances, -distances)

    def _push_inside(self, positions):
        lifted = self._lifted(positions)
        closest, distances, index = calc_closest_points(lifted, self.triangles)
        inside = calc_winding_numbers(lifted, self.vertices, self.faces) > 0.5
        short = ~inside | (distances < self.margin)
        lifted[short] = closest[short] + self.margin * (1.0 + SLACK) * self._inward[index[short]]
        if self.placement == Placement.BOARD:
            lifted[:, 2] = self.base_z
        high = lifted[:, 2] > self._top
        lifted[high, 2] = self._top - (self._top - self.base_z) * SLACK
        return lifted, bool(short.any() or high.any())

    def _push_apart(self, positions):
        moved = False
        positions = positions.copy()
        for i in range(len(positions)):
            for j in range(i + 1, len(positions)):
                gap = positions[j] - positions[i]
                distance = np.linalg.norm(gap)
                if distance < self.spacing:
                    direction = gap / distance if distance > 1e-12 else np.array([1.0, 0.0, 0.0])
                    shift = 0.5 * (self.spacing * (1.0 + SLACK) - distance) * direction
                    positions[i] -= shift
                    positions[j] += shift
                    moved = True
        return positions, moved

    def project_axes(self, axes) -> np.ndarray:
        """Unit axes within `max_tilt` of +z: each normalised, then a tilted one moved
        onto the cone's rim along its own azimuth."""
        axes = np.asarray(axes, dtype=np.float64)
        axes = axes / np.maximum(np.linalg.norm(axes, axis=1, keepdims=True), 1e-300)
        low = axes[:, 2] < np.cos(self.max_tilt)
        if low.any():
            horizontal = axes[low].copy()
            horizontal[:, 2] = 0.0
            norm = np.linalg.norm(horizontal, axis=1, keepdims=True)
            horizontal = np.where(norm > 1e-12, horizontal / np.maximum(norm, 1e-300), np.array([1.0, 0.0, 0.0]))
            axes[low] = np.cos(self.max_tilt) * np.array([0.0, 0.0, 1.0]) + np.sin(self.max_tilt) * horizontal
        return axes

    def project_positions(self, positions) -> np.ndarray:
        """The ports moved onto the feasible set (alternating projections); a
        HydrotactError if they cannot all be placed."""
        positions = np.array(positions, dtype=np.float64)
        for _ in range(PROJECTION_SWEEPS):
            positions, pushed = self._push_inside(positions)
            positions, spread = self._push_apart(positions)
            if not (pushed or spread):
                return positions
        problems = self.violations(positions, np.tile([0.0, 0.0, 1.0], (len(positions), 1)))
        raise HydrotactError(f"could not place {len(positions)} barometers: {problems[0] if problems else 'the projection did not settle'}")

    def violations(self, positions, axes) -> list[str]:
        """Every broken constraint, one sentence each (empty for a feasible layout),
        checked independently of the projection: the inside test by the mesh's own
        point location (barycentric coordinates in its tets)."""
        from ..sensors._inside import find_points_outside_tets

        positions, axes = np.asarray(positions, dtype=np.float64), np.asarray(axes, dtype=np.float64)
        problems = []
        lifted = self._lifted(positions)
        outside = find_points_outside_tets(lifted, self.vertices, self.tets, self.faces, 0.0)
        problems += [f"barometer {int(i)} lies outside the elastomer" for i in outside]
        clearance = self.clearances(positions)
        for i in np.flatnonzero(clearance < self.margin * (1.0 - 1e-6)):
            problems.append(f"barometer {int(i)} lies {clearance[i] * 1e3:.3g} mm from the elastomer's boundary, under the margin of {self.margin * 1e3:.3g} mm")
        if self.placement == Placement.BOARD:
            problems += [f"barometer {int(i)} is off the board" for i in np.flatnonzero(np.abs(positions[:, 2] - self.base_z) > 1e-9)]
        for i in np.flatnonzero(positions[:, 2] > self._top + 1e-12):
            problems.append(f"barometer {int(i)} sits {(positions[i, 2] - self.base_z) * 1e3:.4g} mm above the board, over the {self.max_height * 1e3:.4g} mm allowed")
        gaps = np.linalg.norm(positions[:, None] - positions[None], axis=-1) + np.diag(np.full(len(positions), np.inf))
        for i, j in zip(*np.nonzero(np.triu(gaps < self.spacing * (1.0 - 1e-6))), strict=True):
            problems.append(f"barometers {int(i)} and {int(j)} are {gaps[i, j] * 1e3:.3g} mm apart, under the spacing of {self.spacing * 1e3:.3g} mm")
        norms = np.linalg.norm(axes, axis=1)
        problems += [f"barometer {int(i)}'s axis has length {norms[i]:.6g}, not 1" for i in np.flatnonzero(np.abs(norms - 1.0) > 1e-9)]
        tilt = np.degrees(np.arccos(np.clip(axes[:, 2] / np.maximum(norms, 1e-300), -1.0, 1.0)))
        limit = np.degrees(self.max_tilt)
        problems += [f"barometer {int(i)}'s axis is tilted {tilt[i]:.4g} deg from +z, over {limit:.4g} deg" for i in np.flatnonzero(tilt > limit * (1.0 + 1e-9) + 1e-9)]
        return problems

    def candidates(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """`count` or fewer feasible ports drawn uniformly (by volume inside, by area on
        the board), those closer than the margin to the boundary dropped (drawn in
        tets or on the board's faces, they are inside: only the margin is tested)."""
        corners = self.vertices[self.tets]
        if self.placement == Placement.BOARD:
            faces = self.triangles
            on_board = np.all(np.abs(faces[:, :, 2] - self.base_z) < 1e-9, axis=1)
            faces = faces[on_board]
            sizes = 0.5 * np.linalg.norm(np.cross(faces[:, 1] - faces[:, 0], faces[:, 2] - faces[:, 0]), axis=1)
            pick = rng.choice(len(faces), size=count, p=sizes / sizes.sum())
            r1, r2 = rng.random(count), rng.random(count)
            root = np.sqrt(r1)
            a, b, c = (faces[pick, k] for k in range(3))
            points = (1.0 - root)[:, None] * a + (root * (1.0 - r2))[:, None] * b + (root * r2)[:, None] * c
        else:
            volumes = np.abs(np.einsum("ti,ti->t", corners[:, 1] - corners[:, 0], np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 0]))) / 6.0
            pick = rng.choice(len(corners), size=count, p=volumes / volumes.sum())
            weights = rng.dirichlet(np.ones(4), size=count)
            points = np.einsum("nk,nki->ni", weights, corners[pick])
        points = points[points[:, 2] <= self._top]
        _, distances, _ = calc_closest_points(self._lifted(points), self.triangles)
        return points[distances >= self.margin * (1.0 + SLACK)]

    def random_axes(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """Unit axes uniform over the cone of `max_tilt` around +z (by solid angle)."""
        cos_tilt = 1.0 - rng.random(count) * (1.0 - np.cos(self.max_tilt))
        azimuth = rng.uniform(0.0, 2.0 * np.pi, count)
        sin_tilt = np.sqrt(np.clip(1.0 - cos_tilt**2, 0.0, None))
        return np.column_stack([sin_tilt * np.cos(azimuth), sin_tilt * np.sin(azimuth), cos_tilt])

    def random_layout(self, count: int, rng: np.random.Generator, known=None) -> tuple[np.ndarray, np.ndarray]:
        """A feasible layout of `count` ports by random sequential packing of uniform
        candidates, with random axes. Random packing jams at about half the density a
        grid reaches (a 5 x 5 grid of ports at their pitch: packing finds room for ~18),
        so where it falls short and `known` (a feasible layout of at least `count`
        ports, e.g. the sensor's own, projected) is given, the start is `count` of
        those ports, each moved in turn to a random candidate wherever the spacing
        allows. A HydrotactError naming the most that fit when neither gives `count`."""
        most = 0
        for _ in range(PACKING_TRIES):
            points = self.candidates(CANDIDATES, rng)
            chosen = []
            for point in points:
                if all(np.linalg.norm(point - other) >= self.spacing * (1.0 + SLACK) for other in chosen):
                    chosen.append(point)
                    if len(chosen) == count:
                        return np.array(chosen), self.random_axes(count, rng)
            most = max(most, len(chosen))
        if known is not None and len(known) >= count:
            return self._shuffled(np.asarray(known, dtype=np.float64), count, rng), self.random_axes(count, rng)
        found = f"random packing found room for {most} at most" + (f", the sensor's own layout holds {len(known)}" if known is not None else "")
        where = "on the board" if self.placement == Placement.BOARD else "inside the elastomer"
        if self.max_height is not None and self.placement != Placement.BOARD:
            where += f" no higher than {self.max_height * 1e3:.4g} mm above the board"
        raise HydrotactError(
            f"cannot place {count} barometers {self.spacing * 1e3:.3g} mm apart {where} at least {self.margin * 1e3:.3g} mm from its boundary: "
            f"{found}; ask for fewer barometers (--barometers), a smaller spacing (--spacing) or a smaller margin (--margin)"
        )

    def _shuffled(self, known: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
        """`count` ports of a feasible layout, each (in random order, twice over)
        moved to the first of a few random candidates that keeps the spacing: a random
        feasible layout near a dense one."""
        positions = known[rng.permutation(len(known))[:count]].copy()
        limit = self.spacing * (1.0 + SLACK)
        for _ in range(2):
            for i in rng.permutation(count):
                others = np.delete(positions, i, axis=0)
                for point in self.candidates(64, rng):
                    if len(others) == 0 or np.min(np.linalg.norm(others - point, axis=1)) >= limit:
                        positions[i] = point
                        break
        return positions


def make_feasible_region(mesh, placement, margin: float, spacing: float, max_tilt_deg: float, max_height: float | None = None) -> FeasibleRegion:
    """The FeasibleRegion of a sensor's tet mesh (checked numbers)."""
    placement = Placement.parse(placement, "placement")
    if max_height is not None and not (np.isfinite(max_height) and max_height > margin):
        raise HydrotactError(f"--max-height: must be a height above the board greater than the margin ({margin:g} m), got {max_height!r} m")
    for name, value in (("margin", margin), ("spacing", spacing)):
        if not np.isfinite(value) or value < 0.0:
            raise HydrotactError(f"--{name}: must be a non-negative length, got {value!r} m")
    if not (0.0 <= max_tilt_deg < 90.0):
        raise HydrotactError(f"--max-tilt: must be in [0, 90) deg (an axis must rise from the board towards the skin), got {max_tilt_deg!r}")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    return FeasibleRegion(
        vertices=vertices, faces=np.asarray(mesh.boundary_faces), tets=np.asarray(mesh.tets), placement=placement,
        margin=float(margin), spacing=float(spacing), max_tilt=float(np.radians(max_tilt_deg)), base_z=float(vertices[:, 2].min()),
        max_height=None if max_height is None else float(max_height),
    )
