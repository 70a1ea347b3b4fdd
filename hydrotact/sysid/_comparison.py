"""What a comparison of held-out logs with a fit's prediction reports, whichever
fit predicted them (the lumped press model's `compare`, or a full-mode fit through a
rig): per channel RMS, R², the hold shapes' RMS, the noise, the band, the normalized
RMS; the tare taken from the log itself; the predicted logs and compare.json."""

import dataclasses
import json
import warnings
from pathlib import Path

import numpy as np

from .._errors import HydrotactError

HOLD_TOLERANCE = 1e-6  # m: a press holds where its travel is within this of its deepest
HOMES = ("estimate", "fit")  # a held-out log's home: fitted to it, or the fit's


@dataclasses.dataclass(frozen=True)
class Comparison:
    """One held-out log against a fit's prediction: `source`, `channels`, `times`
    (s), `observed`, `predicted` (T, C) Pa (the tare included), `mask` (T, C) True
    where compared, `hold` (T,) the press held at each sample (-1 elsewhere), and
    per channel `rms_pa`, `r2`, `hold_shape_rms_pa` (the residual during holds less
    each hold's mean: how well the relaxation's shape is predicted), `noise_pa`;
    `predicted_std` (T, C) the prediction's standard deviation, Pa (NaN without the
    fit's covariance), per channel `prediction_std_pa` (its RMS over the compared
    samples) and `normalized_rms` (the error over √(noise² + band²)); `home_shift_m`
    and `home_shift_std_m` the fitted shift of the log's onsets (None where not
    fitted)."""

    source: str
    channels: tuple
    times: np.ndarray
    observed: np.ndarray
    predicted: np.ndarray
    mask: np.ndarray
    hold: np.ndarray
    rms_pa: np.ndarray
    r2: np.ndarray
    hold_shape_rms_pa: np.ndarray
    noise_pa: np.ndarray
    predicted_std: np.ndarray
    prediction_std_pa: np.ndarray
    normalized_rms: np.ndarray
    home_shift_m: float | None = None
    home_shift_std_m: float | None = None

    def to_json(self) -> dict:
        home = None if self.home_shift_m is None else {"value": self.home_shift_m, "std": self.home_shift_std_m}
        return {
            "source": self.source,
            "home_shift_m": home,
            "channels": {
                name: {
                    "rms_Pa": number(self.rms_pa[c]), "r2": number(self.r2[c]), "hold_shape_rms_Pa": number(self.hold_shape_rms_pa[c]), "noise_Pa": number(self.noise_pa[c]),
                    "prediction_std_Pa": number(self.prediction_std_pa[c]), "normalized_rms": number(self.normalized_rms[c]),
                }
                for c, name in enumerate(self.channels)
            },
        }


def number(value):
    """A float for JSON, None where there is no number (a channel masked throughout)."""
    return float(value) if np.isfinite(value) else None


def parse_tare(text):
    """'no-load', 'all' or 'first:N' (N seconds > 0)."""
    if text in ("no-load", "all"):
        return text
    if isinstance(text, str) and text.startswith("first:"):
        try:
            seconds = float(text[len("first:") :])
        except ValueError:
            seconds = float("nan")
        if seconds > 0:
            return ("first", seconds)
    raise HydrotactError(f"--tare: expected no-load, all or first:SECONDS, got {text!r}")


def tare_baseline(tare, times, observed, elastic, mask, basis, source, channels, solve_baseline):
    """(the baseline (T, C), the samples it was taken from (T, C), its basis) of a
    held-out log: `tare` ("no-load", "all" or ("first", S)); `elastic` the model's
    prediction without baseline (0: unloaded); `basis` (T, D) the drift basis;
    `solve_baseline(basis, observed, elastic, used)` -> (D, C) coefficients."""
    if isinstance(tare, tuple):
        first = times - times[0] <= tare[1]
        if first.sum() < 1:
            raise HydrotactError(f"{source}: no samples in the first {tare[1]:g} s to tare on")
        used = mask & first[:, None] & (elastic == 0.0)  # its no-load samples there
        for c in np.flatnonzero(~used.any(axis=0)):
            raise HydrotactError(
                f"{source}: channel {channels[c]!r} has no unloaded, unmasked sample in the log's first {tare[1]:g} s to tare on "
                f"(--tare first:{tare[1]:g}): take more seconds, or --tare no-load"
            )
        baseline = np.broadcast_to((np.sum(np.where(used, observed, 0.0), axis=0) / used.sum(axis=0))[None, :], observed.shape)
        tare_basis = np.ones((len(times), 1))
    else:
        used = mask if tare == "all" else mask & (elastic == 0.0)
        baseline = basis @ solve_baseline(basis, observed, elastic, used)
        tare_basis = basis
    return baseline, used, tare_basis


def summarise_comparison(source, channels, times, observed, predicted, mask, hold, noise, predicted_std, home_shift=None) -> "Comparison":
    """The Comparison of a predicted log: `mask` (T, C) the samples compared, `hold`
    (T,) the press held at each sample (-1 elsewhere), `noise` (C,) Pa,
    `predicted_std` (T, C) (NaN: no band), `home_shift` (value, std) m or None."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a channel clipped through a whole hold: NaN there, None in JSON
        error = np.where(mask, observed - predicted, np.nan)
        rms = np.sqrt(np.nanmean(error**2, axis=0))
        spread = np.nansum((np.where(mask, observed, np.nan) - np.nanmean(np.where(mask, observed, np.nan), axis=0)) ** 2, axis=0)
        r2 = np.where(mask.any(axis=0), 1.0 - np.nansum(error**2, axis=0) / np.maximum(spread, 1e-300), np.nan)  # nothing compared: n/a, not 1
        shaped = np.full(error.shape, np.nan)
        for p in range(int(hold.max()) + 1 if len(hold) else 0):
            rows = hold == p
            if rows.sum() > 1:
                shaped[rows] = error[rows] - np.nanmean(error[rows], axis=0)
        hold_shape = np.sqrt(np.nanmean(shaped**2, axis=0))
        prediction_std = np.sqrt(np.nanmean(np.where(mask, predicted_std**2, np.nan), axis=0))
        normalized = np.sqrt(np.nanmean(error**2 / (noise**2 + np.where(np.isfinite(predicted_std), predicted_std, 0.0) ** 2), axis=0))
    return Comparison(
        source=source, channels=channels, times=times, observed=observed, predicted=predicted, mask=mask, hold=hold, rms_pa=rms, r2=r2,
        hold_shape_rms_pa=hold_shape, noise_pa=noise, predicted_std=predicted_std, prediction_std_pa=prediction_std, normalized_rms=normalized,
        home_shift_m=None if home_shift is None else home_shift[0], home_shift_std_m=None if home_shift is None else home_shift[1],
    )


def write_comparisons(comparisons, paths, output, header: dict, plot=None, files: dict | None = None) -> dict:
    """Write each comparison's `NAME_predicted.parquet`, the pictures (`plot`) and
    compare.json (`header`, then the logs) into `output`; returns the report (its
    `files` beginning with `files`, those the caller already wrote there)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from .. import __version__
    from .._files import atomic_path, write_text_atomic

    output.mkdir(parents=True, exist_ok=True)
    files = dict(files or {})
    for comparison, path in zip(comparisons, paths):
        columns = {"time": comparison.times}
        for c, name in enumerate(comparison.channels):
            columns[name] = comparison.observed[:, c]
            columns[f"{name}_predicted"] = comparison.predicted[:, c]
            columns[f"{name}_predicted_std"] = comparison.predicted_std[:, c]
            columns[f"{name}_compared"] = comparison.mask[:, c].astype(np.int8)
        target = output / f"{Path(path).stem}_predicted.parquet"
        with atomic_path(target) as tmp:
            pq.write_table(pa.table(columns), tmp)
        files[f"{Path(path).stem}_predicted"] = str(target)
    if plot is not None:
        files.update(plot(comparisons, output))
    result = {"generator": f"hydrotact {__version__}", **header, "logs": [c.to_json() for c in comparisons]}
    files["report"] = str(output / "compare.json")
    result["files"] = files
    write_text_atomic(files["report"], json.dumps(result, indent=2) + "\n")
    return result
