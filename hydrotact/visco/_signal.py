"""The barometer signal model: what a MEMS barometer under the elastomer reports.

    reading(t) = ambient + offset + gain · p(t) + drift · (t − t₀) + noise,

quantised to the part's least significant bit, clipped to the part's range (a BMP388
reads 30-125 kPa: a deeper press saturates it) and sampled at the log's rate. p is the
elastomer pressure at the taxel (from the elastic or viscoelastic model), `gain` the
channel's sensitivity (how much of the elastomer pressure reaches the membrane: 1 for
an ideal casting), `offset` its factory offset, `drift` a slow linear drift (aged or
warming sensors), noise white Gaussian with the part's RMS. The part's numbers (LSB,
noise, rate, ambient) come from the sensor spec's parts list, not from code.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from .._types import Array, Float


class BarometerSignal(eqx.Module):
    """Per-channel barometer numbers (a pytree).

    **Fields:** `ambient` Pa; `offsets` (C,) Pa; `gains` (C,); `drift_rates` (C,)
    Pa/s; `noise_rms` Pa; `lsb` Pa (0 disables quantisation); `range_pa` (2,) the
    part's lowest and highest reading, Pa (readings are clipped to it); `rate_hz` the
    output rate.
    """

    ambient: Float[Array, ""]
    offsets: Float[Array, " num_channels"]
    gains: Float[Array, " num_channels"]
    drift_rates: Float[Array, " num_channels"]
    noise_rms: Float[Array, ""]
    lsb: Float[Array, ""]
    range_pa: Float[Array, "2"]
    rate_hz: float = eqx.field(static=True)

    @property
    def num_channels(self) -> int:
        return self.gains.shape[0]


def make_barometer_signal(part, num_channels: int, *, gains=None, offsets=None, drift_rates=None, noise_rms=None, rate_hz=None) -> BarometerSignal:
    """A BarometerSignal for `num_channels` barometers of `part` (a sensors.Part):
    ambient, LSB, noise and rate from the part unless given; gains default to 1,
    offsets and drifts to 0 (host; checks every number)."""

    def per_channel(values, default, name):
        values = np.asarray(default if values is None else values, dtype=np.float64)
        if values.ndim > 1 or (values.ndim == 1 and values.shape[0] != num_channels):
            raise HydrotactError(f"barometer signal: {name}: {values.size} values for {num_channels} channels")
        values = np.broadcast_to(values, (num_channels,))
        if not np.all(np.isfinite(values)):
            raise HydrotactError(f"barometer signal: {name} must be finite numbers")
        return jnp.asarray(values)

    gains = per_channel(gains, 1.0, "gains")
    if np.any(np.asarray(gains) <= 0.0):
        raise HydrotactError("barometer signal: gains must be positive")
    noise = float(part.noise_rms_pa if noise_rms is None else noise_rms)
    rate = float(part.rate_hz if rate_hz is None else rate_hz)
    if not np.isfinite(noise) or noise < 0.0:
        raise HydrotactError(f"barometer signal: noise RMS must be a non-negative pressure, got {noise:g} Pa")
    if not np.isfinite(rate) or rate <= 0.0:
        raise HydrotactError(f"barometer signal: the rate must be positive, got {rate:g} Hz")
    return BarometerSignal(
        ambient=jnp.asarray(float(part.ambient_pa)),
        offsets=per_channel(offsets, 0.0, "offsets"),
        gains=gains,
        drift_rates=per_channel(drift_rates, 0.0, "drift rates"),
        noise_rms=jnp.asarray(noise),
        lsb=jnp.asarray(float(part.lsb_pa)),
        range_pa=jnp.asarray([float(v) for v in part.range_pa]),
        rate_hz=rate,
    )


def calc_sample_times(times, rate_hz: float) -> np.ndarray:
    """The barometer's sample instants t₀ + k / rate within [t₀, t_end] (host)."""
    times = np.asarray(times, dtype=np.float64)
    count = int(np.floor((times[-1] - times[0]) * rate_hz * (1.0 + 1e-12))) + 1
    return times[0] + np.arange(count) / rate_hz


def calc_resampled(times, values, sample_times):
    """`values` (T, C), linear in time between `times`, read at `sample_times` (pure)."""
    return jax.vmap(jnp.interp, in_axes=(None, None, 1), out_axes=1)(sample_times, times, values)


def calc_barometer_readings(signal: BarometerSignal, sample_times, pressures, key=None, quantise: bool = True):
    """Absolute readings (S, C) Pa of the channels for elastomer pressures (S, C) at
    `sample_times` (S,) (pure). Without `key`, no noise; `quantise` rounds to the
    LSB (its gradient is that of the unrounded reading: a straight-through rule).
    Readings are clipped to the part's range (zero gradient where clipped: the part
    reports nothing of the pressure beyond it)."""
    elapsed = sample_times - sample_times[0]
    reading = signal.ambient + signal.offsets[None, :] + signal.gains[None, :] * pressures + signal.drift_rates[None, :] * elapsed[:, None]
    if key is not None:
        reading = reading + signal.noise_rms * jax.random.normal(key, reading.shape, dtype=reading.dtype)
    if quantise:
        lsb = jnp.where(signal.lsb > 0.0, signal.lsb, 1.0)
        rounded = jnp.where(signal.lsb > 0.0, jnp.round(reading / lsb) * lsb, reading)
        reading = reading + jax.lax.stop_gradient(rounded - reading)
    return jnp.clip(reading, signal.range_pa[0], signal.range_pa[1])
