"""Predicting held-out stage logs from a lumped press fit (`hydrotact compare`).

Everything comes from the fit's `material.json` (the relative Prony series and the
channel law: each site's onset, amplitudes per power of the depth and reach, past which
its laws go on as their value there times (δ/reach)², the lag) except each log's
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
- "first:N": the mean of each channel over the log's first N seconds, its samples
  there that the model says are unloaded (a log that starts at rest and does not
  drift: the baseline "before its first press"); a channel with none is an error;
- "all": the baseline that best fits all samples with the law fixed — what the fit
  itself does, so a fit's own log comes back with the fit's residuals.

The stage's *home* (the travel column's zero) differs between sessions: a held-out
log's contact onsets are the fit's per-site onsets shifted by one unknown amount.
With home="estimate" (the default) that shift is fitted to the log (one number: the
least squares over a grid of ±ONSET_HALF_RANGE, then Levenberg-Marquardt, each
channel's baseline solved with it); with home="fit" the fit's onsets are used as they are.

The prediction comes with a band, each sample's standard deviation from what is not
known exactly: the fit's parameters (the relaxation shape, the sites' onsets, the lag
and the amplitudes, from the covariance the fit writes beside material.json), the
estimated home shift, and the tare (the noise of the samples it is taken from).
`normalized_rms` is the RMS of the error over √(noise² + band²): ≈ 1 where the
prediction is as good as the fit's logs allow. The band is first order, and a lower
bound where a site's onset trades against its law (a flat, curved valley): on the test
stand-in the law's error at a few (site, channel) pairs is 3-5 band sigmas, the same
in every held-out log, and the normalized RMS is 1.04-1.37 (1.08-1.53 without the
band).

For a log the fit used (the same SHA-256), the fit's own onsets and lag for that log
(from its report.json) replace the per-site means, and no home shift is fitted.
"""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import HydrotactError, warn
from ...data import estimate_noise, read_material
from ..shared import HOLD_TOLERANCE, HOMES, Comparison, file_digest, parse_tare as parse_tare, summarise_comparison, tare_baseline, write_comparisons
from ._lumped import ONSET_HALF_RANGE
from ._prediction import _estimate_home, _make_law_model, _parameter_variance, _predict, _tare_variance
from ._press_data import DRIFT_KNOT_S, drift_basis, find_clipped, find_kinks, upper_limit
from ._press_projection import solve_baselines
from ._press_windows import POWERS, make_press_data
from ._presses import SITE_TOLERANCE, find_log_presses

BAND_NOTE = (
    "1 sigma, first order in the fit's parameters, the home shift and the tare: a lower bound where a site's onset trades "
    "against its law (on the test stand-in, single presses' errors reach 3-5 band sigmas)"
)


def read_fit(fit_dir):
    """(material document, report dict or None, the channel law's covariance {qq,
    qa, aa} or None) of a fit folder, checked to hold a lumped press fit."""
    fit_dir = Path(fit_dir)
    path = fit_dir / "material.json" if fit_dir.is_dir() else fit_dir
    if not path.is_file():
        raise HydrotactError(f"{fit_dir}: no material.json (give the folder a `hydrotact fit --lumped` wrote)")
    document = read_material(path)
    if "channel_law" not in document:
        raise HydrotactError(f"{path}: no channel_law: compare needs a lumped press fit (`hydrotact fit --lumped`), which records each channel's law")
    report_path = path.parent / "report.json"
    report = json.loads(report_path.read_text(encoding="utf-8")) if report_path.is_file() else None
    return document, report, _read_covariance(path, document["channel_law"])


def _read_covariance(material_path, law):
    """The covariance file material.json names, checked against its law's sizes
    (None where it names none)."""
    if "covariance_file" not in law:
        return None
    path = material_path.parent / law["covariance_file"]
    try:
        with np.load(path) as data:
            covariance = {key: np.asarray(data[key], dtype=np.float64) for key in ("qq", "qa", "aa")}
    except (OSError, KeyError, ValueError) as error:
        raise HydrotactError(f"{path}: cannot read the channel law's covariance ({error}); refit, or remove covariance_file from {material_path}") from None
    num_sites, num_channels, num_powers = len(law["sites"]), len(law["channels"]), len(law["powers"])
    num_q = covariance["qq"].shape[0]
    expected = {"qq": (num_q, num_q), "qa": (num_channels, num_q, num_sites * num_powers), "aa": (num_channels, num_sites * num_powers, num_sites * num_powers)}
    if any(covariance[key].shape != shape for key, shape in expected.items()) or (num_q - num_sites - 1) % 2:
        raise HydrotactError(f"{path}: its sizes do not match {material_path}'s channel law ({num_channels} channels, {num_sites} sites); refit")
    return covariance


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


def compare_log(document, report, log, source, *, tare="no-load", home="estimate", covariance=None, drift=None, saturation_pa=None) -> Comparison:
    """Predict one log from a fit (see the module's docstring); `covariance` the
    channel law's (from :func:`read_fit`; None: no band). Computed in float64
    whatever the caller's JAX precision (absolute readings of ~1e5 Pa to a Pa)."""
    with jax.enable_x64(True):
        return _compare_log(document, report, log, source, tare=tare, home=home, covariance=covariance, drift=drift, saturation_pa=saturation_pa)


def _compare_log(document, report, log, source, *, tare, home, covariance, drift, saturation_pa) -> Comparison:
    law = document["channel_law"]
    tare = parse_tare(tare) if isinstance(tare, str) else tare
    if home not in HOMES:
        raise HydrotactError(f"--home: expected one of {', '.join(HOMES)}, got {home!r}")
    channels = tuple(law["channels"])
    if tuple(law["powers"]) != tuple(POWERS):
        raise HydrotactError(f"channel_law: powers {law['powers']} are not this version's {list(POWERS)}; refit with this hydrotact")
    missing = [name for name in channels if name not in log.columns]
    if missing:
        raise HydrotactError(f"{source}: no channel {missing[0]!r} of the fit (the log has {', '.join(log.metadata['channels'])})")
    if law["indentation"] not in log.columns:
        raise HydrotactError(f"{source}: no travel column {law['indentation']!r} (the fit's indentation column)")
    presses = find_log_presses(log, law["indentation"], law["position_columns"], source=source)
    own = _own_log(report, file_digest(source))
    sites = law["sites"]
    # Presses that began in a gap are in the model (their memory lifts the next
    # presses' readings) but not compared (their loading is unseen).
    if own is not None and len(own["presses"]) == presses.num_presses:
        site_ids = np.array([p["site"] for p in own["presses"]])
        onsets = np.array([p["onset_m"] for p in own["presses"]])
        lag = float(own["lag_s"]["value"])
        keep = np.ones(presses.num_presses, dtype=bool)
    else:
        own = None
        site_ids = np.array([_site_of(presses.positions[s], sites) for s in presses.sites])
        unknown = (site_ids < 0) & ~presses.unseen
        if unknown.all():
            raise HydrotactError(f"{source}: none of its presses is at a site of the fit (positions from {', '.join(law['position_columns']) or 'no columns'})")
        if unknown.any():
            warn(f"{source}: {int(unknown.sum())} press(es) at sites the fit has not seen: not compared")
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
    noise = np.array([estimate_noise(observed[mask[:, c], c : c + 1])[0] for c in range(len(channels))])
    data = make_press_data(times - times[0], travel, kept.press_of_samples(log.num_samples), site_ids, np.zeros(observed.shape), np.ones(observed.shape), np.zeros((len(times), 1)), len(sites))
    model = _make_law_model(document, data, onsets, site_ids, lag)
    amplitudes = jnp.asarray([[site["amplitudes_Pa"][name] for site in sites] for name in channels], dtype=jnp.float64)  # (C, S, J)
    basis = drift_basis(times, drift if drift is not None else DRIFT_KNOT_S)
    shift, shift_var = 0.0, 0.0
    estimated = home == "estimate" and own is None
    if estimated:
        shift, shift_var = _estimate_home(model, amplitudes, basis, observed, mask, noise)
        if abs(shift) > 0.99 * ONSET_HALF_RANGE:
            warn(f"{source}: its home shift is at its bound (±{ONSET_HALF_RANGE * 1e3:g} mm of the fit's onsets): is it a log of this sensor and stage?")
    elastic, bases, touching, by_q, by_shift = (np.asarray(a) for a in _predict(model, amplitudes, jnp.asarray(shift)))
    baseline, used, tare_basis = tare_baseline(tare, times, observed, elastic, mask, basis, source, channels, _solve_baseline)
    predicted = baseline + elastic
    for c, name in enumerate(channels):
        bad = mask[:, c] & ~np.isfinite(predicted[:, c])
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise HydrotactError(
                f"{source}: channel {name!r}: the prediction is not finite at {int(bad.sum())} of its samples "
                f"(first at row {row + 1}, t = {times[row] - times[0]:.3g} s): nothing compared"
            )
    band = _tare_variance(tare_basis, used, noise)
    if covariance is not None:
        band = band + _parameter_variance(by_q, by_shift, shift_var, covariance, bases, touching, elastic, basis if tare == "all" else None, mask)
    hold = np.full(len(times), -1)
    for p, (start, end) in enumerate(zip(kept.starts, kept.ends)):
        deepest = travel[start:end].max()
        hold[start:end][travel[start:end] >= deepest - HOLD_TOLERANCE] = p
    predicted_std = np.sqrt(band) if covariance is not None else np.full(observed.shape, np.nan)
    return summarise_comparison(
        source, channels, times, observed, predicted, mask, hold, noise, predicted_std,
        home_shift=(float(shift), float(np.sqrt(shift_var))) if estimated else None,
    )


def compare_fit(fit_dir, paths, output, *, mapping=None, tare="no-load", home="estimate", plot=None) -> dict:
    """Compare held-out logs with a lumped fit's prediction and write, into
    `output`: `compare.json` (per log: the home shift; per channel: RMS, R²,
    hold-shape RMS, noise, the band's RMS and the normalized RMS),
    `NAME_predicted.parquet` per log (time, each channel, and its prediction as
    `<channel>_predicted`, its standard deviation `<channel>_predicted_std`, 0/1
    `<channel>_compared`), and with `plot(comparisons,
    output) -> {name: path}` pictures. Everything is read and checked before
    anything is written. Returns the report (with `files`)."""

    from ..._files import check_output
    from ..shared import read_logs

    output = check_output(output, directory=True, what="the comparison")
    tare = parse_tare(tare)
    if home not in HOMES:
        raise HydrotactError(f"--home: expected one of {', '.join(HOMES)}, got {home!r}")
    document, report, covariance = read_fit(fit_dir)
    if covariance is None:
        warn(f"{fit_dir}: its material.json names no covariance of the channel law (a fit written before the prediction band): no band; refit for one")
    logs = read_logs([Path(p) for p in paths], mapping, None, require_sensor=False)
    drift = (report or {}).get("drift")
    with jax.enable_x64(True):
        comparisons = [compare_log(document, report, log, str(path), tare=tare, home=home, covariance=covariance, drift=drift) for log, path in zip(logs, paths)]
    header = {"fit": str(fit_dir), "tare": tare if isinstance(tare, str) else f"first:{tare[1]:g}", "home": home, "prediction_band": BAND_NOTE if covariance is not None else None}
    return write_comparisons(comparisons, paths, output, header, plot)
