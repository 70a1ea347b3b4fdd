"""Simulated logs: samples -> a BarometerLog, and the draws that make a simulated
sensor imperfect (channel gains and offsets, barometer and load-cell noise).

`simulate_log` is what a Python user (and `hydrotact simulate`, and the demo) calls to
get a log without files: a sensor spec, a probe, a trajectory and a material in, a
`hydrotact.data.BarometerLog` (and its Samples) out.
"""

import dataclasses

import jax
import numpy as np

from .. import __version__
from .._errors import HydrotactError
from ..data import BarometerLog
from ..field import StrainFieldKind
from ..visco import BarometerSignal, Prony, make_barometer_signal
from ._host import simulate
from ._model import make_sensor_model
from ._simulate import Samples
from ._trajectory import Trajectory, resample_trajectory

MAX_GAIN_SPREAD = 0.25
"""The largest standard deviation of the channel gains a simulation takes (a gain of 1
± 25 %: beyond it a draw may put a gain at or below 0)."""


@dataclasses.dataclass(frozen=True)
class BarometerSettings:
    """How a simulated log's barometers and load cell depart from ideal ones.

    **Fields:** `seed` of every draw (channel gains and offsets, noise); `noise_rms`
    the barometer noise, Pa (None: the part's); `gain_spread` the standard deviation
    of the channel gains around 1; `offset_spread` that of the channel offsets, Pa;
    `force_noise` the load cell's RMS noise on fx, fy, fz, N. The readings are the
    part's (ambient, LSB, rate): see :mod:`hydrotact.visco`'s signal model.
    """

    seed: int = 0
    noise_rms: float | None = None
    gain_spread: float = 0.0
    offset_spread: float = 0.0
    force_noise: float = 0.0

    def __post_init__(self):
        for name in ("gain_spread", "offset_spread", "force_noise"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value < 0.0:
                raise HydrotactError(f"--{name.replace('_', '-')}: must be a non-negative number, got {value:g}")
        if self.gain_spread > MAX_GAIN_SPREAD:
            raise HydrotactError(
                f"--gain-spread: {self.gain_spread:g} is a spread of {self.gain_spread:.0%} around a gain of 1; at most {MAX_GAIN_SPREAD:g} "
                "(cast barometers differ by a few per cent; a gain must stay positive)"
            )
        if self.noise_rms is not None and (not np.isfinite(float(self.noise_rms)) or float(self.noise_rms) < 0.0):
            raise HydrotactError(f"--noise: must be a non-negative pressure in Pa, got {float(self.noise_rms):g}")

    def draw(self, part, num_channels: int) -> tuple[BarometerSignal, np.random.Generator]:
        """The channels' signal model (gains drawn around 1, offsets around 0) and the
        generator the load-cell noise is drawn from next (host). A draw that puts a
        gain below 0.05 (over 3.8 spreads down) is refused, never clipped."""
        rng = np.random.default_rng(self.seed)
        gains = 1.0 + self.gain_spread * rng.standard_normal(num_channels)
        if np.any(gains < 0.05):
            low = int(np.argmin(gains))
            raise HydrotactError(f"--gain-spread: seed {self.seed} draws a gain of {gains[low]:.3g} for channel {low}; use another --seed or a smaller spread")
        offsets = self.offset_spread * rng.standard_normal(num_channels)
        return make_barometer_signal(part, num_channels, gains=gains, offsets=offsets, noise_rms=self.noise_rms), rng

    @property
    def key(self):
        """The PRNG key of the barometer noise."""
        return jax.random.PRNGKey(self.seed)


def calc_saturated(signal, readings) -> np.ndarray:
    """(S, C) readings at the part's limits: the part clipped them (host)."""
    low, high = (float(v) for v in np.asarray(signal.range_pa))
    return (readings <= low) | (readings >= high)


def material_metadata(material: Prony) -> dict:
    """The log's `material` entry: E for an elastic material, E(0), E∞ and the
    terms for a viscoelastic one."""
    if material.num_terms == 0:
        return {"modulus_Pa": float(material.long_term_modulus)}
    return {
        "modulus_Pa": float(material.instantaneous_modulus),
        "long_term_modulus_Pa": float(material.long_term_modulus),
        "prony_terms": [{"modulus_Pa": float(m), "tau_s": float(t)} for m, t in zip(np.asarray(material.moduli), np.asarray(material.taus))],
    }


def make_barometer_log(
    spec,
    samples: Samples,
    trajectory: Trajectory,
    *,
    probe: str,
    material: Prony,
    field_kind: StrainFieldKind | str = StrainFieldKind.LAPLACE,
    num_rays: int = 64,
    barometer: BarometerSettings | None = None,
) -> BarometerLog:
    """A BarometerLog of simulated samples (host).

    Columns: time; one per taxel (the elastomer pressure, or with `barometer` the
    absolute readings `samples.readings`, simulated with `barometer.draw`'s signal);
    the probe pose (`probe_x`.. m, `probe_rx`.. rad); the wrench on the sensor (`fx`..
    N, with the load-cell noise of `barometer`; `tx`.. N m); `fn`; `theta`, `phi` where the sensor
    defines a contact centre; `contact`. The metadata say how it was simulated
    (`probe`: the probe's spec string, left out when it has none).
    """
    signal = rng = None
    if barometer is not None:  # the same draws the readings were simulated with (one seed)
        signal, rng = barometer.draw(spec.part, spec.num_taxels)
    columns = {"time": np.asarray(samples.times, dtype=np.float64)}
    pressures = samples.taxel_pressures if barometer is None else samples.readings
    for k, name in enumerate(spec.taxel_names):
        columns[name] = np.asarray(pressures[:, k])
    for k, axis in enumerate("xyz"):
        columns[f"probe_{axis}"] = np.asarray(trajectory.translations[:, k])
    for k, axis in enumerate("xyz"):
        columns[f"probe_r{axis}"] = np.asarray(trajectory.rotation_vectors[:, k])
    for k, axis in enumerate("xyz"):
        force = np.asarray(samples.force_S[:, k])
        if barometer is not None and barometer.force_noise > 0.0:
            force = force + barometer.force_noise * rng.standard_normal(len(force))
        columns[f"f{axis}"] = force
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
        "pressure": "elastic" if barometer is None else "absolute",
        "channels": list(spec.taxel_names),
        **({"stress_channels": [name for name, elastic in zip(spec.taxel_names, spec.is_elastic) if elastic]} if spec.is_elastic.any() else {}),
        "generator": f"hydrotact {__version__}",
        **({"probe": probe} if probe else {}),  # a probe loaded from a mesh has no spec to name it
        "material": material_metadata(material),
        "field": str(StrainFieldKind.parse(field_kind, "field kind")),
        "num_rays": int(num_rays),
    }
    steps = np.diff(np.asarray(samples.times))
    if len(steps):
        metadata["rate_hz"] = float(1.0 / np.median(steps))
    if barometer is not None:
        metadata["rate_hz"] = float(signal.rate_hz)
        metadata["barometer"] = {
            "part": spec.part.name,
            "seed": int(barometer.seed),
            "noise_rms_Pa": float(signal.noise_rms),
            "gains": np.asarray(signal.gains).tolist(),
            "offsets_Pa": np.asarray(signal.offsets).tolist(),
            "force_noise_N": float(barometer.force_noise),
            "range_Pa": np.asarray(signal.range_pa).tolist(),
            "saturated_samples": [int(n) for n in np.sum(calc_saturated(signal, np.asarray(samples.readings)), axis=0)],
        }
    return BarometerLog(metadata=metadata, columns=columns)


def simulate_log(
    sensor,
    probe,
    trajectory: Trajectory,
    material: Prony,
    *,
    field_kind: StrainFieldKind | str = StrainFieldKind.LAPLACE,
    num_rays: int = 64,
    barometer: BarometerSettings | None = None,
    progress: bool = False,
    checkpoint=None,
    cache: bool = True,
) -> tuple[BarometerLog, Samples]:
    """Simulate a log of `sensor` (a sensors.SensorSpec, a built-in name or a spec
    file) pressed by `probe` (a probe object or its spec string, e.g.
    "cylinder:d=2mm") along `trajectory`, with `material` (host).

    Without `barometer` the channels hold the elastomer pressure at each barometer at
    the trajectory's times (`pressure: elastic`). With it, the trajectory is first
    resampled to the part's rate and the channels hold absolute readings of the
    part (ambient, the drawn gains and offsets, noise, LSB; `pressure: absolute`),
    the forces the load cell's noise. `checkpoint`, `cache`, `progress`: as
    :func:`hydrotact.sim.simulate`.

    **Returns:** (the log, the Samples it was made from).
    """
    from ..contact import parse_probe
    from ..sensors import SensorSpec, load_sensor

    spec = sensor if isinstance(sensor, SensorSpec) else load_sensor(sensor)
    if isinstance(probe, str):
        probe_spec, probe = probe, parse_probe(probe)
    else:
        probe_spec = probe.spec
    signal = key = None
    if barometer is not None:
        trajectory = resample_trajectory(trajectory, spec.part.rate_hz)
        signal, _ = barometer.draw(spec.part, spec.num_taxels)
        key = barometer.key
    model = make_sensor_model(spec, field_kind=field_kind, num_rays=num_rays)
    samples = simulate(model, material, probe, trajectory, barometer=signal, key=key, progress=progress, checkpoint=checkpoint, cache=cache)
    log = make_barometer_log(spec, samples, trajectory, probe=probe_spec, material=material, field_kind=field_kind, num_rays=num_rays, barometer=barometer)
    return log, samples
