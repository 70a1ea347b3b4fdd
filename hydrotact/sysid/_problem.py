"""Fit problems: logs turned into the arrays a fit runs on (host side).

A fit compares each log's barometer channels (and reference force columns, when the
log has them) with the model

    reading_c(t) = offset_c + gain_c · (E ∗ u_c)(t),

where (E ∗ u) is the hereditary integral of the unit-modulus response u with the Prony
relaxation modulus, a contact pushing but never pulling (visco.calc_contact_response).
The log carries the probe pose (`probe_x`, `probe_y`, `probe_z`, optional
`probe_rx`..`probe_rz`) and names a sensor spec and a probe; the simulator computes the
unit-modulus taxel pressures and contact force once per distinct pose, and the fit runs
in that reduced space (the elastic response is linear in E). A sensor nobody has
modelled, pressed by a stage, is fitted by the lumped press model instead
(`_press_fit.fit_press_logs`, `hydrotact fit --lumped`).

Each channel is weighted by its noise, estimated from the log itself (the median
absolute second difference, robust to contacts and ramps), so the residuals are in
units of noise standard deviations and the covariance needs no further scaling
beyond the reduced chi-square.
"""

import dataclasses
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._types import Array, Float, Int
from ..data import estimate_noise
from ._drift import drift_basis
from ._rig_problem import RigArrays, make_rig_arrays, rig_log_inputs

FORCE_COLUMNS = ("fx", "fy", "fz")
POSE_COLUMNS = ("probe_x", "probe_y", "probe_z")
ROTATION_COLUMNS = ("probe_rx", "probe_ry", "probe_rz")
# Channels whose unit response stays below this fraction of the strongest channel's
# never see the contact: their gain is not identifiable and stays 1.
_SILENT_FRACTION = 1e-3
# Relative gains: a channel whose readings move this many times more, or less, than
# the model's response of it, against the channels' median, does not read as modelled
# (dead, misplaced, or beyond the model): its gain is fitted outside the mean.
OUTLIER_GAIN = 4.0


def find_clipped_readings(log, channels, saturation_pa=None) -> np.ndarray:
    """(T, C) readings of an absolute log at or beyond its part's range (the part
    clips there: the pressure behind the reading is unknown), for a known sensor;
    with `saturation_pa`, also those at or above it (a part that clips below its
    rated limit)."""
    from ..data import sensor_spec

    if saturation_pa is not None:
        return (np.asarray(channels) >= float(saturation_pa)) | find_clipped_readings(log, channels)
    spec = sensor_spec(log.metadata.get("sensor", ""))
    if spec is None or log.metadata.get("pressure") != "absolute":
        return np.zeros(np.shape(channels), dtype=bool)
    low, high = spec.part.range_pa
    return (np.asarray(channels) <= low) | (np.asarray(channels) >= high)


class LogArrays(eqx.Module):
    """One log, ready for the residual function (device arrays).

    **Fields:**

    - `times` (T,) s.
    - `inputs` (T, C + F): unit-modulus responses of the C channels then the F force
      columns (Pa and N per Pa of E).
    - `observed` (T, C + F): the channels (Pa) and the reference forces (N).
    - `weights` (T, C + F): 1 / noise standard deviation; 0 where a barometer
      clipped (a reading at or beyond its part's range: the pressure is unknown there).
    - `offset_base`, `offset_scale` (C,): the channel's baseline is base + scale ·
      (drift @ θ) with θ (D,) per channel.
    - `drift` (T, D): the baseline's basis (a column of ones: a constant offset).
    - `gain_index` (C,): index into the shared gains, −1 for a fixed gain of 1.

    With a rig (:class:`FitProblem` `rig`), `inputs` are those at the rig's starts
    (for the linear start); the fit reads them off the rig's table at each step.
    """

    times: Float[Array, " num_samples"]
    inputs: Float[Array, "num_samples num_inputs"]
    observed: Float[Array, "num_samples num_columns"]
    weights: Float[Array, "num_samples num_columns"]
    offset_base: Float[Array, " num_channels"]
    offset_scale: Float[Array, " num_channels"]
    drift: Float[Array, "num_samples num_drift"]
    gain_index: Int[Array, " num_channels"]
    num_channels: int = eqx.field(static=True)


@dataclasses.dataclass(frozen=True)
class LogInfo:
    """What the report needs to know of a log (host)."""

    source: str
    channels: tuple[str, ...]
    force_columns: tuple[str, ...]
    sensor: str | None
    pressure: str
    sha256: str | None
    noise: tuple[float, ...]  # (C + F,) noise standard deviations, Pa and N


class FitProblem(eqx.Module):
    """A system-identification problem: the logs and how they are modelled.

    `gain_names` the shared channel gains that are free (keyed `sensor/channel`);
    with `relative_gains` (static) the first `num_reference_gains` are relative:
    their geometric mean is 1 (a pressure-only fit: the gains' common scale is E's);
    the rest (channels that do not read as modelled, :data:`OUTLIER_GAIN`) are free
    on their own; `logs` LogArrays; `infos` LogInfo per log (static); `rig` the stage rig's
    arrays (:class:`RigArrays`: its table, the stage columns, the bounds) for stage
    logs, with `rig_start` (static) every rig parameter's start; else None.
    """

    logs: tuple[LogArrays, ...]
    gain_names: tuple[str, ...] = eqx.field(static=True)
    infos: tuple[LogInfo, ...] = eqx.field(static=True)
    rig: RigArrays | None = None
    rig_start: tuple[float, ...] = eqx.field(static=True, default=())
    relative_gains: bool = eqx.field(static=True, default=False)
    num_reference_gains: int = eqx.field(static=True, default=0)
    gain_starts: tuple[float, ...] = eqx.field(static=True, default=())  # relative: each gain's start (the reference's geometric mean 1)

    @property
    def num_samples(self) -> int:
        """The residuals that count (the masked, clipped readings do not)."""
        return sum(int(np.count_nonzero(np.asarray(log.weights))) for log in self.logs)

    def without_infos(self) -> "FitProblem":
        """The same problem without the per-log descriptions: what jitted calls get,
        so that logs of the same shapes share one compilation (the descriptions are
        static and differ from log to log)."""
        return dataclasses.replace(self, infos=())


def file_digest(path) -> str | None:
    import hashlib

    path = Path(path)
    if not path.is_file():
        return None
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _log_pose_rows(log) -> np.ndarray:
    """(T, 6) the logged probe pose per sample: position (m), rotation vector (rad)."""
    zeros = np.zeros(log.num_samples)
    return np.column_stack([np.asarray(log.columns[name], dtype=np.float64) for name in POSE_COLUMNS] + [np.asarray(log.columns.get(name, zeros), dtype=np.float64) for name in ROTATION_COLUMNS])


def check_pose_columns(log, source: str) -> None:
    """Refuse a log without the probe pose columns a full-mode fit simulates."""
    missing = [name for name in POSE_COLUMNS if name not in log.columns]
    if missing:
        raise HydrotactError(f"{source}: a full-mode fit needs the probe pose; column {missing[0]!r} is missing (or fit with --lumped --indentation COLUMN)")


def log_probe(log, source: str):
    """The probe a log's metadata names, or an error naming the file and the field."""
    from ..contact import parse_probe

    if "probe" not in log.metadata:
        raise HydrotactError(f"{source}: metadata has no 'probe' (e.g. cylinder:d=2mm); a full-mode fit needs to know the probe")
    try:
        return parse_probe(log.metadata["probe"])
    except HydrotactError as error:
        raise HydrotactError(f"{source}: probe: {str(error).removeprefix('--probe').lstrip(': ')}") from None


def _log_model(log, source: str, field: str, num_rays: int):
    """The sensor model a log's metadata names, checked against its channels."""
    from ..sensors import load_sensor
    from ..sim import make_sensor_model

    metadata = log.metadata
    spec = load_sensor(metadata["sensor"], source=f"{source}: sensor")
    if spec.num_taxels != len(metadata["channels"]):
        raise HydrotactError(f"{source}: channels: {len(metadata['channels'])} channels, but sensor {spec.name} has {spec.num_taxels} taxels")
    return make_sensor_model(spec, field_kind=field, num_rays=num_rays)


def _unique_pose_responses(log, source: str, field: str, num_rays: int, progress: bool):
    """Unit responses of the log's taxels and contact force at its probe poses: each
    distinct pose is simulated once (holds repeat poses), through the simulator's
    cache of unit responses (so a log simulated by hydrotact fits at once)."""
    from ..sim import compute_trajectory_responses, make_trajectory

    check_pose_columns(log, source)
    model = _log_model(log, source, field, num_rays)
    probe = log_probe(log, source)
    rows = _log_pose_rows(log)
    trajectory = make_trajectory(np.asarray(log.times, dtype=np.float64), rows[:, :3], rows[:, 3:], source=source)
    unit = compute_trajectory_responses(model, probe, trajectory, progress=progress)
    return np.asarray(unit.taxel_pressures), np.asarray(unit.force_S)


def _channel_values(log) -> np.ndarray:
    return np.column_stack([np.asarray(log.columns[name], dtype=np.float64) for name in log.metadata["channels"]])


def make_fit_problem(
    logs, *, field: str | None = None, num_rays: int | None = None, use_forces: bool = True,
    unit_responses=None, sources=None, progress: bool = False, rig=None, drift="none", saturation_pa=None, gains: str | None = None,
) -> FitProblem:
    """Build a FitProblem from BarometerLogs (host).

    **Arguments:**

    - `logs`: BarometerLogs (hydrotact.data), fitted jointly: one material; offsets
      per log and channel; gains per channel, shared by logs of the same sensor.
    - `field`, `num_rays`: the strain field and rays per taxel (default: the
      log's metadata, else laplace and 64).
    - `use_forces`: also fit the reference force columns fx, fy, fz when
      the log has them; they fix the modulus' scale, so the channel gains are free.
      Without them the gains stay 1 (a gain and E are not separable from pressures).
    - `unit_responses`: per log, (taxel pressures (T, C), force (T, 3)) per
      pascal of E, if already computed (else simulated here from the logged poses).
    - `sources`: names for messages and the report (default: the log's path or index).
    - `rig`: a :class:`hydrotact.data.Rig` for stage logs (no probe pose columns): the
      probe's pose comes from the stage's columns, and its offsets, the home per log
      and the lag are fitted within the rig's bounds (the logs must share one
      sensor; the rig names the probe).
    - `drift`: each channel's baseline per log: "none" (a constant offset),
      "linear", or a knot spacing in s (cubic B-splines: a drifting barometer).
    - `saturation_pa`: readings at or above this are clipped too (masked), besides
      those at the part's range limits.
    - `gains`: each responding channel's gain (shared by logs of one sensor):
      "fixed" (1, what a pressure-only fit of a simulated sensor assumes), "free" (its
      own scale: needs the force columns, which fix E's), or "relative" (free with
      their geometric mean 1: a barometer's potting, port and part set its
      sensitivity, the mean is E's). Default: "free" where a log has force columns,
      "relative" for stage logs (`rig`), else "fixed".
    """
    if not logs:
        raise HydrotactError("no logs to fit")
    if num_rays is not None and (int(num_rays) != num_rays or num_rays < 1):
        raise HydrotactError(f"--rays: rays per taxel must be at least 1, got {num_rays}")
    sources = list(sources) if sources is not None else [f"log {k + 1}" for k in range(len(logs))]
    if gains not in (None, "fixed", "free", "relative"):
        raise HydrotactError(f"--gains: one of fixed, free, relative, got {gains!r}")
    if gains == "free" and not (use_forces and any(name in log.columns for log in logs for name in FORCE_COLUMNS)):
        raise HydrotactError("--gains free: no log has force columns (fx, fy, fz) to fix the modulus' scale (a gain and E are not separable); use --gains relative")
    rig_arrays = rig_starts = None
    if rig is not None:
        from ..contact import parse_probe

        sensors = {log.metadata["sensor"] for log in logs}
        if len(sensors) > 1:
            raise HydrotactError(f"--rig: the logs come from {len(sensors)} sensors ({', '.join(sorted(sensors))}); a rig's logs are of one sensor")
        log_field = logs[0].metadata.get("field", "laplace") if field is None else field
        log_rays = logs[0].metadata.get("num_rays", 64) if num_rays is None else num_rays
        model = _log_model(logs[0], sources[0], log_field, log_rays)
        every = [np.arange(len(log.metadata["channels"]) + 3) for log in logs]
        rig_arrays, rig_starts = make_rig_arrays(rig, model, parse_probe(rig.probe), logs, sources, every, progress=progress, drift=drift, saturation_pa=saturation_pa)
    prepared, infos, gain_names, columns, excursions = [], [], [], [], {}
    for k, (log, source) in enumerate(zip(logs, sources)):
        if log.num_samples < 8:
            raise HydrotactError(f"{source}: {log.num_samples} samples; a fit needs at least 8")
        channels = tuple(log.metadata["channels"])
        observed = _channel_values(log)
        times = np.asarray(log.times, dtype=np.float64)
        force_columns: tuple[str, ...] = ()
        metadata = log.metadata
        if unit_responses is not None:
            taxels, forces = (np.asarray(a, dtype=np.float64) for a in unit_responses[k])
            if taxels.shape != observed.shape or forces.shape != (len(times), 3):
                raise HydrotactError(f"{source}: unit responses of shapes {taxels.shape} and {forces.shape} do not match {observed.shape} channels and (T, 3) forces")
        elif rig_arrays is not None:
            full = np.asarray(rig_log_inputs(rig_arrays, jnp.asarray(rig_starts), k, jnp.asarray(times)))
            taxels, forces = full[:, : len(channels)], full[:, len(channels) :]
        else:
            log_field = metadata.get("field", "laplace") if field is None else field
            log_rays = metadata.get("num_rays", 64) if num_rays is None else num_rays
            taxels, forces = _unique_pose_responses(log, source, log_field, log_rays, progress)
        inputs = taxels
        if use_forces:
            force_columns = tuple(name for k, name in enumerate(FORCE_COLUMNS) if name in log.columns and np.max(np.abs(forces[:, k])) > 0.0)
            keep = [FORCE_COLUMNS.index(name) for name in force_columns]
            inputs = np.column_stack([taxels, forces[:, keep]])
            observed = np.column_stack([observed] + [np.asarray(log.columns[name], dtype=np.float64) for name in force_columns])
            columns.append(list(range(len(channels))) + [len(channels) + i for i in keep])
        else:
            columns.append(list(range(len(channels))))
        num_channels = len(channels)
        clipped = np.zeros(observed.shape, dtype=bool)
        clipped[:, :num_channels] = find_clipped_readings(log, observed[:, :num_channels], saturation_pa)
        noise = estimate_noise(observed)
        gain_index = np.full(num_channels, -1)
        if gains in ("free", "relative") or (gains is None and (force_columns or rig is not None)):
            strength = np.max(np.abs(inputs[:, :num_channels]), axis=0)
            strength[np.all(clipped[:, :num_channels], axis=0)] = 0.0  # every reading clipped: nothing tells its gain
            for c in np.flatnonzero(strength > _SILENT_FRACTION * strength.max()):
                name = f"{log.metadata['sensor']}/{channels[c]}"
                if name not in gain_names:
                    gain_names.append(name)
                gain_index[c] = gain_names.index(name)
                excursions.setdefault(name, []).append(_excursion_ratio(observed[:, c], inputs[:, c], ~clipped[:, c]))
        baseline = np.median(observed[: max(4, len(times) // 50), :num_channels], axis=0)
        prepared.append(
            LogArrays(
                times=jnp.asarray(times),
                inputs=jnp.asarray(inputs),
                observed=jnp.asarray(observed),
                weights=jnp.asarray(np.where(clipped, 0.0, 1.0 / noise[None, :])),
                offset_base=jnp.asarray(baseline),
                offset_scale=jnp.asarray(noise[:num_channels]),
                drift=jnp.asarray(drift_basis(times, drift)),
                gain_index=jnp.asarray(gain_index),
                num_channels=num_channels,
            )
        )
        infos.append(
            LogInfo(
                source=source, channels=channels, force_columns=force_columns, sensor=log.metadata.get("sensor"),
                pressure=log.metadata.get("pressure", "absolute"), sha256=file_digest(source), noise=tuple(float(v) for v in noise),
            )
        )
    if rig_arrays is not None:
        rig_arrays = eqx.tree_at(lambda r: r.columns, rig_arrays, tuple(jnp.asarray(c) for c in columns))
    relative = gains == "relative" or (gains is None and rig is not None and not any(info.force_columns for info in infos))
    num_reference, starts = len(gain_names), ()
    if relative and gain_names:
        gain_names, num_reference, starts, prepared = _order_relative_gains(gain_names, excursions, prepared)
    return FitProblem(
        logs=tuple(prepared), gain_names=tuple(gain_names), infos=tuple(infos), rig=rig_arrays,
        rig_start=() if rig_starts is None else tuple(float(v) for v in rig_starts), relative_gains=relative, num_reference_gains=num_reference,
        gain_starts=starts,
    )


def _excursion_ratio(observed, response, used) -> float:
    """How far a channel's readings move, the way its unit response moves (up for a
    pressure, down where the model says tension), per unit of that response: the
    99.5th percentile of each from the readings' median (robust to spikes; its scale
    is E's)."""
    observed, response = observed[used], response[used]
    if not len(observed):
        return 0.0
    sign = 1.0 if response[np.argmax(np.abs(response))] >= 0.0 else -1.0
    moved = np.percentile(sign * (observed - np.median(observed)), 99.5)
    return float(max(moved, 0.0) / max(float(np.percentile(np.abs(response), 99.5)), 1e-300))


def _order_relative_gains(gain_names, excursions, prepared):
    """The relative gains' reference first (channels whose readings move, per unit of
    the model's response, within :data:`OUTLIER_GAIN` of the channels' median), the
    outliers after it; each log's gain_index remapped. Returns (names, the
    reference's count, each gain's start (the ratio against the reference's
    geometric mean), logs)."""
    ratios = np.array([np.median(excursions[name]) for name in gain_names])
    centre = np.median(ratios[ratios > 0.0]) if np.any(ratios > 0.0) else 1.0
    outside = [not (centre / OUTLIER_GAIN <= ratio <= centre * OUTLIER_GAIN) for ratio in ratios]
    if all(outside):  # no channel moved (every ratio 0): none to set apart from
        outside = [False] * len(ratios)
    order = [k for k in range(len(gain_names)) if not outside[k]] + [k for k in range(len(gain_names)) if outside[k]]
    where = np.full(len(gain_names) + 1, -1)
    where[np.asarray(order)] = np.arange(len(order))
    prepared = [eqx.tree_at(lambda log: log.gain_index, log, jnp.asarray(where[np.asarray(log.gain_index)])) for log in prepared]
    count = len(order) - sum(outside)
    ratios = np.maximum(ratios[np.asarray(order)], 1e-6 * centre)
    starts = ratios / np.exp(np.mean(np.log(ratios[:count])))
    return [gain_names[k] for k in order], count, tuple(float(v) for v in starts), prepared
