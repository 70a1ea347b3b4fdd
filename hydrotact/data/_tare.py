"""Tare calibration: subtract each barometer's no-load baseline, drift included.

A barometer cast in silicone reads the ambient pressure plus an offset that creeps as
the elastomer ages; the barometric estimation work tares such sensors on the stretches
of a log where nothing touches the skin. Here a no-load segment comes from the log's
`contact` flag, its `indentation` (<= 0), its force columns (|f| <= 0.1 N), or, when it
has none, from the signal itself; the baseline is each channel's mean over each segment,
interpolated linearly in time between segment centres (and continued along the
first and the last piece), so a drifting baseline is followed rather than averaged away.
"""

import math

import numpy as np

from .._errors import HydrotactError
from ._log import BarometerLog, _runs

METHODS = ("auto", "contact", "indentation", "force", "signal")
# Defaults: |force| at or below this is no load (the `contact` flag's threshold), N; a
# quiet stretch has rolling stds within QUIET_FACTOR noise stds; a no-load stretch lies
# within LEVEL_FACTOR noise stds of the baseline its neighbours predict.
FORCE_THRESHOLD_N = 0.1
QUIET_FACTOR = 2.0
LEVEL_FACTOR = 6.0


def estimate_noise(channels: np.ndarray) -> np.ndarray:
    """Each channel's white-noise standard deviation, from its samples alone.

    The median absolute second difference / (0.6745 √6): second differences cancel
    steps' neighbours, ramps and slow drift, and the median ignores the few samples at
    load changes. Floored at the quantisation noise implied by the smallest non-zero
    step (LSB / √12: a quiet quantised channel can have a median difference of 0) and
    at 1e-12 of the channel's level.

    **Arguments:** `channels`: (num_samples, num_channels) readings.

    **Returns:** (num_channels,) standard deviations, in the readings' unit.
    """
    values = np.asarray(channels, dtype=np.float64)
    second = np.diff(values, n=2, axis=0)
    sigma = np.median(np.abs(second), axis=0) / (0.6745 * math.sqrt(6.0))
    steps = np.abs(np.diff(values, axis=0))
    lsb = np.min(np.where(steps > 0.0, steps, np.inf), axis=0)
    floor = np.where(np.isfinite(lsb), lsb / math.sqrt(12.0), 0.0)
    return np.maximum(np.maximum(sigma, floor), 1e-12 * np.maximum(np.max(np.abs(values), axis=0), 1.0))


def _min_samples(times: np.ndarray, duration: float) -> int:
    step = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    return max(2, int(math.ceil(duration / step - 1e-9)))


def _segments_from_mask(mask: np.ndarray, times: np.ndarray, min_duration: float, margin: float) -> list[tuple[int, int]]:
    """Runs of `mask`, each trimmed by `margin` seconds at both ends, kept when they
    still last `min_duration` seconds (in samples at the median step)."""
    minimum = _min_samples(times, min_duration)
    segments = []
    for start, stop in _runs(mask):
        if margin > 0.0:
            start = int(np.searchsorted(times, times[start] + margin, side="left"))
            stop = int(np.searchsorted(times, times[stop - 1] - margin, side="right"))
        if stop - start >= minimum:
            segments.append((start, stop))
    return segments


def _quiet_runs(channels: np.ndarray, sigma: np.ndarray, window: int, quiet_factor: float) -> np.ndarray:
    """Samples where every channel's centred rolling std over `window` samples is at
    most `quiet_factor` times its noise."""
    from scipy.ndimage import uniform_filter1d

    centred = channels - np.median(channels, axis=0)
    mean = uniform_filter1d(centred, window, axis=0, mode="nearest")
    variance = np.maximum(uniform_filter1d(centred**2, window, axis=0, mode="nearest") - mean**2, 0.0)
    return np.all(np.sqrt(variance) <= quiet_factor * sigma, axis=1)


def _predict(levels: np.ndarray, centres: np.ndarray, keep: list[int], index: int) -> np.ndarray:
    """Run `index`'s level as predicted from the kept runs other than it: linear
    between its neighbours; at the ends the higher of the nearest run's level and the
    linear extrapolation from the two nearest (a held load among those two must not
    make a no-load run at the end look loaded); the one other's level when only one
    is left."""
    others = [k for k in keep if k != index]
    if len(others) == 1:
        return levels[others[0]]
    before = [k for k in others if centres[k] < centres[index]]
    after = [k for k in others if centres[k] > centres[index]]
    if before and after:
        low, high = before[-1], after[0]
    elif after:
        low, high = after[0], after[1]
    else:
        low, high = before[-2], before[-1]
    weight = (centres[index] - centres[low]) / (centres[high] - centres[low])
    linear = levels[low] + weight * (levels[high] - levels[low])
    if before and after:
        return linear
    return np.maximum(linear, levels[after[0] if after else before[-1]])


def _signal_segments(log: BarometerLog, min_duration: float, margin: float, quiet_factor: float, level_factor: float) -> list[tuple[int, int]]:
    """No-load segments from the barometers alone.

    Quiet runs: every channel's rolling std (window a fifth of `min_duration`, at least
    5 samples) within `quiet_factor` times its noise, for at least `min_duration`. A
    quiet run may be a held load; one is, when some channel's mean over it sits more than
    `level_factor` noise stds above the level its neighbouring runs predict (linear in
    time). Such runs are dropped, the worst first, until every run left lies on the low,
    slowly drifting baseline those runs trace.
    """
    times = np.asarray(log.times, dtype=np.float64)
    channels = np.asarray(log.channels, dtype=np.float64)
    if len(times) < 3:
        return []
    sigma = estimate_noise(channels)
    window = max(5, _min_samples(times, min_duration) // 5)
    runs = _segments_from_mask(_quiet_runs(channels, sigma, window, quiet_factor), times, min_duration, 0.0)
    if not runs:
        return []
    levels = np.array([channels[start:stop].mean(axis=0) for start, stop in runs])
    centres = np.array([times[start:stop].mean() for start, stop in runs])
    keep = list(range(len(runs)))
    while len(keep) > 1:
        excess = {index: float(np.max((levels[index] - _predict(levels, centres, keep, index)) / (level_factor * sigma))) for index in keep}
        worst = max(excess, key=excess.get)
        if excess[worst] <= 1.0:
            break
        keep.remove(worst)
    return _segments_from_mask(_mask_of([runs[k] for k in keep], len(times)), times, min_duration, margin)


def _mask_of(segments, num_samples: int) -> np.ndarray:
    mask = np.zeros(num_samples, dtype=bool)
    for start, stop in segments:
        mask[start:stop] = True
    return mask


def _detect(log: BarometerLog, method: str, min_duration: float, margin: float, force_threshold: float, quiet_factor: float, level_factor: float, source: str):
    """(segments, method used)."""
    if method not in METHODS:
        raise HydrotactError(f"{source}: unknown tare method {method!r}; one of {', '.join(METHODS)}")
    columns = log.columns
    forces = [name for name in ("fx", "fy", "fz") if name in columns] or [name for name in ("fn",) if name in columns]
    available = {"contact": "contact" in columns, "indentation": "indentation" in columns, "force": bool(forces), "signal": True}
    if method == "auto":
        method = next(name for name in ("contact", "indentation", "force", "signal") if available[name])
    elif not available[method]:
        raise HydrotactError(f"{source}: tare method {method!r} needs the log's {method} column{'s' if method == 'force' else ''}, which it lacks")
    times = np.asarray(log.times, dtype=np.float64)
    if method == "signal":
        return _signal_segments(log, min_duration, margin, quiet_factor, level_factor), method
    if method == "contact":
        mask = np.asarray(columns["contact"]) == 0
    elif method == "indentation":
        mask = np.asarray(columns["indentation"], dtype=np.float64) <= 0.0
    else:
        magnitude = np.sqrt(sum(np.asarray(columns[name], dtype=np.float64) ** 2 for name in forces))
        mask = magnitude <= force_threshold
    return _segments_from_mask(mask, times, min_duration, margin), method


def find_no_load_segments(
    log: BarometerLog,
    *,
    method: str = "auto",
    min_duration: float = 0.5,
    margin: float = 0.0,
    force_threshold: float = FORCE_THRESHOLD_N,
    quiet_factor: float = QUIET_FACTOR,
    level_factor: float = LEVEL_FACTOR,
    source: str = "log",
) -> list[tuple[int, int]]:
    """The stretches of `log` where nothing loads the sensor, as row ranges.

    With `method` "auto" the first the log allows of: its `contact` flag (0), its
    `indentation` (<= 0), its force columns (|(fx, fy, fz)| or |fn| <= `force_threshold`
    N), else the `signal`: quiet stretches (every channel's rolling std within
    `quiet_factor` times its noise, estimated by :func:`estimate_noise`) lying
    on the channels' low baseline (no channel's mean more than `level_factor` noise stds
    above what the neighbouring quiet stretches predict, linearly in time, so a drifting
    baseline is followed and a held load is not taken for one).

    **Arguments:**

    - `log`: the :class:`BarometerLog`.
    - `method`: "auto", "contact", "indentation", "force" or "signal".
    - `min_duration`: the shortest segment kept, s.
    - `margin`: seconds trimmed off both ends of every segment (the elastomer relaxes
      after a release).
    - `force_threshold`, `quiet_factor`, `level_factor`: as above.
    - `source`: the log's file name, for messages.

    **Returns:** [(start, stop), ...] row ranges (0-based, stop exclusive: Python slices)
    in time order; empty when none is found.
    """
    return _detect(log, method, min_duration, margin, force_threshold, quiet_factor, level_factor, source)[0]


def _given_segments(log: BarometerLog, segments, segment_times, source: str) -> tuple[list[tuple[int, int]], str]:
    times = np.asarray(log.times, dtype=np.float64)
    result = []
    if segments is not None:
        for index, segment in enumerate(segments):
            start, stop = (int(value) for value in segment)
            if not 0 <= start < stop <= len(times):
                raise HydrotactError(f"{source}: segments[{index}]: rows ({start}, {stop}) are not a range within the log's {len(times)} rows")
            result.append((start, stop))
        return sorted(result), "rows"
    for index, (start_time, stop_time) in enumerate(segment_times):
        start = int(np.searchsorted(times, float(start_time), side="left"))
        stop = int(np.searchsorted(times, float(stop_time), side="right"))
        if not float(start_time) < float(stop_time) or stop <= start:
            raise HydrotactError(
                f"{source}: segment_times[{index}]: ({float(start_time):g} s, {float(stop_time):g} s) holds no sample (the log runs {times[0]:g} s to {times[-1]:g} s)"
            )
        result.append((start, stop))
    return sorted(result), "times"


def interpolate_baseline(times: np.ndarray, centres: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """The baseline at `times` through the segment levels: piecewise linear between
    segment centres, continued along the first and the last piece beyond the ends
    (constant for a single segment).

    **Arguments:** `times`: (num_samples,) s; `centres`: (num_segments,) increasing
    mean times of the segments, s; `levels`: (num_segments, num_channels), Pa.

    **Returns:** (num_samples, num_channels), Pa.
    """
    if len(centres) == 1:
        return np.broadcast_to(levels[0], (len(times), levels.shape[1])).copy()
    baseline = np.column_stack([np.interp(times, centres, levels[:, k]) for k in range(levels.shape[1])])
    for before, (low, high) in ((times < centres[0], (0, 1)), (times > centres[-1], (-2, -1))):
        slope = (levels[high] - levels[low]) / (centres[high] - centres[low])
        baseline[before] = levels[low] + (times[before, None] - centres[low]) * slope
    return baseline


def tare_log(
    log: BarometerLog,
    segments=None,
    *,
    segment_times=None,
    method: str = "auto",
    min_duration: float = 0.5,
    margin: float = 0.0,
    source: str = "log",
) -> tuple[BarometerLog, np.ndarray]:
    """Subtract each channel's no-load baseline; the log's pressure becomes `tared`.

    Over each no-load segment the baseline is the channel's mean; at every sample it is
    interpolated linearly in time between the segments' mean times and continued along
    the first and the last piece beyond them (:func:`interpolate_baseline`). One segment
    gives a constant baseline; several follow the drift of an aged sensor. The tare is recorded in the metadata (`tare`: method,
    segments in s, baselines per segment in Pa).

    **Arguments:**

    - `log`: an `absolute` (or already `tared`) :class:`BarometerLog`.
    - `segments`: no-load row ranges [(start, stop), ...] (0-based, stop exclusive), or
      None to find them (:func:`find_no_load_segments` with `method`, `min_duration`,
      `margin`).
    - `segment_times`: instead, no-load time ranges [(t0, t1), ...], s (inclusive).
    - `source`: the log's file name, for messages.

    **Returns:** (the tared log, (num_channels,) baselines: each channel's mean over all
    no-load samples, Pa).
    """
    if log.metadata["pressure"] == "elastic":
        raise HydrotactError(f"{source}: pressure: an 'elastic' (simulated) log has no barometer baseline to tare")
    if segments is not None and segment_times is not None:
        raise HydrotactError(f"{source}: give the no-load segments as rows or as times, not both")
    if segments is None and segment_times is None:
        found, used = _detect(log, method, min_duration, margin, FORCE_THRESHOLD_N, QUIET_FACTOR, LEVEL_FACTOR, source)
    else:
        found, used = _given_segments(log, segments, segment_times, source)
    if not found:
        raise HydrotactError(
            f"{source}: no no-load segment found (method {used!r}, at least {min_duration:g} s); give the no-load times (segment_times) or a shorter min_duration"
        )
    times = np.asarray(log.times, dtype=np.float64)
    channels = np.asarray(log.channels, dtype=np.float64)
    levels = np.array([channels[start:stop].mean(axis=0) for start, stop in found])
    centres = np.array([times[start:stop].mean() for start, stop in found])
    baseline = interpolate_baseline(times, centres, levels)
    columns = dict(log.columns)
    for k, name in enumerate(log.metadata["channels"]):
        columns[name] = channels[:, k] - baseline[:, k]
    metadata = dict(log.metadata)
    metadata["pressure"] = "tared"
    metadata["tare"] = {
        "method": used,
        "segments_s": [[float(times[start]), float(times[stop - 1])] for start, stop in found],
        "baselines_Pa": levels.tolist(),
    }
    no_load = _mask_of(found, len(times))
    return BarometerLog(metadata=metadata, columns=columns, source_columns=log.source_columns), channels[no_load].mean(axis=0)
