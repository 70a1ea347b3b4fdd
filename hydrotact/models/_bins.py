"""Binned angle heads: θ and φ as classes over fixed-width bins (the barometric
estimation paper's Binned RNN, Eq. 1).

A range [low, high] is covered by `count` = ceil((high - low) / width) bins of the
given width (π/16 by default), centred on the range: the bins overhang both ends by
the same amount when the range is not a whole number of widths. The paper's own
ellipsoid bins were counted with a floor and left the top of the φ range uncovered
(θ ±40°: 7 bins, φ ±72°: 12); `cover="floor"` reproduces them (for the paper's
parameter counts), starting at `low`.

An angle is decoded as the probability-weighted mean of the bin centres (Eq. 1):
θ̂ = Σ_k softmax(z)_k c_k. Its training target is the index of the bin holding the
true angle (cross-entropy); an angle outside the bins falls in the nearest end bin.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

BIN_WIDTH = math.pi / 16
"""The papers' bin width (rad)."""


@dataclasses.dataclass(frozen=True)
class AngleBins:
    """`count` bins of `width` (rad) starting at `start`: bin k spans
    [start + k width, start + (k + 1) width]; `low`, `high` the range they cover."""

    low: float
    high: float
    width: float
    count: int
    start: float

    @property
    def centres(self) -> np.ndarray:
        return self.start + (np.arange(self.count) + 0.5) * self.width

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


def make_angle_bins(low: float, high: float, width: float = BIN_WIDTH, cover: str = "whole") -> AngleBins:
    """Bins over [low, high] (rad): `cover="whole"` (ceil, centred; every angle of the
    range lies in a bin) or `"floor"` (the paper's count, from `low`; see the module)."""
    if not (np.isfinite(low) and np.isfinite(high) and high > low and width > 0.0):
        raise ValueError(f"angle bins need low < high and width > 0, got {low!r}, {high!r}, {width!r}")
    span = (high - low) / width
    if cover == "whole":
        count = max(1, math.ceil(span - 1e-9))
        return AngleBins(float(low), float(high), float(width), count, float(0.5 * (low + high) - 0.5 * count * width))
    if cover == "floor":
        return AngleBins(float(low), float(high), float(width), max(1, math.floor(span + 1e-9)), float(low))
    raise ValueError(f"cover must be 'whole' or 'floor', got {cover!r}")


def calc_bin_index(bins: AngleBins, angle):
    """The bin holding each angle (ints; outside the bins: the nearest end bin)."""
    return jnp.clip(jnp.floor((angle - bins.start) / bins.width), 0, bins.count - 1).astype(jnp.int32)


def decode_bins(bins: AngleBins, logits):
    """Eq. 1: the softmax-weighted mean of the bin centres. `logits` (..., count)."""
    # A sum per row, not a matrix product: one sample decodes to the same bits alone
    # (streaming) as in a batch (a matrix-vector product's blocking differs with the rows).
    centres = jnp.asarray(bins.centres, dtype=logits.dtype).reshape((1,) * (logits.ndim - 1) + (-1,))
    return jnp.sum(jax.nn.softmax(logits, axis=-1) * centres, axis=-1)
