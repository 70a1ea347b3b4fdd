"""Probe trajectories: sample times and the probe's pose X_SR at each, checked."""

import csv
import difflib
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError, where
from .._types import Array, Float
from .._units import LENGTH_UNITS
from ..contact import Pose, make_pose

TRAJECTORY_COLUMNS = ("time", "x", "y", "z")
ROTATION_COLUMNS = ("rx", "ry", "rz")


class Trajectory(eqx.Module):
    """A probe trajectory: at time `times[k]` (s) the probe frame R sits at the pose
    given by `translations[k]` (the origin of R in the sensor frame S, m) and
    `rotation_vectors[k]` (R's orientation in S as a rotation vector, rad). Built-in
    probes have their tip at R's origin.

    These rows are the one stored form of a pose along a trajectory; `X_SR` (the
    batched Pose the contact stage takes) is computed from them, so a gradient with
    respect to the trajectory is one with respect to translations and rotation
    vectors. `rows` (T, 6) is the same data side by side, the key for finding the
    distinct poses of a trajectory (:func:`hydrotact.sim.find_distinct_poses`).
    """

    times: Float[Array, " num_samples"]
    translations: Float[Array, "num_samples 3"]
    rotation_vectors: Float[Array, "num_samples 3"]

    @property
    def num_samples(self) -> int:
        return self.times.shape[0]

    @property
    def X_SR(self) -> Pose:
        return jax.vmap(make_pose)(self.translations, self.rotation_vectors)

    @property
    def rows(self):
        return jnp.concatenate([self.translations, self.rotation_vectors], axis=-1)


def make_trajectory(times, translations, rotation_vectors=None, source: str | None = None) -> Trajectory:
    """A checked Trajectory (host): finite values, strictly increasing times, one
    translation (m) and optional rotation vector (rad) per time."""
    times = np.asarray(times, dtype=np.float64)
    translations = np.asarray(translations, dtype=np.float64)
    if times.ndim != 1 or times.shape[0] == 0:
        raise HydrotactError(f"{where(source)}a trajectory needs at least one sample time")
    if translations.shape != (times.shape[0], 3):
        raise HydrotactError(f"{where(source)}expected {times.shape[0]} probe positions (x, y, z), got shape {translations.shape}")
    rotation_vectors = np.zeros_like(translations) if rotation_vectors is None else np.asarray(rotation_vectors, dtype=np.float64)
    if rotation_vectors.shape != translations.shape:
        raise HydrotactError(f"{where(source)}expected {times.shape[0]} rotation vectors, got shape {rotation_vectors.shape}")
    for name, values in (("time", times), ("position", translations), ("rotation", rotation_vectors)):
        bad = np.flatnonzero(~np.all(np.isfinite(values.reshape(len(times), -1)), axis=1))
        if bad.size:
            raise HydrotactError(f"{where(source)}row {bad[0] + 1}: {name} is not a finite number")
    steps = np.diff(times)
    if np.any(steps <= 0.0):
        row = int(np.flatnonzero(steps <= 0.0)[0]) + 2
        raise HydrotactError(f"{where(source)}row {row}: time {times[row - 1]:g} s does not increase (previous {times[row - 2]:g} s)")
    return Trajectory(times=jnp.asarray(times), translations=jnp.asarray(translations), rotation_vectors=jnp.asarray(rotation_vectors))


def check_header(header: list[str], source: str) -> None:
    """A trajectory header: time, x, y, z and optionally all of rx, ry, rz, each once,
    nothing else (an unknown name is a typo or a misread file, never ignored)."""
    if len(header) == 1 and any(mark in header[0] for mark in ";\t|"):
        mark = next(mark for mark in ";\t|" if mark in header[0])
        raise HydrotactError(f"{source}: the header {header[0][:40]!r} is one field: the file separates fields by {mark!r}; hydrotact reads comma-separated values")
    for index, name in enumerate(header):
        if name in header[:index]:
            raise HydrotactError(f"{source}: column {name!r} appears twice in the header ({', '.join(header)})")
    known = TRAJECTORY_COLUMNS + ROTATION_COLUMNS
    for name in header:
        if name not in known:
            lower = [k for k in known if k == name.strip().lower()]
            close = lower or difflib.get_close_matches(name, known, n=1)
            hint = f" (did you mean {close[0]!r}?{' names are lower case' if lower else ''})" if close else ""
            raise HydrotactError(f"{source}: unknown column {name!r}{hint}; a trajectory has time, x, y, z and optionally rx, ry, rz")
    missing = [name for name in TRAJECTORY_COLUMNS if name not in header]
    if missing:
        raise HydrotactError(f"{source}: missing column(s) {', '.join(missing)} (has {', '.join(header) or 'no header'})")


def read_trajectory(path, units: str = "m") -> Trajectory:
    """A trajectory from a CSV file with a header row: columns `time` (s), `x`, `y`,
    `z` (the probe tip in the sensor frame, in `units`) and optionally `rx`, `ry`,
    `rz` (rotation vector, rad), in any order. Rows are numbered from 1 after the
    header; blank lines are skipped (but counted)."""
    path = Path(path)
    if units not in LENGTH_UNITS:
        raise HydrotactError(f"{path}: unknown length unit {units!r}; use one of {sorted(LENGTH_UNITS)}")
    if not path.is_file():
        raise HydrotactError(f"{path}: no such trajectory file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:  # -sig: a byte-order mark (Excel) is no part of the header
            reader = csv.reader(handle)
            header = [name.strip() for name in next(reader, [])]
            rows = list(reader)
    except (UnicodeDecodeError, csv.Error) as error:
        raise HydrotactError(f"{path}: not a CSV text file ({str(error)[:80]})") from None
    check_header(header, str(path))
    rotations = [name for name in ROTATION_COLUMNS if name in header]
    if rotations and len(rotations) != 3:
        raise HydrotactError(f"{path}: give all of rx, ry, rz or none (has {', '.join(rotations)})")
    wanted = list(TRAJECTORY_COLUMNS) + rotations
    index = [header.index(name) for name in wanted]
    numbered = [(number, row) for number, row in enumerate(rows, start=1) if any(field.strip() for field in row)]  # skip blank lines; rows keep their numbers
    values = np.empty((len(numbered), len(wanted)))
    for k, (row_number, row) in enumerate(numbered):
        if len(row) != len(header):
            hint = " (decimal commas? write 0.5, not 0,5)" if len(row) > len(header) else ""
            raise HydrotactError(f"{path}: row {row_number}: {len(row)} fields, expected {len(header)}{hint}")
        for j, (name, column) in enumerate(zip(wanted, index)):
            try:
                values[k, j] = float(row[column])
            except ValueError:
                raise HydrotactError(f"{path}: row {row_number}, column {name}: not a number: {row[column]!r}") from None
            if not np.isfinite(values[k, j]):
                raise HydrotactError(f"{path}: row {row_number}, column {name}: {row[column].strip()} is not a finite number")
    back = np.flatnonzero(np.diff(values[:, 0]) <= 0.0)
    if back.size:
        k = int(back[0]) + 1
        raise HydrotactError(f"{path}: row {numbered[k][0]}, column time: time {values[k, 0]:g} s does not increase (previous {values[k - 1, 0]:g} s)")
    scale = LENGTH_UNITS[units]
    return make_trajectory(values[:, 0], values[:, 1:4] * scale, values[:, 4:7] if rotations else None, source=str(path))


def resample_trajectory(trajectory: Trajectory, rate_hz: float) -> Trajectory:
    """The trajectory at a barometer's sample instants t₀ + k / rate within its span,
    translations and rotation vectors linear in time between the given samples (as a
    stage moves between waypoints) (host: the number of samples depends on the span)."""
    from ..visco import calc_sample_times

    times = np.asarray(trajectory.times)
    samples = calc_sample_times(times, rate_hz)
    translations = np.column_stack([np.interp(samples, times, column) for column in np.asarray(trajectory.translations).T])
    rotations = np.column_stack([np.interp(samples, times, column) for column in np.asarray(trajectory.rotation_vectors).T])
    return make_trajectory(samples, translations, rotations)


def find_distinct_poses(trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory's distinct poses, in the order they first occur, and the index
    of each sample's pose among them (host). A probe held still repeats its pose, and
    a pose's response is computed once: holds make up most of a press-and-hold log.

    **Returns:** (rows (D, 6): translation m, rotation vector rad; index (T,) ints).
    """
    rows = np.asarray(trajectory.rows, dtype=np.float64)
    _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
    order = np.sort(first)
    position = np.empty(len(rows), dtype=np.int64)
    position[order] = np.arange(len(order))
    return rows[order], position[first[inverse.reshape(-1)]]
