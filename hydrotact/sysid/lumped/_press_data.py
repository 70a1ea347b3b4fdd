"""Stage logs made ready for the lumped press model (host): presses and sites found,
clipped samples and the samples at kinks of the stage's path masked, each channel's
noise estimated, silent channels and logs without a responding press skipped, each
press's onset estimated from the readings' first rise, and each log's baseline basis
(a constant, a line, or cubic B-splines with knots `drift` seconds apart).

:func:`prepare_press_logs` returns one :class:`PressLog` per log; :mod:`._press_fit` fits them.
"""

import dataclasses
import warnings

import numpy as np

from ..._errors import HydrotactError, warn
from ...data import estimate_noise, sensor_spec
from ..shared import drift_basis as drift_basis, parse_drift as parse_drift
from ._lumped import ONSET_HALF_RANGE
from ._press_windows import PressData, make_press_data
from ._presses import GAP_FACTOR, POSITION_COLUMNS, PRESS_THRESHOLD, SITE_TOLERANCE, find_log_presses

DRIFT_KNOT_S = 30.0  # s between the baseline spline's knots: slower than any relaxation we fit
RESPONSE_SNR = 20.0  # a channel responds to a press when it moves this many noise stds
SITE_RESPONSE_SNR = 3.0  # a channel's law at a site is fitted where it moves this many noise stds there
FLAT_TOP_SAMPLES = 3  # a channel's maximum held this many times is its clip level
MIN_SAMPLES = 8  # a log shorter than this holds no press to fit
KINK_FRACTION = 0.3  # a change of the stage's speed above this of its top speed is a kink
KINK_WINDOW = 3  # samples on each side over which the stage's speed is measured for kinks
# Where each channel's baseline is learned: "all", jointly with the laws over every
# sample (the default); "unloaded", from the samples out of contact alone, where the
# model reads nothing but its baseline, so that no relaxation can pass into the drift.
# On the stand-in with 20 s holds, a slow term (tau 40 s) and 600 Pa of drift, the joint
# baseline gives the slow term back within its std (the spline cannot follow a
# relaxation that restarts with every press); from the unloaded samples alone the
# model's own misfit passes into the shape instead (~3 std low: tests/test_press_fit.py).
# "unloaded" is the check that a slow term is not drift.
DRIFT_FROM = ("all", "unloaded")


def upper_limit(log, source, saturation_pa=None):
    """The reading limit of a log's channels: `saturation_pa` when given, else its
    part's upper limit for absolute readings of a known sensor, else None."""
    if saturation_pa is not None:
        return float(saturation_pa)
    spec = sensor_spec(log.metadata["sensor"], source) if log.metadata.get("sensor") else None
    return float(spec.part.range_pa[1]) if spec is not None and log.metadata.get("pressure") == "absolute" else None


def find_clipped(observed, upper=None, lower=None) -> np.ndarray:
    """(T, C) samples a barometer clipped: at or beyond the part's limits (when
    known), or at a channel's maximum (minimum) where that value repeats at least
    FLAT_TOP_SAMPLES times (a clipped reading is flat; a noisy peak is not)."""
    observed = np.asarray(observed, dtype=np.float64)
    clipped = np.zeros(observed.shape, dtype=bool)
    if upper is not None:
        clipped |= observed >= upper
    if lower is not None:
        clipped |= observed <= lower
    for extreme in (observed.max(axis=0), observed.min(axis=0)):
        at = observed == extreme[None, :]
        flat = at.sum(axis=0) >= FLAT_TOP_SAMPLES
        clipped |= at & flat[None, :]
    return clipped


def find_kinks(times, travel, reach: int = 1) -> np.ndarray:
    """(T,) samples within `reach` samples of a kink in the travel (where a ramp starts
    or ends: the stage's speed changes by more than KINK_FRACTION of its top speed).
    Between two samples of a log the stage's path is unknown; across a kink, the
    travel a lagged pressure saw (interpolated between the samples) is off by up to a
    quarter of a step's travel — at 1 mm/s and 16 Hz, 15 um or tens of Pa. Such
    samples are masked.

    The speed is measured over KINK_WINDOW samples on each side, and a kink is where
    its change peaks: a real stage logs its position on its own clock and the PC
    stamps the time on receipt (7-20 ms of jitter at 16 Hz), and it reports its
    position in steps, so the speed between two adjacent samples swings by a quarter
    along a steady ramp, which a sample-to-sample test reads as a kink at every
    sample (and then masks every ramp and every peak)."""
    times, travel = np.asarray(times, dtype=np.float64), np.asarray(travel, dtype=np.float64)
    count = len(travel)
    if count < 3:
        return np.zeros(count, dtype=bool)
    index = np.arange(count)
    low, high = np.maximum(index - KINK_WINDOW, 0), np.minimum(index + KINK_WINDOW, count - 1)
    before = (travel - travel[low]) / np.maximum(times - times[low], 1e-12)
    after = (travel[high] - travel) / np.maximum(times[high] - times, 1e-12)
    top = np.percentile(np.abs(after), 99)
    change = np.abs(after - before)
    kink = np.zeros(count, dtype=bool)
    if top > 0.0:
        padded = np.concatenate([[-np.inf], change, [-np.inf]])
        peak = np.flatnonzero((change >= padded[:-2]) & (change >= padded[2:]) & (change > KINK_FRACTION * top))
        # The kink lies between its peak sample and the larger of that one's neighbours.
        kink[peak] = True
        kink[np.clip(np.where(padded[peak + 2] > padded[peak], peak + 1, peak - 1), 0, count - 1)] = True
    near = kink.copy()
    for shift in range(1, reach + 1):
        near[shift:] |= kink[:-shift]
        near[:-shift] |= kink[shift:]
    return near


@dataclasses.dataclass(frozen=True)
class PressLog:
    """One log made ready for the fit (host): `source`; `times` (s from the log's
    start), `travel`, `press`, `press_site` (global site ids), `observed`, `mask`
    (True: fitted), `noise` (C,), `baseline` (T, D), `onset_start` (P,) the onsets'
    first estimates, `clipped` (C,) masked samples per channel, `t0` the log's first
    time, `drift_from` where its baseline is learned (see DRIFT_FROM)."""

    source: str
    times: np.ndarray
    travel: np.ndarray
    press: np.ndarray
    press_site: np.ndarray
    observed: np.ndarray
    mask: np.ndarray
    noise: np.ndarray
    baseline: np.ndarray
    onset_start: np.ndarray
    clipped: np.ndarray
    t0: float
    responses: np.ndarray
    drift_from: str = "all"

    def to_data(self, num_sites: int, responds=None) -> PressData:
        weights = np.where(self.mask, 1.0 / self.noise[None, :], 0.0)
        return make_press_data(self.times, self.travel, self.press, self.press_site, self.observed, weights, self.baseline, num_sites, responds, self.drift_from)


def site_responses(logs: list, num_sites: int) -> np.ndarray:
    """(C, S) whether each channel responds at each site: it moves more than
    SITE_RESPONSE_SNR noise stds in some press at the site, in some log, or no press
    there measured it (NaN responses: clipped through the hold, or begun in a gap). Elsewhere
    its law is fixed at 0: a barometer far from a press reads only noise there, and a
    law of four powers fitted to noise is any shape — where the push max(0, ·) cuts it
    off, the projection leaves it free, and it pushes by tens of Pa where the fit never
    looked (a held-out log, or the model's own residuals)."""
    responds = np.zeros((len(logs[0].noise), num_sites), dtype=bool)
    measured = np.zeros_like(responds)
    for log in logs:
        for p, site in enumerate(log.press_site):
            responds[:, site] |= log.responses[p] > SITE_RESPONSE_SNR
            measured[:, site] |= np.isfinite(log.responses[p])
    return responds | ~measured  # never measured there (clipped through, or a press begun in a gap): fitted


def _level(values) -> np.ndarray:
    """(C,) the median of rows of values with NaN where masked (NaN where all are)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-masked column: NaN, counted as no response
        return np.nanmedian(values, axis=0)


def _responses(observed, travel, times, presses, noise) -> np.ndarray:
    """(P, C) each press's step in each channel, in noise stds: the median level over
    the hold (the samples within 5 % of the press's deepest travel; the ramps' ends are
    masked as kinks, so no fixed few samples will do) against the line through the
    levels just before and just after the press (the baseline drifts: over a 20 s
    hold by more than a far channel's step). `observed` holds NaN where masked.
    A press without a hold (or one masked over its hold) is measured at the deepest
    samples the channel has. Presses that began in a gap count 0; a channel masked
    over a whole press (clipped through it) is NaN: unknown (the channel test counts it
    as a response where the channel clipped in the press and not just before it)."""
    out = np.zeros((presses.num_presses, observed.shape[1]))
    for p, (start, end) in enumerate(zip(presses.starts, presses.ends)):
        if presses.unseen[p]:
            continue
        before = _level(observed[max(start - 4, 0) : max(start, 1)])
        after = _level(observed[min(end, len(observed) - 1) : end + 4])
        before, after = np.where(np.isnan(before), after, before), np.where(np.isnan(after), before, after)  # a press at the log's end
        deep = start + np.flatnonzero(travel[start:end] >= travel[start] + 0.95 * (np.max(travel[start:end]) - travel[start]))
        fraction = (np.mean(deep) - (start - 1)) / max(end - start + 1, 1)
        if np.any(np.diff(times[int(deep[-1]) : end + 4]) > GAP_FACTOR * np.median(np.diff(times))):
            fraction = 0.0  # the press's end fell into a gap: its level after is minutes of drift away
        level = _level(observed[deep])
        # A press without a hold peaks at a kink, masked: its level is then that of
        # the deepest samples the channel has (the response test uses what it has).
        for c in np.flatnonzero(np.isnan(level)):
            rows = start + np.flatnonzero(np.isfinite(observed[start:end, c]))
            if rows.size:
                level[c] = np.median(observed[rows[np.argsort(travel[rows])[-3:]], c])
        out[p] = np.abs(level - (before + fraction * (after - before))) / noise
    return out


def _first_onsets(travel, observed, mask, presses, noise, lag, times) -> np.ndarray:
    """(P,) each press's onset estimate, from its strongest channel's rise on the
    approach: the (lagged) travel where the rise first passes 10 % and 50 % of its
    step, extrapolated back to zero as for a law δ² (δ₁₀ = 0.45 δ₅₀; a Hertz law's
    0.34 or a cone's 0.45 put the estimate within a third of (travel₅₀ − travel₁₀), well
    inside the fitted onset's range). A press whose step is under 10 × RESPONSE_SNR
    noise stds has a 10 % point lost in the noise: it starts at the median estimate of
    the others (the skin's height varies little between sites a few mm apart)."""
    lagged = np.interp(times - lag, times, travel)
    onsets = np.full(presses.num_presses, np.nan)
    for p, (start, end) in enumerate(zip(presses.starts, presses.ends)):
        deepest = start + int(np.argmax(lagged[start:end]))
        if deepest <= start:
            continue
        before = _level(np.where(mask, observed, np.nan)[max(start - 4, 0) : max(start, 1)])
        used = mask[start : deepest + 1] & np.isfinite(before)[None, :]
        rise = (observed[start : deepest + 1] - np.nan_to_num(before)) * np.sign(_level(np.where(used, observed[start : deepest + 1], np.nan)[-4:]) - np.nan_to_num(before))
        rise = np.nan_to_num(rise)
        strongest = int(np.argmax(np.max(np.where(used, np.abs(rise), 0.0), axis=0) / noise))
        curve = np.where(used[:, strongest], rise[:, strongest], -np.inf)
        step = np.max(curve)
        if not step > 10 * RESPONSE_SNR * noise[strongest]:
            continue
        tenth = np.flatnonzero(curve >= 0.1 * step)
        half = np.flatnonzero(curve >= 0.5 * step)
        if not (tenth.size and half.size):
            continue
        low, high = lagged[start + tenth[0]], lagged[start + half[0]]
        onsets[p] = low - 0.45 / 0.55 * max(high - low, 0.0)
    weak = np.isnan(onsets)
    if weak.all():
        return np.array([float(np.max(lagged[start:end])) for start, end in zip(presses.starts, presses.ends)]) - ONSET_HALF_RANGE
    onsets[weak] = np.median(onsets[~weak])
    return onsets


def prepare_press_logs(
    logs, sources, *, indentation="indentation", position_columns=POSITION_COLUMNS, drift=DRIFT_KNOT_S, lag=0.0,
    saturation_pa=None, threshold=PRESS_THRESHOLD, drift_from="all",
):
    """The logs made ready for the fit: presses and sites found, sites matched across
    logs by position, clipped samples masked, noise estimated, silent channels and
    logs without presses skipped (each with a :class:`HydrotactWarning`).

    **Returns:** (PressLogs, fitted channel names, site positions (S, k), skipped
    {name: reason}).
    """
    if drift_from not in DRIFT_FROM:
        raise HydrotactError(f"--drift-from: expected {' or '.join(DRIFT_FROM)}, got {drift_from!r}")
    channels = list(logs[0].metadata["channels"])
    for log, source in zip(logs, sources):
        if list(log.metadata["channels"]) != channels:
            raise HydrotactError(f"{source}: channels {', '.join(log.metadata['channels'])} differ from {sources[0]}'s ({', '.join(channels)}); a joint lumped fit needs logs of one sensor")
    skipped, kept = {}, []
    for log, source in zip(logs, sources):
        if log.num_samples < MIN_SAMPLES:
            raise HydrotactError(f"{source}: {log.num_samples} samples; a fit needs at least {MIN_SAMPLES}")
        try:
            presses = find_log_presses(log, indentation, position_columns, threshold=threshold, source=source)
        except HydrotactError as error:
            if "no indentation column" in str(error) or "stage moves" in str(error):
                raise
            skipped[source] = str(error).removeprefix(f"{source}: ")
            continue
        if presses.unseen.all():
            skipped[source] = "every press began in a gap of the log"
            continue
        if presses.unseen.any():
            warn(f"{source}: {int(presses.unseen.sum())} press(es) began in a gap of the log (loading unseen): masked, kept in the model for their memory")
        kept.append((log, source, presses))
    if not kept:
        raise HydrotactError("no log has a press to fit: " + "; ".join(f"{name}: {reason}" for name, reason in skipped.items()))
    for name, reason in skipped.items():
        warn(f"{name}: skipped: {reason}")
    # Sites shared by the logs: positions within SITE_TOLERANCE are one site; a log
    # without position columns has sites of its own, one per press.
    centres, prepared = [], []
    for log, source, presses in kept:
        if presses.positions.shape[1] == 0:
            site_ids = np.arange(presses.num_presses) + len(centres)
            centres.extend([np.full(len(position_columns), np.nan)] * presses.num_presses)
        else:
            site_ids = np.zeros(presses.num_sites, dtype=np.int64)
            for s, position in enumerate(presses.positions):
                match = [k for k, centre in enumerate(centres) if len(centre) == len(position) and np.all(np.abs(centre - position) <= SITE_TOLERANCE)]
                site_ids[s] = match[0] if match else len(centres)
                if not match:
                    centres.append(np.asarray(position, dtype=np.float64))
            site_ids = site_ids[presses.sites]
        # A press begun in a gap gets a site of its own (no position: never matched),
        # so that its memory, fitted from the samples after it, does not bend the law
        # of the site it was at (its onset is hardly identified).
        for p in np.flatnonzero(presses.unseen):
            site_ids[p] = len(centres)
            centres.append(np.full(len(position_columns), np.nan))
        prepared.append((log, source, presses, site_ids))
    # Channels: masked where clipped; fitted when they respond to some press.
    staged = []
    responding = np.zeros(len(channels), dtype=bool)
    for log, source, presses, site_ids in prepared:
        observed = np.asarray(log.channels, dtype=np.float64)
        travel = np.asarray(log.columns[indentation], dtype=np.float64)
        clipped = find_clipped(observed, upper_limit(log, source, saturation_pa))
        masked = clipped | find_kinks(log.times, travel)[:, None]
        noise = np.array([estimate_noise(observed[~masked[:, c], c : c + 1])[0] for c in range(observed.shape[1])])
        usable = np.where(masked, np.nan, observed)
        responses = _responses(usable, travel, np.asarray(log.times, dtype=np.float64), presses, noise)
        # NaN: masked through a press; where it clipped there (and not just before), it moved.
        rose = np.array([clipped[start:end].any(axis=0) & ~clipped[max(start - 4, 0) : max(start, 1)].any(axis=0) for start, end in zip(presses.starts, presses.ends)])
        log_responding = np.where(np.isnan(responses), rose, responses > RESPONSE_SNR).any(axis=0)
        responding |= log_responding
        staged.append((log, source, presses, site_ids, observed, clipped, masked, noise, log_responding, responses))
    for c, name in enumerate(channels):
        if not responding[c]:
            skipped[name] = f"channel {name!r} moves less than {RESPONSE_SNR:g} noise stds in every press: not fitted"
            warn(f"skipped: {skipped[name]}")
    if not responding.any():
        raise HydrotactError("no channel responds to the presses in any log (each moves less than " f"{RESPONSE_SNR:g} noise stds): nothing to fit")
    fitted = np.flatnonzero(responding)
    out = []
    for log, source, presses, site_ids, observed, clipped, masked, noise, log_responding, responses in staged:
        if not log_responding[fitted].any():
            skipped[source] = f"no channel responds to its presses (each moves less than {RESPONSE_SNR:g} noise stds)"
            warn(f"{source}: skipped: {skipped[source]}")
            continue
        times = np.asarray(log.times, dtype=np.float64)
        travel = np.asarray(log.columns[indentation], dtype=np.float64)
        mask = ~masked[:, fitted]
        mask[presses.select(presses.unseen).press_of_samples(log.num_samples) >= 0] = False
        # A press that began in a gap stays in the model, its samples masked: its loading
        # is unseen, but its memory lifts the next presses' readings as the skin
        # recovers (by ~70 Pa over a hold on a skin relaxing 40 %; dropped, it left the
        # log after the gap at a reduced chi2 of ~58 at the true relaxation). Its
        # onset starts at the median of the others'.
        seen = presses.select(~presses.unseen)
        onset_start = np.full(presses.num_presses, np.nan)
        onset_start[~presses.unseen] = _first_onsets(travel, observed[:, fitted], mask, seen, noise[fitted], float(lag), times)
        onset_start[presses.unseen] = np.median(onset_start[~presses.unseen])
        out.append(PressLog(
            source=source, times=times - times[0], travel=travel, press=presses.press_of_samples(log.num_samples), press_site=site_ids,
            observed=observed[:, fitted], mask=mask, noise=noise[fitted], baseline=drift_basis(times, drift), onset_start=onset_start,
            clipped=clipped[:, fitted].sum(axis=0), t0=float(times[0]), responses=np.where(presses.unseen[:, None], np.nan, responses)[:, fitted],
            drift_from=drift_from,
        ))
        if clipped[:, fitted].any():
            counts = ", ".join(f"{channels[c]} {n}" for c, n in zip(fitted, clipped[:, fitted].sum(axis=0)) if n)
            warn(f"{source}: masked clipped samples ({counts})")
    if not out:
        raise HydrotactError("no log has a responding channel: " + "; ".join(f"{name}: {reason}" for name, reason in skipped.items()))
    width = max((len(c) for c in centres), default=0)
    sites = np.array([np.resize(c, width) for c in centres]) if centres else np.zeros((0, 0))
    return out, tuple(channels[c] for c in fitted), sites, skipped
