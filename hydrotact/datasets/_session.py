"""One continuous data-collection session: approach marches, the timeline, and the
samples with their labels (host around pure kernels).

Each event approaches its skin point along its drawn direction at its drawn speed,
one sample per 1/rate, no deeper than its own limit (:attr:`EventPlan.max_depths`).
The approaches of all events march together in rounds (one batch of unit responses per
round), each event taking as many samples as its force so far predicts it still needs
(at most `ROUND_SAMPLES`): after each round an event whose elastic force along its
approach E(0) F(s)·d has reached its target stops, and its hold depth is interpolated
linearly between its last two samples (the approach samples find the depth; there is no
separate search). An event with a target depth (the paper's regime) marches to the
first sample at or past it and holds at the depth itself. The holds (one pose each)
are computed last. The retract retraces the approach's poses in reverse.

Then the session's timeline is laid out (gap, approach, hold, retract per event) and
the whole of it goes through :func:`hydrotact.sim.calc_samples` at once: the
hereditary integral runs over the session, so the residual stress of one event is
still there in the next, as on a real gantry; then the barometer signal.
"""

import dataclasses
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._files import atomic_path
from ..sim import SimCapacity, UnitResponse, calc_samples
from ._compute import calc_start_rungs
from ._config import PHASES, DatasetConfig
from ._events import EventPlan

ROUND_SAMPLES = 8
"""The most approach samples per event per round of the march (before contact, and
while the force so far predicts more)."""

_PAIRS = [field.name for field in dataclasses.fields(SimCapacity)].index("pairs")
"""Where UnitResponse.needed counts the contact's candidate pairs (none without contact)."""

FAR_ROW = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
"""The probe's pose between events: a metre above the sensor (no contact)."""


@dataclasses.dataclass(frozen=True)
class Presses:
    """The outcome of the march: a table of distinct poses (`rows` (P, 6) and their
    unit responses `table`, a dict of UnitResponse fields), per event the table
    indices of its approach samples (`approach`, a list of arrays), of its hold pose
    (`hold` (N,)), its approach `depths` (list of arrays, m past the skin point) and
    `hold_depths` (N,), whether the target was `reached` (N,), the elastic force along
    the approach at the hold `hold_forces` (N,), N; `far` the index of the no-contact
    pose; `num_rounds` the batches computed (the holds' included)."""

    rows: np.ndarray
    table: dict
    approach: list
    depths: list
    hold: np.ndarray
    hold_depths: np.ndarray
    reached: np.ndarray
    hold_forces: np.ndarray
    far: int
    num_rounds: int


def _pose_rows(plan: EventPlan, events: np.ndarray, depths: np.ndarray) -> np.ndarray:
    tips = plan.points[events] + depths[:, None] * plan.directions[events]
    return np.column_stack([tips, plan.rotation_vectors[events]])


def _axial_forces(forces_S: np.ndarray, directions: np.ndarray, modulus: float) -> np.ndarray:
    """The elastic force E(0) F·d along each press's approach direction d (what the
    gantry's load cell controls to its target): not the contact normal force, which on
    a curved skin near the board can stay small while the probe sinks past its own
    radius and the total force grows to several times the target (measured on sphere8:
    30 N with 4 N along the field's normal)."""
    return modulus * np.sum(forces_S * directions, axis=1)


BATCH_ROWS = 1024
"""The most poses computed, saved and reported at once: a round of the march is cut into
batches of this many (a multiple of the engine's slice), so that the progress moves and
a killed run loses at most one batch."""


class _Rounds:
    """Batches of poses, each computed once: looked up in the run's checkpoint folder
    (`batch-NNNNN.npz`, the rows must match exactly) or computed and saved there."""

    def __init__(self, engine, folder: Path | None, on_poses=None):
        self.engine, self.folder, self.on_poses = engine, folder, on_poses
        self.rows, self.parts, self.count, self.rounds = [], [], 0, 0

    def _batch(self, rows: np.ndarray, needs) -> dict:
        number = len(self.rows)
        path = None if self.folder is None else self.folder / f"batch-{number:05d}.npz"
        result, restored = None, False
        if path is not None and path.is_file():
            try:
                with np.load(path, allow_pickle=False) as saved:
                    if saved["rows"].shape == rows.shape and np.array_equal(saved["rows"], rows):
                        result, restored = {name: saved[name] for name in saved.files if name != "rows"}, True
            except (OSError, ValueError, KeyError, EOFError):
                result = None  # unreadable: compute again
        if result is None:
            result = self.engine.compute(rows, needs)
            if path is not None:
                with atomic_path(path, suffix=".npz") as tmp:
                    np.savez(tmp, rows=rows, **result)
        if self.on_poses is not None:
            self.on_poses(len(rows), restored)
        self.rows.append(rows)
        self.parts.append(result)
        return result

    def add(self, rows: np.ndarray, needs: np.ndarray) -> tuple[np.ndarray, dict]:
        """Compute (or load) one round, in batches: (the table indices of its rows,
        its unit responses); `needs` (n, 6) the buffers each row is predicted to need
        (:func:`hydrotact.datasets._compute.compute_block`)."""
        parts = [self._batch(rows[start : start + BATCH_ROWS], needs[start : start + BATCH_ROWS]) for start in range(0, len(rows), BATCH_ROWS)]
        self.rounds += 1
        index = np.arange(self.count, self.count + len(rows))
        self.count += len(rows)
        return index, {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}

    def table(self) -> tuple[np.ndarray, dict]:
        names = self.parts[0].keys()
        return np.concatenate(self.rows), {name: np.concatenate([part[name] for part in self.parts]) for name in names}


def _samples_to_go(forces: list, target: float) -> int:
    """Approach samples an event still needs, predicted from its last two: with both
    touching and rising, √F is extrapolated linearly in depth to the target, plus one
    sample of margin (a rounded probe's hydroelastic force grows about like depth²:
    contact area and pressure each grow with depth; on sphere8 the slope of √F against
    depth for a 3 mm sphere falls by about 10 % from 1 to 7 mm, so the prediction
    errs short, by one more round, rather than long). ROUND_SAMPLES before contact.
    Under-predicting costs one more round (a batch); over-predicting, poses past the
    target."""
    if len(forces) < 2 or not forces[-1] > forces[-2] or not forces[-1] > 0.0:
        return ROUND_SAMPLES
    low, high = np.sqrt(max(forces[-2], 0.0)), np.sqrt(forces[-1])
    ahead = (np.sqrt(target) - high) / (high - low)
    return int(np.clip(np.ceil(ahead) + 1, 1, ROUND_SAMPLES))


def _predicted_needs(needs: list, first: int, count: int) -> np.ndarray:
    """(count, 6): the buffers an event's approach samples `first` .. `first + count
    - 1` are predicted to need, from its samples so far (`needs[k]`, sample k's): the
    last one's, grown as between its last two when both touch (a deeper press needs
    more; at first contact the need jumps from nothing to whole clusters of tets, no
    slope to extrapolate); zeros before any. A prediction only chooses where a slice
    starts on the engine's ladder: one too low costs a climb, never a wrong answer."""
    if not needs:
        return np.zeros((count, len(SimCapacity().sizes)))
    touching = len(needs) > 1 and needs[-2][_PAIRS] > 0
    slope = np.maximum(needs[-1] - needs[-2], 0) if touching else np.zeros_like(needs[-1])
    ahead = np.arange(first, first + count) - (len(needs) - 1)
    return needs[-1] + ahead[:, None] * slope


def march_presses(engine, plan: EventPlan, config: DatasetConfig, modulus: float, folder: Path | None = None, on_poses=None, on_round=None) -> Presses:
    """March every event's approach until its target force (see the module), then
    compute the holds and the no-contact pose. `folder` keeps each batch's responses
    (resumable); `on_poses(n, restored)` after each batch of n poses (`restored`:
    read back from `folder`, not computed); `on_round(active,
    poses_to_go)` after each round, with a prediction of the poses still to compute."""
    count = plan.num_events
    steps = plan.speeds / config.rate_hz
    limits = np.floor((plan.max_depths + config.clearance) / steps + 1e-9).astype(np.int64) + 1  # samples up to the event's max depth
    rounds = _Rounds(engine, folder, on_poses)
    index_of = [[] for _ in range(count)]  # table index per approach sample so far
    forces = [[] for _ in range(count)]
    needs = [[] for _ in range(count)]  # the buffers each approach sample needed
    done = np.zeros(count, dtype=bool)
    first_above = np.full(count, -1)  # the first sample at or above the target
    taken = np.zeros(count, dtype=np.int64)  # approach samples computed per event
    by_depth = config.target == "depth"
    if by_depth:  # the first sample at or past the target depth: every event's samples are known from the start
        at_target = np.ceil((plan.target_depths + config.clearance) / steps - 1e-9).astype(np.int64)
        depth_stops = np.minimum(at_target + 1, limits)
    while not done.all():
        active = np.flatnonzero(~done)
        if by_depth:
            wanted = np.minimum(depth_stops[active] - taken[active], ROUND_SAMPLES)
        else:
            wanted = np.array([_samples_to_go(forces[e], plan.target_forces[e]) for e in active.tolist()], dtype=np.int64)
        starts = taken[active]
        stops = np.minimum(starts + wanted, limits[active])
        lengths = stops - starts
        events = np.repeat(active, lengths)
        k = np.concatenate([np.arange(a, b) for a, b in zip(starts, stops)])
        depths = -config.clearance + k * steps[events]
        predicted = np.concatenate([_predicted_needs(needs[e], a, b - a) for e, a, b in zip(active.tolist(), starts.tolist(), stops.tolist())])
        # Computed by the rung they are predicted to need, shallowest first within
        # one: the engine's slices then hold poses of like needs, and a slice's buffers
        # grow to its hardest pose only (a deep press can need 20x the buffers of a
        # light one, a press near the sensor's base more than one on top).
        order = np.lexsort((depths, calc_start_rungs(engine.probe, predicted)))
        index, force, needed = np.empty(len(events), np.int64), np.empty(len(events)), np.empty((len(events), predicted.shape[1]))
        index[order], result = rounds.add(_pose_rows(plan, events[order], depths[order]), predicted[order])
        force[order] = _axial_forces(result["force_S"], plan.directions[events[order]], modulus)
        needed[order] = result["needed"]
        offset = 0
        for event, length in zip(active.tolist(), lengths.tolist()):
            new = force[offset : offset + length]
            index_of[event] += index[offset : offset + length].tolist()
            forces[event] += new.tolist()
            needs[event] += list(needed[offset : offset + length])
            offset += length
            if by_depth:
                if taken[event] + length >= depth_stops[event]:
                    first_above[event] = at_target[event] if at_target[event] < limits[event] else -1
                    done[event] = True
                continue
            above = np.flatnonzero(new >= plan.target_forces[event])
            if above.size:
                first_above[event] = taken[event] + int(above[0])
                done[event] = True
            elif taken[event] + length >= limits[event]:
                done[event] = True
        taken[active] = stops
        if on_round is not None:
            still = np.flatnonzero(~done)
            to_go = int((depth_stops[still] - taken[still]).sum()) if by_depth else sum(min(_samples_to_go(forces[e], plan.target_forces[e]), int(limits[e] - taken[e])) for e in still.tolist())
            on_round(len(still), to_go + count + 1)
    reached = first_above >= 0
    hold_depths = np.empty(count)
    approach, depths = [], []
    hold_needs = np.empty((count, len(SimCapacity().sizes)))
    for event in range(count):
        step = steps[event]
        if reached[event]:
            j = int(first_above[event])
            if by_depth:
                hold_depths[event] = plan.target_depths[event]
            elif j == 0:
                hold_depths[event] = -config.clearance
            else:
                low, high = forces[event][j - 1], forces[event][j]
                fraction = (plan.target_forces[event] - low) / (high - low) if high > low else 1.0
                hold_depths[event] = -config.clearance + (j - 1 + float(np.clip(fraction, 0.0, 1.0))) * step
            used = j
        else:  # the target lies deeper than max_depth: hold at the last sample
            used = int(limits[event]) - 1
            hold_depths[event] = -config.clearance + used * step
        hold_needs[event] = needs[event][used]  # the sample at or past the hold: it needs no less
        approach.append(np.asarray(index_of[event][:used], dtype=np.int64))
        depths.append(-config.clearance + np.arange(used) * step)
    # By rung and shallowest first, as in the march: in event order nearly every slice
    # held a deep hold and climbed to the largest buffers.
    order = np.lexsort((hold_depths, calc_start_rungs(engine.probe, hold_needs)))
    index, _ = rounds.add(np.vstack([_pose_rows(plan, order, hold_depths[order]), FAR_ROW[None]]), np.vstack([hold_needs[order], np.zeros_like(hold_needs[:1])]))
    hold = np.empty(count, dtype=np.int64)
    hold[order] = index[:count]
    rows, table = rounds.table()
    return Presses(
        rows=rows, table=table, approach=approach, depths=depths, hold=hold, hold_depths=hold_depths, reached=reached,
        hold_forces=_axial_forces(table["force_S"][hold], plan.directions, modulus), far=int(index[count]), num_rounds=rounds.rounds,
    )


@dataclasses.dataclass(frozen=True)
class Timeline:
    """Per sample of the session: `pose` (the table index), `event` (-1 in gaps),
    `phase` (:data:`PHASES`), `depth` (m past the event's skin point; NaN in gaps);
    `event_starts` (N + 1,) the first sample of each event's gap (and the end)."""

    pose: np.ndarray
    event: np.ndarray
    phase: np.ndarray
    depth: np.ndarray
    event_starts: np.ndarray

    @property
    def num_samples(self) -> int:
        return len(self.pose)


def lay_out_timeline(plan: EventPlan, presses: Presses, config: DatasetConfig) -> Timeline:
    """The session: per event a gap, the approach, the hold and the retract; a last gap."""
    pose, event, phase, depth, starts = [], [], [], [], []
    total = 0

    def append(poses, number, code, depths):
        nonlocal total
        pose.append(np.asarray(poses, dtype=np.int64))
        event.append(np.full(len(poses), number, dtype=np.int32))
        phase.append(np.full(len(poses), code, dtype=np.int8))
        depth.append(np.asarray(depths, dtype=np.float64))
        total += len(poses)

    def gap(seconds):
        n = max(1, int(round(seconds * config.rate_hz)))
        append(np.full(n, presses.far), -1, PHASES["gap"], np.full(n, np.nan))

    for e in range(plan.num_events):
        starts.append(total)
        gap(plan.gaps[e])
        append(presses.approach[e], e, PHASES["approach"], presses.depths[e])
        n = max(1, int(round(plan.holds[e] * config.rate_hz)))
        append(np.full(n, presses.hold[e]), e, PHASES["hold"], np.full(n, presses.hold_depths[e]))
        append(presses.approach[e][::-1], e, PHASES["retract"], presses.depths[e][::-1])
    gap(config.gap_range[1])
    starts.append(total)
    return Timeline(np.concatenate(pose), np.concatenate(event), np.concatenate(phase), np.concatenate(depth), np.asarray(starts, dtype=np.int64))


_calc_samples = eqx.filter_jit(calc_samples)


def run_session(model, material, presses: Presses, timeline: Timeline, config: DatasetConfig, signal, key) -> dict:
    """The session's samples and labels as columns (NumPy arrays; see the manifest's
    column list): the whole timeline through the viscoelastic response and the
    barometer signal in one pure call."""
    times = np.arange(timeline.num_samples) / config.rate_hz
    unit = UnitResponse(**{name: jnp.asarray(values[timeline.pose]) for name, values in presses.table.items()})
    samples = _calc_samples(model, material, jnp.asarray(times), unit, signal, key)
    samples = jax.tree_util.tree_map(np.asarray, samples)
    touching = np.asarray(samples.unit.area) > 0.0
    columns = {"time": times}
    return columns | {
        "readings": samples.readings,
        "fx": samples.force_S[:, 0], "fy": samples.force_S[:, 1], "fz": samples.force_S[:, 2],
        "fn": samples.normal_force, "theta": samples.theta, "phi": samples.phi,
        "contact": samples.contact.astype(np.int8),
        "cop_x": np.where(touching, samples.unit.contact_point_S[:, 0], np.nan),
        "cop_y": np.where(touching, samples.unit.contact_point_S[:, 1], np.nan),
        "cop_z": np.where(touching, samples.unit.contact_point_S[:, 2], np.nan),
        "depth": timeline.depth, "event": timeline.event, "phase": timeline.phase,
        "probe": presses.rows[timeline.pose],
        "elastic": samples.taxel_pressures,
    }
