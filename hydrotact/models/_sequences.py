"""Training sequences from a dataset's contiguous blocks (host, NumPy).

A recurrent estimator's state at a sample depends on the samples before it. The paper
re-runs a 512-sample history for every label (a window per label: 512 steps of work
per label). Here a block is cut into consecutive sequences of `length` labelled
samples, each preceded by `burn_in` samples of context whose outputs do not count
(mask 0): about (length + burn_in) / length steps of work per label. With
`length=1, burn_in=511` the same function gives the paper's windows (see the benchmark).

At a block's start the context is shorter; the sequence is then padded at the front
with the block's first sample (masked). Inputs are normalised per channel with the
training split's mean and standard deviation, of the readings or of their asinh
(:class:`Normaliser`).
"""

import dataclasses

import numpy as np

from .._errors import HydrotactError
from ._estimator import FORCES, LABEL_COLUMNS, label_column


@dataclasses.dataclass(frozen=True)
class Normaliser:
    """Per-channel input normalisation: z-scores (the mean and standard deviation over
    the training inputs) of the readings in Pa, the paper's; or, with `scale` (Pa), of
    asinh((y - rest) / scale), `rest` each channel's reading at rest (Pa): linear
    within `scale` of rest and logarithmic above it, so that a light press moves the
    inputs by a visible step as well as a hard one does. (`mean` and `std` are then of
    the compressed inputs, unitless.)"""

    mean: np.ndarray
    std: np.ndarray
    rest: np.ndarray | None = None
    scale: float | None = None

    @classmethod
    def fit(cls, readings: np.ndarray, scale: float | None = None, resting: np.ndarray | None = None) -> "Normaliser":
        """From the training `readings` (N, C) Pa; with `scale`, the rest is each
        channel's median over the samples `resting` marks (N,) (no contact; all
        samples where none is marked)."""
        rest = None
        if scale is not None:
            quiet = readings[resting] if resting is not None and np.any(resting) else readings
            rest = np.median(quiet, axis=0)
        inputs = cls(np.zeros(readings.shape[1]), np.ones(readings.shape[1]), rest, scale).compress(readings)
        std = inputs.std(axis=0)
        return cls(inputs.mean(axis=0), np.where(std > 0.0, std, 1.0), rest, scale)

    def compress(self, readings: np.ndarray) -> np.ndarray:
        """The readings before the z-scores: as they are, or asinh((y - rest) / scale)."""
        return readings if self.scale is None else np.arcsinh((readings - self.rest) / self.scale)

    def __call__(self, readings: np.ndarray) -> np.ndarray:
        return (self.compress(readings) - self.mean) / self.std

    def to_json(self) -> dict:
        document = {"mean_Pa": self.mean.tolist(), "std_Pa": self.std.tolist()}
        if self.scale is not None:
            document |= {"asinh_scale_Pa": float(self.scale), "rest_Pa": np.asarray(self.rest).tolist()}
        return document

    @classmethod
    def from_json(cls, document: dict) -> "Normaliser":
        scale = document.get("asinh_scale_Pa")
        rest = None if scale is None else np.asarray(document["rest_Pa"], dtype=np.float64)
        return cls(np.asarray(document["mean_Pa"], dtype=np.float64), np.asarray(document["std_Pa"], dtype=np.float64), rest, None if scale is None else float(scale))


def target_labels(arrays: dict, targets, source: str = "the data") -> np.ndarray:
    """The labels (N, K) of regression `targets` from columns `arrays` (see
    :data:`hydrotact.models.LABEL_COLUMNS`), or an error naming the missing label."""
    columns = []
    for name in targets:
        column = label_column(name, arrays)
        if column is None:
            raise HydrotactError(f"{source}: no label for the target {name!r} (a column {' or '.join(map(repr, LABEL_COLUMNS[name]))})")
        columns.append(np.asarray(arrays[column], dtype=np.float64))
    return np.column_stack(columns) if columns else np.zeros((len(arrays["time"]), 0))


def make_sequences(arrays: dict, channels, normaliser: Normaliser, length: int, burn_in: int, stride: int | None = None, dtype=np.float32, targets=FORCES) -> tuple[np.ndarray, dict]:
    """Sequences of `burn_in + length` samples from `arrays` (a dataset split's
    columns with `block_starts`): inputs (S, burn_in + length, channels) normalised,
    and targets {values (S, T, K) the regression `targets`' labels, theta, phi,
    contact, mask (S, T)}. Labelled spans start every `stride` samples (default
    `length`: each label once) within a block."""
    if length < 1 or burn_in < 0:
        raise ValueError(f"length must be positive and burn_in non-negative, got {length}, {burn_in}")
    stride = stride or length
    total = len(arrays["time"])
    edges = list(np.asarray(arrays["block_starts"], dtype=np.int64)) + [total]
    inputs = normaliser(np.column_stack([arrays[name] for name in channels]))
    values = target_labels(arrays, targets)
    theta = arrays.get("theta", np.full(total, np.nan))
    phi = arrays.get("phi", np.full(total, np.nan))
    contact = arrays["contact"]
    steps = burn_in + length
    index, mask = [], []
    for first, end in zip(edges[:-1], edges[1:]):
        for start in range(first, end, stride):
            span = np.arange(start - burn_in, start + length)
            valid = (span >= start) & (span < end)
            index.append(np.clip(span, first, end - 1))
            mask.append(valid)
    index = np.asarray(index, dtype=np.int64).reshape(-1, steps)
    mask = np.asarray(mask, dtype=bool).reshape(-1, steps)
    targets = {"values": values[index].astype(dtype), "theta": theta[index].astype(dtype), "phi": phi[index].astype(dtype),
               "contact": contact[index].astype(dtype), "mask": mask.astype(dtype)}
    return inputs[index].astype(dtype), targets
