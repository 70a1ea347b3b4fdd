"""The `hydrotact simulate` job: a sensor, a probe and a trajectory file -> a barometer
log (Parquet) and a plot of its traces.

Long trajectories are simulated in blocks; each finished block is saved beside the
output (`.LOG.partial.npz`, atomically), so an interrupted run resumes where it
stopped when started again with the same inputs. The log itself is written atomically
at the end, and the partial file removed.
"""

import dataclasses
import json
from pathlib import Path

import jax
import numpy as np

from . import __version__
from ._errors import HydrotactError
from ._files import atomic_path, digest
from .data import BarometerLog, write_log
from .sim import Material, UnitResponse, compute_unit_responses, make_material, make_sensor_model, make_trajectory, read_trajectory, scale_unit_responses

BLOCK = 512


def _resume_key(*parts) -> str:
    return digest(*(np.ascontiguousarray(p).tobytes() if isinstance(p, np.ndarray) else p for p in parts))


def _load_partial(partial: Path, key: str) -> list:
    """The blocks saved in `partial` if it was written for `key`; [] if it is absent,
    of other inputs, or unreadable (it is only a cache: recompute rather than fail)."""
    import zipfile

    if not partial.is_file():
        return []
    try:
        with partial.open("rb") as handle, np.load(handle, allow_pickle=False) as saved:  # our handle: np.load leaks its own on a bad zip
            if str(saved["key"]) != key:
                return []
            return [dict((name[len(f"{k}/"):], saved[name]) for name in saved.files if name.startswith(f"{k}/")) for k in range(int(saved["num_blocks"]))]
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return []


def distinct_poses(trajectory):
    """(the trajectory's distinct poses as a batched Pose, index of each sample's pose):
    a probe held still repeats its pose, and a pose's response is computed once."""
    rows = np.column_stack([np.asarray(trajectory.X_SR.translation), np.asarray(trajectory.rotation_vectors)])
    _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
    order = np.sort(first)  # keep the trajectory's order (progress, resuming)
    position = np.empty(len(rows), dtype=np.int64)
    position[order] = np.arange(len(order))
    index = position[first[inverse.reshape(-1)]]
    return jax.tree_util.tree_map(lambda a: a[order], trajectory.X_SR), index


def compute_responses_resumably(model, probe, trajectory, partial: Path, key: str, progress: bool = True):
    """Unit responses along the trajectory, block by block over its distinct poses,
    saved to `partial` after each block; a matching `partial` from an interrupted run
    is picked up (host)."""
    from tqdm.auto import tqdm

    X_SR, index = distinct_poses(trajectory)
    count = X_SR.translation.shape[0]
    blocks = _load_partial(partial, key)
    done = sum(len(block["area"]) for block in blocks)  # not len(blocks) * BLOCK: the blocks may have been saved with another BLOCK
    capacity = None
    with tqdm(total=count, initial=min(count, done), unit="pose", desc=f"simulating {model.name} ({count} distinct poses)", disable=not progress) as bar:
        for start in range(done, count, BLOCK):
            stop = min(count, start + BLOCK)
            poses = jax.tree_util.tree_map(lambda a: a[start:stop], X_SR)
            unit, capacity = compute_unit_responses(model, probe, poses, capacity)
            blocks.append({field.name: np.asarray(getattr(unit, field.name)) for field in dataclasses.fields(unit)})
            arrays = {f"{k}/{name}": value for k, block in enumerate(blocks) for name, value in block.items()}
            with atomic_path(partial, suffix=".npz") as tmp:
                np.savez(tmp, key=np.array(key), num_blocks=np.array(len(blocks)), **arrays)
            bar.update(stop - start)
    return {name: np.concatenate([block[name] for block in blocks])[index] for name in blocks[0]}


def samples_to_log(spec, samples, trajectory_translations, rotation_vectors, metadata_extra: dict) -> BarometerLog:
    """A BarometerLog (pressure 'elastic') from simulated samples."""
    columns = {"time": np.asarray(samples.times, dtype=np.float64)}
    for k, name in enumerate(spec.taxel_names):
        columns[name] = np.asarray(samples.taxel_pressures[:, k])
    for k, axis in enumerate("xyz"):
        columns[f"probe_{axis}"] = trajectory_translations[:, k]
    for k, axis in enumerate("xyz"):
        columns[f"probe_r{axis}"] = rotation_vectors[:, k]
    for k, axis in enumerate("xyz"):
        columns[f"f{axis}"] = np.asarray(samples.force_S[:, k])
    for k, axis in enumerate("xyz"):
        columns[f"t{axis}"] = np.asarray(samples.torque_S[:, k])
    columns["fn"] = np.asarray(samples.normal_force)
    if spec.contact_center_S is not None:
        columns["theta"] = np.asarray(samples.theta)
        columns["phi"] = np.asarray(samples.phi)
    columns["contact"] = np.asarray(samples.contact).astype(np.int8)
    metadata = {
        "format": "hydrotact.barometer_log",
        "version": 1,
        "sensor": spec.name,
        "source": "simulated",
        "pressure": "elastic",
        "channels": list(spec.taxel_names),
        "generator": f"hydrotact {__version__}",
        **metadata_extra,
    }
    return BarometerLog(metadata=metadata, columns=columns)


def run_simulate(sensor: str, probe_spec: str, trajectory_path, output, *, modulus=1e6, material=None, barometer=False, seed=0, noise_rms=None, gain_spread=0.0, offset_spread=0.0, force_noise=0.0, field="laplace", num_rays=64, units="m", png=None, progress=True) -> dict:
    """Simulate the sensor along the trajectory file and write the log (and plot).

    With `material` (a material.json), the material is viscoelastic; with `barometer`,
    the log holds absolute barometer readings (the sensor's part: ambient, LSB, noise,
    rate; per-channel gains drawn around 1 with `gain_spread`, offsets with
    `offset_spread` Pa, load-cell noise `force_noise` N on fx, fy, fz; all from
    `seed`), sampled at the part's rate. Returns a report dict."""
    from ._contact_job import parse_probe
    from .sensors import load_sensor

    output = Path(output)
    if output.suffix.lower() != ".parquet":
        raise HydrotactError(f"{output}: the log is written as Parquet; name it *.parquet")
    if png is not None and Path(png).suffix.lower() != ".png":
        raise HydrotactError(f"{png}: the plot is written as PNG; name it *.png")
    if not barometer:
        given = [flag for flag, value in (("--noise", noise_rms), ("--gain-spread", gain_spread or None), ("--offset-spread", offset_spread or None), ("--force-noise", force_noise or None)) if value is not None]
        if given:
            raise HydrotactError(f"{given[0]}: applies to barometer readings; add --barometer")
    if material is not None:
        from .data import material_prony, read_material

        material_path = material
        material = material_prony(read_material(material_path), str(material_path))
        modulus = float(material.instantaneous_modulus)
    else:
        material = make_material(modulus)
    spec = load_sensor(sensor)
    probe = parse_probe(probe_spec)
    trajectory = read_trajectory(trajectory_path, units=units)
    if barometer:
        trajectory = resample_trajectory(trajectory, spec.part.rate_hz)
    model = make_sensor_model(spec, field_kind=field, num_rays=num_rays)
    translations = np.asarray(trajectory.X_SR.translation)
    rotations = np.asarray(trajectory.rotation_vectors)
    key = _resume_key(__version__, "distinct-poses", spec.name, json.dumps(spec.to_json(), sort_keys=True), probe_spec, field, num_rays, np.asarray(trajectory.times), translations, rotations)
    partial = output.with_name(f".{output.name}.partial.npz")
    unit = UnitResponse(**compute_responses_resumably(model, probe, trajectory, partial, key, progress))
    samples = scale_unit_responses(model, material, trajectory.times, unit)
    extra = {"probe": probe_spec, "material": material_metadata(material), "field": field, "num_rays": int(num_rays)}
    steps = np.diff(np.asarray(trajectory.times))
    if len(steps):
        extra["rate_hz"] = float(1.0 / np.median(steps))
    log = samples_to_log(spec, samples, translations, rotations, extra)
    if barometer:
        log = add_barometer_signal(log, spec.part, seed=seed, noise_rms=noise_rms, gain_spread=gain_spread, offset_spread=offset_spread, force_noise=force_noise)
    write_log(output, log)
    partial.unlink(missing_ok=True)
    from .sysid._problem import store_unit_responses

    store_unit_responses(spec, probe_spec, field, num_rays, np.column_stack([translations, rotations]), unit.taxel_pressures, unit.force_S)
    if png is not None:
        from .viz import plot_log

        plot_log(log, png, title=f"{spec.name}: {probe_spec}, E(0) = {modulus:g} Pa")
    return {
        "sensor": spec.name,
        "probe": probe_spec,
        "num_samples": trajectory.num_samples,
        "num_taxels": spec.num_taxels,
        "samples_in_contact": int(np.sum(samples.contact)),
        "max_normal_force_N": float(np.max(samples.normal_force, initial=0.0)),
        "max_taxel_pressure_Pa": float(np.max(samples.taxel_pressures, initial=0.0)),
        "log": str(output),
        **({"png": str(png)} if png is not None else {}),
    }


def material_metadata(material) -> dict:
    """The log's `material` entry for an elastic Material or a visco.Prony."""
    if isinstance(material, Material):
        return {"modulus_Pa": float(material.modulus)}
    return {
        "modulus_Pa": float(material.instantaneous_modulus),
        "long_term_modulus_Pa": float(material.long_term_modulus),
        "prony_terms": [{"modulus_Pa": float(m), "tau_s": float(t)} for m, t in zip(np.asarray(material.moduli), np.asarray(material.taus))],
    }


def resample_trajectory(trajectory, rate_hz: float):
    """The trajectory at a barometer's sample instants, poses linear in time between
    the given ones (as a stage moves between waypoints)."""
    from .visco import calc_sample_times

    times = np.asarray(trajectory.times)
    samples = calc_sample_times(times, rate_hz)
    translations = np.column_stack([np.interp(samples, times, column) for column in np.asarray(trajectory.X_SR.translation).T])
    rotations = np.column_stack([np.interp(samples, times, column) for column in np.asarray(trajectory.rotation_vectors).T])
    return make_trajectory(samples, translations, rotations)


def add_barometer_signal(log: BarometerLog, part, *, seed=0, noise_rms=None, gain_spread=0.0, offset_spread=0.0, force_noise=0.0) -> BarometerLog:
    """The log with its elastic channel pressures turned into absolute barometer
    readings (visco.calc_barometer_readings) and load-cell noise on the forces."""
    import jax.numpy as jnp

    from .visco import calc_barometer_readings, make_barometer_signal

    for name, value in (("gain spread", gain_spread), ("offset spread", offset_spread), ("force noise", force_noise)):
        if not np.isfinite(value) or value < 0.0:
            raise HydrotactError(f"--{name.replace(' ', '-')}: must be a non-negative number, got {value:g}")
    rng = np.random.default_rng(seed)
    count = len(log.metadata["channels"])
    gains = np.clip(1.0 + gain_spread * rng.standard_normal(count), 0.05, None)
    offsets = offset_spread * rng.standard_normal(count)
    signal = make_barometer_signal(part, count, gains=gains, offsets=offsets, noise_rms=noise_rms)
    times = jnp.asarray(log.times)
    readings = np.asarray(calc_barometer_readings(signal, times, jnp.asarray(log.channels), key=jax.random.PRNGKey(seed)))
    columns = dict(log.columns)
    for k, name in enumerate(log.metadata["channels"]):
        columns[name] = readings[:, k]
    for name in ("fx", "fy", "fz"):
        if name in columns and force_noise > 0.0:
            columns[name] = columns[name] + force_noise * rng.standard_normal(len(times))
    metadata = dict(log.metadata, pressure="absolute", rate_hz=float(signal.rate_hz))
    metadata["barometer"] = {"part": part.name, "seed": int(seed), "noise_rms_Pa": float(signal.noise_rms), "gains": gains.tolist(), "offsets_Pa": offsets.tolist(), "force_noise_N": float(force_noise)}
    return BarometerLog(metadata=metadata, columns=columns)
