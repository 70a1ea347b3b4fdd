"""Synthetic barometer logs with a known material, for the system-identification tests.

No contact simulation: the indentation is a press/hold/release history and each
channel's unit-modulus response is a power law of the depth, so a log takes
milliseconds. The viscoelastic truth is the exact hereditary integral
(hydrotact.visco) and the readings go through the barometer signal model (gain,
offset, white noise, the part's quantisation).
"""

import jax
import jax.numpy as jnp
import numpy as np

from hydrotact.data import BarometerLog
from hydrotact.sensors import known_parts
from hydrotact.visco import calc_barometer_readings, calc_contact_response, make_barometer_signal

PART = "BMP388"
FORCE_NOISE = 5e-3  # N
PRESSURE_NOISE = 2.0  # Pa: a barometer cast in silicone, far above the bare part's 0.03 Pa
DEPTH_SCALE = 0.5e-3  # m: the depth where a unit response reaches its `shape` value


def make_depth_history(rng, duration: float, rate_hz: float, holds=(2.0, 30.0), gaps=(2.0, 15.0), ramp: float = 0.3):
    """(times, depth) of press / hold / release cycles (:func:`make_press_depths`)
    sampled at `rate_hz` for `duration` s: the first press at min(1 s, duration / 10),
    none starting within min(5 s, duration / 5) of the end."""
    times = np.arange(0.0, duration, 1.0 / rate_hz)
    return times, make_press_depths(rng, times, holds, gaps, ramp, start=min(1.0, 0.1 * duration), end_margin=min(5.0, 0.2 * duration))


def make_press_depths(rng, times, holds, gaps, ramp: float, start: float, end_margin: float):
    """Depth (T,) in m at `times` of press / hold / release cycles: 0.3-0.8 mm deep,
    linear ramps of `ramp` s, hold and rest times drawn uniformly from `holds` and
    `gaps`, the first press at `start`, none starting within `end_margin` of the end.
    (Also benchmarks/sysid.py's log.)"""
    depth = np.zeros_like(times)
    while start < times[-1] - end_margin:
        hold = rng.uniform(*holds)
        deepest = rng.uniform(0.3e-3, 0.8e-3)
        up = (times >= start) & (times < start + ramp)
        depth[up] = deepest * (times[up] - start) / ramp
        held = (times >= start + ramp) & (times < start + ramp + hold)
        depth[held] = deepest
        down = (times >= start + ramp + hold) & (times < start + 2 * ramp + hold)
        depth[down] = deepest * (1.0 - (times[down] - start - ramp - hold) / ramp)
        start += 2 * ramp + hold + rng.uniform(*gaps)
    return depth


def _metadata(num_channels: int) -> dict:
    return {
        "format": "hydrotact.barometer_log",
        "version": 1,
        "sensor": "synthetic",
        "source": "simulated",
        "pressure": "absolute",
        "channels": [f"b{k}" for k in range(num_channels)],
    }


def make_unit_responses(depth, shapes):
    """Unit-modulus responses: taxels (T, C) Pa per Pa of E ∝ depth^1.5 per channel
    and a force (T, 3) N per Pa of E along z."""
    normalised = (np.asarray(depth) / DEPTH_SCALE) ** 1.5
    unit = normalised[:, None] * 1e-3 * np.asarray(shapes)[None, :]
    force = np.zeros((len(depth), 3))
    force[:, 2] = 3e-6 * normalised
    return unit, force


def _readings(times, pressures, gains, offsets, seed: int, noise_rms: float):
    """Barometer readings of elastomer pressures (T, C) through the BMP388 model."""
    part = known_parts()[PART]
    signal = make_barometer_signal(part, pressures.shape[1], gains=gains, offsets=offsets, noise_rms=noise_rms)
    key = jax.random.PRNGKey(seed)
    return np.asarray(calc_barometer_readings(signal, jnp.asarray(times), jnp.asarray(pressures), key=key))


class FullLogMaker:
    """Full-mode logs of one trajectory and truth; `make(seed)` draws new noise.

    Channels respond ∝ depth^1.5 with random strengths; the true channel gains
    (0.8-1.2) and offsets (±50 Pa) are drawn once, from `trajectory_seed`; the log
    has the force columns fx, fy, fz (only fz is loaded).

    The noiseless response (channels and force) is computed once; each seed adds
    barometer noise (and quantisation) and force noise.
    """

    def __init__(self, truth, *, duration: float, rate_hz: float, num_channels: int, trajectory_seed: int = 0, noise_rms: float = PRESSURE_NOISE, force_noise: float = FORCE_NOISE, **history):
        rng = np.random.default_rng(trajectory_seed)
        self.times, self.depth = make_depth_history(rng, duration, rate_hz, **history)
        shapes = rng.uniform(0.3, 1.0, num_channels)
        self.unit, self.force_unit = make_unit_responses(self.depth, shapes)
        self.gains = rng.uniform(0.8, 1.2, num_channels)
        self.offsets = rng.normal(0.0, 50.0, num_channels)
        self.truth = truth
        self.noise_rms = noise_rms
        self.force_noise = force_noise
        stacked = np.column_stack([self.unit, self.force_unit])
        response = np.asarray(calc_contact_response(truth, jnp.asarray(self.times), jnp.asarray(stacked)))
        self.pressures = response[:, :num_channels]
        self.forces = response[:, num_channels:]

    @property
    def unit_responses(self):
        return [(self.unit, self.force_unit)]

    def make(self, seed: int) -> BarometerLog:
        readings = _readings(self.times, self.pressures, self.gains, self.offsets, seed, self.noise_rms)
        force = self.forces + np.random.default_rng(seed).normal(0.0, self.force_noise, self.forces.shape)
        count = readings.shape[1]
        columns = {"time": self.times, **{f"b{k}": readings[:, k] for k in range(count)}}
        columns.update({"fx": force[:, 0], "fy": force[:, 1], "fz": force[:, 2], "indentation": self.depth})
        return BarometerLog(_metadata(count), columns)


def make_lumped_log(relative, amplitudes, exponents, *, duration: float, rate_hz: float, seed: int = 0, noise_rms: float = PRESSURE_NOISE, **history):
    """A lumped-mode log: channel c reads offset + E_rel ∗ (a_c (δ/δ_max)^b_c), with
    `relative` the Prony kernel with E∞ = 1; the `indentation` column is δ."""
    rng = np.random.default_rng(seed)
    times, depth = make_depth_history(rng, duration, rate_hz, **history)
    normalised = depth / depth.max()
    inputs = np.asarray(amplitudes)[None, :] * normalised[:, None] ** np.asarray(exponents)[None, :]
    pressures = np.asarray(calc_contact_response(relative, jnp.asarray(times), jnp.asarray(inputs)))
    count = len(amplitudes)
    readings = _readings(times, pressures, np.ones(count), rng.normal(0.0, 50.0, count), seed + 1, noise_rms)
    columns = {"time": times, **{f"b{k}": readings[:, k] for k in range(count)}, "indentation": depth}
    return BarometerLog(_metadata(count), columns)
