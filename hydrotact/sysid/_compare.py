"""Predicting held-out stage logs from a lumped press fit (`hydrotact compare`).

Everything comes from the fit's `material.json` (the relative Prony series and the
channel law: each site's onset and amplitudes per power of the depth, the lag) except each log's
baseline, the *tare*, which comes from the log itself:

- "no-load" (default): each channel's baseline fitted to the log's samples where the
  model predicts no load (the fit's drift basis, by least squares): between presses,
  and in presses where the channel's law is 0 or its push is cut off by the skin's
  recovery. A stage log rests for as little as 0.1 s between presses: on a held-out
  stand-in log of the tests, the rests alone (114 of 1,706 samples) leave a drifting
  baseline 3.5 Pa RMS off, ~2 noise stds; with the samples in presses that the model
  says are unloaded, 0.3 and 1.0 Pa on two channels. Where the model wrongly says
  no load (the third channel, whose push it cuts off at one press that truly reads
  5-15 Pa), its error moves into the tare: 4.7 Pa;
- "first:N": the mean of each channel over the log's first N seconds (a log that
  starts at rest and does not drift);
- "all": the baseline that best fits all samples with the law fixed — what the fit
  itself does, so a fit's own log comes back with the fit's residuals.

For a log the fit used (the same SHA-256), the fit's own onsets and lag for that log
(from its report.json) replace the per-site means.
"""

import dataclasses
import json
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from ..data import estimate_noise, read_material
from ..visco import Prony
from ._lumped import calc_elastic, solve_baselines
from ._press_data import DRIFT_KNOT_S, drift_basis, find_clipped, find_kinks, upper_limit
from ._press_windows import POWERS, calc_bases, calc_depths, make_press_data
from ._presses import SITE_TOLERANCE, find_log_presses
from ._problem import _file_digest

HOLD_TOLERANCE = 1e-6  # m: a press holds where its travel is within this of its deepest


@dataclasses.dataclass(frozen=True)
class Comparison:
    """One held-out log against a fit's prediction: `source`, `channels`, `times`
    (s), `observed`, `predicted` (T, C) Pa (the tare included), `mask` (T, C) True
    where compared, `hold` (T,) the press held at each sample (-1 elsewhere), and
    per channel `rms_pa`, `r2`, `hold_shape_rms_pa` (the residual during holds less
    each hold's mean: how well the relaxation's shape is predicted), `noise_pa`."""

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

    def to_json(self) -> dict:
        return {
            "source": self.source,
            "channels": {
                name: {
                    "rms_Pa": _number(self.rms_pa[c]), "r2": _number(self.r2[c]), "hold_shape_rms_Pa": _number(self.hold_shape_rms_pa[c]), "noise_Pa": _number(self.noise_pa[c]),
                }
                for c, name in enumerate(self.channels)
            },
        }


def _number(value):
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


def read_fit(fit_dir):
    """(material document, report dict or None) of a fit folder, checked to hold a
    lumped press fit."""
    fit_dir = Path(fit_dir)
    path = fit_dir / "material.json" if fit_dir.is_dir() else fit_dir
    if not path.is_file():
        raise HydrotactError(f"{fit_dir}: no material.json (give the folder a `hydrotact fit --lumped` wrote)")
    document = read_material(path)
    if "channel_law" not in document:
        raise HydrotactError(f"{path}: no channel_law: compare needs a lumped press fit (`hydrotact fit --lumped`), which records each channel's law")
    report_path = path.parent / "report.json"
    report = json.loads(report_path.read_text(encoding="utf-8")) if report_path.is_file() else None
    return document, report


def _law_prony(document) -> Prony:
    terms = document["prony_terms"]
    return Prony(
        jnp.asarray(float(document["long_term_modulus_Pa"]["value"])),
        jnp.asarray([float(t["modulus_Pa"]["value"]) for t in terms]),
        jnp.asarray([float(t["tau_s"]["value"]) for t in terms]),
    )


def _site_of(position, sites) -> int:
    for s, site in enumerate(sites):
        known = np.asarray(site["position_m"], dtype=np.float64)
        if len(known) == len(position) and len(known) and np.all(np.abs(known - position) <= SITE_TOLERANCE):
            return s
    return -1


def _own_log(report, digest):
    """The fit report's entry for the fitted log with this digest (its onsets, lag)."""
    if report is None or digest is None:
        return None
    for log in report.get("logs", []):
        if log.get("sha256") == digest:
            return log
    return None


def _solve_baseline(basis, observed, elastic, used):
    """(D, C) baseline coefficients fitting observed − elastic on `used` (T, C) (the
    press fit's own solve, so that a fitted log is reproduced exactly)."""
    if not used.any(axis=0).all():
        raise HydrotactError("no sample to tare on")
    return np.asarray(solve_baselines(jnp.asarray(basis), jnp.asarray(observed - elastic), jnp.asarray(used))).T


def compare_log(document, report, log, source, *, tare="no-load", drift=None, saturation_pa=None, report_message=None) -> Comparison:
    """Predict one log from a fit (see the module's docstring)."""
    say = report_message or (lambda message: None)
    law = document["channel_law"]
    tare = parse_tare(tare) if isinstance(tare, str) else tare
    channels = tuple(law["channels"])
    if tuple(law["powers"]) != tuple(POWERS):
        raise HydrotactError(f"channel_law: powers {law['powers']} are not this version's {list(POWERS)}; refit with this hydrotact")
    missing = [name for name in channels if name not in log.columns]
    if missing:
        raise HydrotactError(f"{source}: no channel {missing[0]!r} of the fit (the log has {', '.join(log.metadata['channels'])})")
    if law["indentation"] not in log.columns:
        raise HydrotactError(f"{source}: no travel column {law['indentation']!r} (the fit's indentation column)")
    presses = find_log_presses(log, law["indentation"], law["position_columns"], source=source)
    own = _own_log(report, _file_digest(source))
    sites = law["sites"]
    # Presses that began in a gap are in the model (their memory lifts the next
    # presses' readings) but not compared (their loading is unseen).
    if own is not None and len(own["presses"]) == presses.num_presses:
        site_ids = np.array([p["site"] for p in own["presses"]])
        onsets = np.array([p["onset_m"] for p in own["presses"]])
        lag = float(own["lag_s"]["value"])
        keep = np.ones(presses.num_presses, dtype=bool)
    else:
        site_ids = np.array([_site_of(presses.positions[s], sites) for s in presses.sites])
        unknown = (site_ids < 0) & ~presses.unseen
        if unknown.all():
            raise HydrotactError(f"{source}: none of its presses is at a site of the fit (positions from {', '.join(law['position_columns']) or 'no columns'})")
        if unknown.any():
            say(f"{source}: {int(unknown.sum())} press(es) at sites the fit has not seen: not compared")
        keep = site_ids >= 0
        onsets = np.array([sites[s]["onset_m"] for s in site_ids[keep]])
        lag = float(law["lag_s"])
        site_ids = site_ids[keep]
    observed = np.column_stack([np.asarray(log.columns[name], dtype=np.float64) for name in channels])
    times = np.asarray(log.times, dtype=np.float64)
    travel = np.asarray(log.columns[law["indentation"]], dtype=np.float64)
    mask = ~find_clipped(observed, upper_limit(log, source, saturation_pa)) & ~find_kinks(times, travel)[:, None]
    mask[presses.select(~keep | presses.unseen).press_of_samples(log.num_samples) >= 0] = False
    kept = presses.select(keep)
    press = kept.press_of_samples(log.num_samples)
    data = make_press_data(times - times[0], travel, press, site_ids, np.zeros(observed.shape), np.ones(observed.shape), np.zeros((len(times), 1)), len(sites))
    depths = calc_depths(data, jnp.asarray(onsets), lag)
    bases = np.asarray(calc_bases(_law_prony(document), depths, data))  # (T, S, J)
    amplitudes = np.array([[site["amplitudes_Pa"][name] for site in sites] for name in channels], dtype=np.float64)  # (C, S, J)
    elastic = np.asarray(calc_elastic(bases, depths > 0.0, amplitudes))
    if isinstance(tare, tuple):
        first = times - times[0] <= tare[1]
        baseline = np.broadcast_to(np.mean(np.where(mask & first[:, None], observed, np.nan), axis=0)[None, :], observed.shape)
        if first.sum() < 1:
            raise HydrotactError(f"{source}: no samples in the first {tare[1]:g} s to tare on")
    else:
        basis = drift_basis(times, drift if drift is not None else DRIFT_KNOT_S)
        used = mask if tare == "all" else mask & (elastic == 0.0)
        baseline = basis @ _solve_baseline(basis, observed, elastic, used)
    predicted = baseline + elastic
    hold = np.full(len(times), -1)
    for p, (start, end) in enumerate(zip(kept.starts, kept.ends)):
        deepest = travel[start:end].max()
        hold[start:end][travel[start:end] >= deepest - HOLD_TOLERANCE] = p
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a channel clipped through a whole hold: NaN there, None in JSON
        error = np.where(mask, observed - predicted, np.nan)
        rms = np.sqrt(np.nanmean(error**2, axis=0))
        spread = np.nansum((np.where(mask, observed, np.nan) - np.nanmean(np.where(mask, observed, np.nan), axis=0)) ** 2, axis=0)
        r2 = 1.0 - np.nansum(error**2, axis=0) / np.maximum(spread, 1e-300)
        shaped = np.full(error.shape, np.nan)
        for p in range(kept.num_presses):
            rows = hold == p
            if rows.sum() > 1:
                shaped[rows] = error[rows] - np.nanmean(error[rows], axis=0)
        hold_shape = np.sqrt(np.nanmean(shaped**2, axis=0))
    return Comparison(
        source=source, channels=channels, times=times, observed=observed, predicted=predicted, mask=mask, hold=hold, rms_pa=rms, r2=r2,
        hold_shape_rms_pa=hold_shape, noise_pa=np.array([estimate_noise(observed[mask[:, c], c : c + 1])[0] for c in range(len(channels))]),
    )


def compare_fit(fit_dir, paths, output, *, mapping=None, tare="no-load", report_warning=None, plot=None) -> dict:
    """Compare held-out logs with a lumped fit's prediction and write, into
    `output`: `compare.json` (per log and channel: RMS, R², hold-shape RMS, noise),
    `NAME_predicted.parquet` per log (time, each channel, and its prediction as
    `<channel>_predicted`, 0/1 `<channel>_compared`), and with `plot(comparisons,
    output) -> {name: path}` pictures. Everything is read and checked before
    anything is written. Returns the report (with `files`)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from .. import __version__
    from .._files import atomic_path, write_text_atomic
    from ._fit_logs import read_logs

    output = Path(output)
    if output.exists() and not output.is_dir():
        raise HydrotactError(f"{output}: exists and is not a folder; -o names the folder compare writes into")
    tare = parse_tare(tare)
    document, report = read_fit(fit_dir)
    logs = read_logs([Path(p) for p in paths], mapping, None, report_warning, require_sensor=False)
    drift = (report or {}).get("drift")
    with jax.enable_x64(True):
        comparisons = [compare_log(document, report, log, str(path), tare=tare, drift=drift, report_message=report_warning) for log, path in zip(logs, paths)]
    output.mkdir(parents=True, exist_ok=True)
    files = {}
    for comparison, path in zip(comparisons, paths):
        columns = {"time": comparison.times}
        for c, name in enumerate(comparison.channels):
            columns[name] = comparison.observed[:, c]
            columns[f"{name}_predicted"] = comparison.predicted[:, c]
            columns[f"{name}_compared"] = comparison.mask[:, c].astype(np.int8)
        target = output / f"{Path(path).stem}_predicted.parquet"
        with atomic_path(target) as tmp:
            pq.write_table(pa.table(columns), tmp)
        files[f"{Path(path).stem}_predicted"] = str(target)
    if plot is not None:
        files.update(plot(comparisons, output))
    result = {"generator": f"hydrotact {__version__}", "fit": str(fit_dir), "tare": tare if isinstance(tare, str) else f"first:{tare[1]:g}", "logs": [c.to_json() for c in comparisons]}
    files["report"] = str(output / "compare.json")
    result["files"] = files
    write_text_atomic(files["report"], json.dumps(result, indent=2) + "\n")
    return result
