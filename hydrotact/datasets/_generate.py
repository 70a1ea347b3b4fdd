"""`generate_dataset`: a synthetic dataset of the contact-estimation data-collection
regime, from a sensor and a material to shards and a manifest (host).

Deterministic: one seed spawns independent streams (events, material draw, sensor
variation, barometer noise, the train/test split), and the unit responses are bit-identical on any
number of devices or Ray workers (see :mod:`._compute`), so the same request gives
byte-identical shards however it was run. Resumable: each batch of unit responses is
saved as it finishes; a killed run started again with the same request picks them up.
"""

import json
import time
from pathlib import Path

import jax
import numpy as np

from .. import __version__
from .._defaults import DEFAULT_DATASET_MODULUS
from .._errors import HydrotactError, HydrotactWarning
from .._files import digest
from ._config import PHASES, DatasetConfig
from ._store import finish_state, prepare_folder, read_manifest, start_state, write_manifest, write_shards

GENERATOR = f"hydrotact {__version__} datasets/5"
"""Bumped whenever the same seed and configuration give other rows (3: presses stop on
the force along their approach, not the contact normal force; 4: the default modulus
10 MPa, and the holds computed shallowest first; 5: slices start on the rung of buffers
their poses are predicted to need, so some forces, and the hold depths found from them,
differ in the last bit)."""

STREAMS = ("events", "material", "sensor", "noise", "split")
"""The independent random streams one seed spawns (numpy SeedSequence), in order."""

PUBLISHED_CHANNEL_STD_PA = (3e3, 9e3)
"""The range of per-channel standard deviations in the barometric estimation paper's
published normalisation statistics (real barometers under these elastomers)."""

def _material_values(document: dict) -> tuple[float, list, list]:
    terms = document["prony_terms"]
    return document["long_term_modulus_Pa"]["value"], [t["modulus_Pa"]["value"] for t in terms], [t["tau_s"]["value"] for t in terms]


def draw_material(document: dict, rng: np.random.Generator, source: str) -> tuple[dict, dict]:
    """A material drawn from a document's covariance (log space), or from its
    standard deviations (independent, log-normal) without one: (the drawn values
    {long_term_modulus_Pa, moduli_Pa, taus_s}, what was drawn from)."""
    long_term, moduli, taus = _material_values(document)
    names = ["log_long_term_modulus", *(f"log_modulus_{i}" for i in range(1, len(moduli) + 1)), *(f"log_tau_{i}" for i in range(1, len(taus) + 1))]
    mean = np.log([long_term, *moduli, *taus])
    covariance = document.get("covariance")
    if covariance is not None:
        if covariance.get("space", "log") != "log":
            raise HydrotactError(f"{source}: covariance.space: {covariance['space']!r}; a material is drawn from a covariance in log space")
        position = {name: k for k, name in enumerate(names)}
        unknown = [name for name in covariance["parameters"] if name not in position]
        if unknown:
            raise HydrotactError(f"{source}: covariance.parameters: {unknown[0]!r} is not a parameter of this material ({', '.join(names)})")
        index = [position[name] for name in covariance["parameters"]]
        matrix = np.asarray(covariance["matrix"], dtype=np.float64)
        if np.min(np.linalg.eigvalsh(matrix)) < -1e-9 * max(np.max(np.abs(matrix)), 1e-300):
            raise HydrotactError(f"{source}: covariance.matrix is not positive semi-definite; it cannot be drawn from")
        values = mean.copy()
        values[index] = rng.multivariate_normal(mean[index], matrix, method="eigh")
        origin = "covariance (log space)"
    else:
        entries = [document["long_term_modulus_Pa"], *(t["modulus_Pa"] for t in document["prony_terms"]), *(t["tau_s"] for t in document["prony_terms"])]
        stds = np.array([entry.get("std", 0.0) for entry in entries])
        if not np.any(stds > 0.0):
            raise HydrotactError(f"{source}: --randomise-material needs a covariance or standard deviations in the material document; it has neither")
        sigma = np.sqrt(np.log1p((stds / np.exp(mean)) ** 2))  # log-normal with the given mean's std
        values = mean + sigma * rng.standard_normal(len(mean))
        origin = "standard deviations (independent, log-normal)"
    values = np.exp(values)
    count = len(moduli)
    return {"long_term_modulus_Pa": float(values[0]), "moduli_Pa": values[1 : 1 + count].tolist(), "taus_s": values[1 + count :].tolist()}, {"drawn_from": origin}


def _resolve_material(material, modulus, config: DatasetConfig, rng) -> tuple:
    """(Prony, the manifest's material entry)."""
    from ..data import check_material, material_prony, read_material
    from ..field import check_modulus
    from ..visco import make_prony

    if material is None:
        if config.randomise_material:
            raise HydrotactError("--randomise-material: needs --material (a material document with uncertainties)")
        value = check_modulus(DEFAULT_DATASET_MODULUS if modulus is None else modulus)
        return make_prony(value, source="--modulus"), {"source": "--modulus", "randomised": False, "long_term_modulus_Pa": float(value), "moduli_Pa": [], "taus_s": []}
    if isinstance(material, dict):
        document, source = material, "material document"
        check_material(document, source)
    else:
        source = str(material)
        document = read_material(material)
    if document.get("modulus_scale") == "relative":
        material_prony(document, source)  # refuses, with its message
    entry = {"source": Path(source).name if not isinstance(material, dict) else source, "name": document.get("name", ""), "randomised": bool(config.randomise_material)}
    if config.randomise_material:
        values, origin = draw_material(document, rng, source)
        entry |= values | origin
        entry["nominal"] = dict(zip(("long_term_modulus_Pa", "moduli_Pa", "taus_s"), _material_values(document)))
        prony = make_prony(values["long_term_modulus_Pa"], values["moduli_Pa"], values["taus_s"], source=f"{source} (drawn)")
    else:
        long_term, moduli, taus = _material_values(document)
        entry |= {"long_term_modulus_Pa": long_term, "moduli_Pa": moduli, "taus_s": taus}
        prony = material_prony(document, source)
    return prony, entry


def _jitter_layout(model, spec, jitter: float, rng):
    """The model with its barometers moved by N(0, jitter) per axis: (model, offsets)."""
    from ..sim import with_barometer_positions

    offsets = jitter * rng.standard_normal((spec.num_taxels, 3))
    if jitter == 0.0:
        return model, offsets
    return with_barometer_positions(model, spec, spec.taxel_positions_S + offsets), offsets


def _split(timeline, config: DatasetConfig, rng) -> dict:
    """Contiguous blocks of events; a seeded choice of them for testing."""
    count = len(timeline.event_starts) - 1
    blocks = min(config.split_blocks, count)
    edges = [int(timeline.event_starts[(b * count) // blocks]) for b in range(blocks)] + [timeline.num_samples]
    num_test = 0 if config.test_fraction == 0.0 or blocks < 2 else min(blocks - 1, max(1, int(round(config.test_fraction * blocks))))
    test = set(rng.choice(blocks, size=num_test, replace=False).tolist()) if num_test else set()
    ranges = {"train": [], "test": []}
    for b in range(blocks):
        ranges["test" if b in test else "train"].append([edges[b], edges[b + 1]])
    return ranges | {"blocks": blocks, "test_blocks": sorted(test), "test_fraction": config.test_fraction}


def _columns(spec, columns: dict) -> tuple[dict, list]:
    """The shard columns in order, and their manifest descriptions."""
    names = list(spec.taxel_names)
    out, described = {"time": columns["time"]}, [{"name": "time", "unit": "s", "description": "session time, 0 at the first sample"}]
    for k, name in enumerate(names):
        out[name] = columns["readings"][:, k]
        described.append({"name": name, "unit": "Pa", "description": f"barometer {name}'s absolute reading (the part's ambient, gain, offset, noise, LSB, range)"})
    labels = [
        ("fx", "N", "force of the probe on the sensor, x (sensor base frame)"), ("fy", "N", "force, y"), ("fz", "N", "force, z"),
        ("fn", "N", "force along the inward skin normal at the contact"),
    ]
    if spec.contact_center_S is not None:
        labels += [("theta", "rad", "contact angle asin(-n_y) of the centre of pressure seen from the contact centre (NaN without contact)"),
                   ("phi", "rad", "contact angle atan2(n_x, n_z) (NaN without contact)")]
    labels += [
        ("contact", "", "1 where |F| > 0.1 N"),
        ("cop_x", "m", "centre of pressure, x (NaN without contact)"), ("cop_y", "m", "centre of pressure, y"), ("cop_z", "m", "centre of pressure, z"),
        ("depth", "m", "the probe tip's travel past the event's skin point along the approach (NaN between events)"),
        ("event", "", "event index (-1 between events)"),
        ("phase", "", "0 gap, 1 approach, 2 hold, 3 retract"),
    ]
    for name, unit, text in labels:
        out[name] = columns[name]
        described.append({"name": name, "unit": unit, "description": text})
    for k, axis in enumerate(("x", "y", "z", "rx", "ry", "rz")):
        out[f"probe_{axis}"] = columns["probe"][:, k]
        described.append({"name": f"probe_{axis}", "unit": "m" if k < 3 else "rad", "description": "the probe frame's pose (tip position, rotation vector), sensor frame"})
    return out, described


def _request(spec, probe_spec: str, material_entry: dict, config: DatasetConfig, field: str) -> dict:
    return {"generator": GENERATOR, "sensor": spec.to_json(), "probe": probe_spec, "material": material_entry, "config": config.to_json(), "field": field}


def generate_dataset(sensor, output, *, material=None, modulus=None, config: DatasetConfig | None = None, ray_address: str | None = None, progress: bool = False) -> dict:
    """Generate a synthetic dataset into the folder `output` (host).

    **Arguments:**

    - `sensor`: a :class:`hydrotact.sensors.SensorSpec`, a built-in name or a spec file.
    - `material`: a material document (dict) or its JSON file (drawn from its
      covariance with `config.randomise_material`); without it an elastic material of
      `modulus` Pa (default :data:`hydrotact._defaults.DEFAULT_DATASET_MODULUS`, 10 MPa).
    - `config`: the regime (:class:`DatasetConfig`; the paper's by default).
    - `ray_address`: None to run in this process on every local JAX device; "auto" or
      an address to send the pose batches to a Ray cluster as tasks.
    - `progress`: progress bars (poses, then shards).

    **Returns:** the manifest (a dict), plus `status` ("written" or "complete": the
    folder already held this dataset) and `elapsed_s`.
    """
    from tqdm.auto import tqdm

    from ..contact import parse_probe
    from ..sensors import SensorSpec, load_sensor
    from ..sim import BarometerSettings, make_sensor_model
    from ._compute import PoseEngine
    from ._events import find_touchable_skin, sample_events
    from ._session import lay_out_timeline, march_presses, run_session

    started = time.perf_counter()
    config = config or DatasetConfig()
    spec = sensor if isinstance(sensor, SensorSpec) else load_sensor(sensor)
    probe = parse_probe(config.probe)
    events_rng, material_rng, sensor_rng, noise_rng, split_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(config.seed).spawn(len(STREAMS)))
    prony, material_entry = _resolve_material(material, modulus, config, material_rng)
    request = _request(spec, probe.spec, material_entry, config, "laplace")
    request_digest = digest(json.dumps(request, sort_keys=True))
    status = prepare_folder(output, request_digest)
    output = Path(output)
    if ray_address is not None and status != "complete":
        from ._compute import _check_reachable

        _check_reachable(ray_address)  # before the sensor's fields are built: a cluster not there is refused in seconds
    if status == "complete":
        return read_manifest(output) | {"status": "complete", "elapsed_s": time.perf_counter() - started}
    model = make_sensor_model(spec, num_rays=config.num_rays)
    model, position_offsets = _jitter_layout(model, spec, config.position_jitter, sensor_rng)
    barometer = BarometerSettings(seed=int(sensor_rng.integers(2**31)), noise_rms=config.noise_rms, gain_spread=config.gain_spread, offset_spread=config.offset_spread)
    signal, _ = barometer.draw(spec.part, spec.num_taxels)
    key = jax.random.PRNGKey(int(noise_rng.integers(2**31)))
    plan = sample_events(find_touchable_skin(spec, spec.make_mesh(check=False)), config, events_rng)
    engine = PoseEngine(model, probe, ray_address)  # a Ray cluster that does not answer is refused here, before anything is written
    partial = start_state(output, request_digest, request)
    doing = "resuming" if status == "resume" else "generating"
    with tqdm(total=plan.num_events * (ROUND_ESTIMATE + 1) + 1, unit="pose", desc=f"{doing} {spec.name} ({plan.num_events} events, {engine.description})", disable=not progress) as bar:
        bar.set_postfix_str("compiling the contact kernels", refresh=True)

        restored = [0]

        def on_poses(count, from_checkpoint=False):
            if from_checkpoint:  # read back, not computed: counted, but kept out of the rate
                restored[0] += count
                bar.n += count
                bar.last_print_n = bar.n
                bar.set_postfix_str(f"resuming: {restored[0]} poses read back from {partial.name}/", refresh=True)
                return
            bar.set_postfix_str(f"{restored[0]} read back" if restored[0] else "", refresh=False)
            bar.update(count)

        def on_round(active, to_go):
            bar.total = bar.n + max(to_go, 1)
            bar.refresh()

        presses = march_presses(engine, plan, config, float(prony.instantaneous_modulus), folder=partial, on_poses=on_poses, on_round=on_round)
        bar.total = bar.n
        bar.refresh()
    timeline = lay_out_timeline(plan, presses, config)
    columns = run_session(model, prony, presses, timeline, config, signal, key)
    shard_columns, described = _columns(spec, columns)
    import pyarrow as pa

    table = pa.table(shard_columns)
    count = (table.num_rows + config.shard_rows - 1) // config.shard_rows
    with tqdm(total=count, unit="shard", desc=f"writing {output}", disable=not progress) as bar:
        shards = write_shards(output, table, config.shard_rows, on_shard=bar.update)
    readings = columns["readings"]
    saturated = (readings <= float(signal.range_pa[0])) | (readings >= float(signal.range_pa[1]))
    contact = columns["contact"].astype(bool)
    hold = columns["phase"] == PHASES["hold"]
    manifest = {
        "format": "hydrotact.dataset",
        "version": 1,
        "generator": GENERATOR,
        "request_digest": request_digest,
        "sensor": {"name": spec.name, "spec": spec.to_json()},
        "probe": probe.spec,
        "field": "laplace",
        "material": material_entry,
        "config": config.to_json(),
        "seeds": {"seed": config.seed, "streams": list(STREAMS), "barometer_seed": barometer.seed},
        "sensor_variation": {
            "gains": np.asarray(signal.gains).tolist(), "offsets_Pa": np.asarray(signal.offsets).tolist(),
            "position_offsets_m": position_offsets.tolist(), "noise_rms_Pa": float(signal.noise_rms),
        },
        "rate_hz": float(config.rate_hz),
        "channels": list(spec.taxel_names),
        "columns": described,
        "phases": dict(PHASES),
        "num_events": plan.num_events,
        "num_rows": int(table.num_rows),
        "duration_s": float(table.num_rows / config.rate_hz),
        "num_distinct_poses": int(len(presses.rows)),
        "num_rounds": int(presses.num_rounds),
        "shards": shards,
        "split": _split(timeline, config, split_rng),
        "statistics": {
            "channel_mean_Pa": readings.mean(axis=0).tolist(),
            "channel_std_Pa": readings.std(axis=0).tolist(),
            "published_channel_std_Pa": list(PUBLISHED_CHANNEL_STD_PA),
            "saturated_samples": saturated.sum(axis=0).astype(int).tolist(),
            "contact_fraction": float(contact.mean()),
            "events_short_of_target": int((~presses.reached).sum()),
            "hold_force_N": {"min": float(presses.hold_forces.min()), "median": float(np.median(presses.hold_forces)), "max": float(presses.hold_forces.max())},
            "fx_N": [float(np.min(columns["fx"])), float(np.max(columns["fx"]))],
            "fy_N": [float(np.min(columns["fy"])), float(np.max(columns["fy"]))],
            "fn_N": [float(np.min(columns["fn"])), float(np.max(columns["fn"]))],
            "hold_depth_m": [float(presses.hold_depths.min()), float(presses.hold_depths.max())],
            "max_depth_m": [float(plan.max_depths.min()), float(plan.max_depths.max())],
            "in_contact_hold_fraction": float(contact[hold].mean()) if hold.any() else 0.0,
        },
    }
    write_manifest(output, manifest)
    finish_state(output)
    _warn(output, manifest, config)
    return manifest | {"status": "written", "elapsed_s": time.perf_counter() - started}


ROUND_ESTIMATE = 16
"""Approach samples expected per event, for the progress bar's first total."""


def _warn(output, manifest: dict, config: DatasetConfig) -> None:
    import warnings

    stats = manifest["statistics"]
    short = stats["events_short_of_target"]
    if short and config.target == "depth":
        warnings.warn(HydrotactWarning(
            f"{output}: {short} of {manifest['num_events']} events' target depths lay past --max-depth {config.max_depth * 1e3:g} mm "
            f"or --max-depth-fraction {config.max_depth_fraction:g} of the elastomer's thickness; they hold there"
        ), stacklevel=3)
    elif short:
        warnings.warn(HydrotactWarning(
            f"{output}: {short} of {manifest['num_events']} events did not reach their target force within --max-depth {config.max_depth * 1e3:g} mm "
            f"or --max-depth-fraction {config.max_depth_fraction:g} of the elastomer's thickness "
            f"and hold there (the material is softer than the force range needs; hold forces up to {stats['hold_force_N']['max']:.3g} N)"
        ), stacklevel=3)
    # a barometer whose readings move no more than its noise: no contact of this regime reaches it (a receptive
    # field that misses the skin pressed, a layout or regime to check); its column is noise for the estimator
    floor = 1.5 * manifest["sensor_variation"]["noise_rms_Pa"] + 1.0  # the noise drawn (the part's where --noise is not given)
    dead = [name for name, std in zip(manifest["channels"], stats["channel_std_Pa"]) if std <= floor]
    if dead:
        warnings.warn(HydrotactWarning(
            f"{output}: {len(dead)} of {len(manifest['channels'])} channels never respond over the {manifest['num_events']} events "
            f"({', '.join(dead[:8])}{' ...' if len(dead) > 8 else ''}: a spread of at most {floor:.3g} Pa, the noise's): no press of this regime reaches them"
        ), stacklevel=3)
    saturated = sum(stats["saturated_samples"])
    if saturated:
        warnings.warn(HydrotactWarning(f"{output}: {saturated} readings reached the barometer's range and read its limit (a real part clips so too)"), stacklevel=3)

