"""Fitting logs end to end: barometer logs -> a fitted material, a report and
(given a plotter) pictures.

Everything the user gave is read and checked before anything is written; the outputs
(material.json, report.json, PNGs) are each written atomically into the output folder.
Unit responses of full-mode fits are cached (they are the expensive part), so a second
fit of the same logs with other options starts at once.
"""

import dataclasses
import math
import warnings
from pathlib import Path

import jax
import numpy as np

from .._errors import HydrotactError, warn
from .._files import check_output
from ..data import LogWarning, read_log, read_rig, sensor_spec, tare_log
from ._drift import parse_drift
from ._fit import CHI_SQUARE_WARNING, MAX_AUTO_TERMS, fit_auto, fit_problem
from ._problem import OUTLIER_GAIN, check_pose_columns, find_clipped_readings, log_probe, make_fit_problem
from ._report import write_fit_outputs
from ._solve import make_solver, solver_name


def parse_terms(text) -> int | str:
    """'auto' or a non-negative integer."""
    if str(text) == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        raise HydrotactError(f"--terms: expected a number of Prony terms or 'auto', got {text!r}") from None
    if value < 0 or value > 8:
        raise HydrotactError(f"--terms: expected 0 to 8 Prony terms, got {value}")
    return value


def _content_digest(log) -> str:
    """A SHA-256 of a log's samples (time and channels): the same log under two names
    (or in two formats) has one."""
    import hashlib

    h = hashlib.sha256()
    for values in (log.times, log.channels):
        h.update(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return h.hexdigest()


def _check_responds(log, source: str) -> None:
    """Refuse a log in which no channel moves (nothing to fit: a dead sensor, a log
    before any press, or a column mapping onto the wrong columns)."""
    channels = log.channels
    if channels.shape[0] and np.all(np.ptp(channels, axis=0) == 0.0):
        names = log.metadata["channels"]
        raise HydrotactError(
            f"{source}: no channel varies ({len(names)} channels, each constant; {names[0]} = {channels[0, 0]:g} Pa): nothing to fit; "
            "is it the right log, or the mapping's right columns?"
        )


def read_logs(paths, mapping=None, sensor=None, require_sensor: bool = True):
    """Read and check every log first (one error line, nothing written). Warnings
    that repeat across the logs (uneven sampling, say) are issued once, with the
    number of logs and the first one named."""
    if not paths:
        raise HydrotactError("no logs given")
    logs, seen, digests = [], {}, {}
    for path in paths:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LogWarning)
            log = read_log(path, mapping, sensor=sensor, require_sensor=require_sensor)
        key = _content_digest(log)
        if key in digests:
            raise HydrotactError(
                f"{path}: holds the same samples as {digests[key]}: a log given twice counts its noise twice (standard errors shrink by √2); give each log once"
            )
        digests[key] = path
        _check_responds(log, str(path))
        logs.append(log)
        for warning in caught:
            if issubclass(warning.category, LogWarning):
                message = str(warning.message)
                kind = message.removeprefix(f"{path}: ").split(":")[0].split("(")[0].strip()
                seen.setdefault(kind, {}).setdefault(str(path), message)
            else:
                warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    for by_log in seen.values():
        messages = list(by_log.values())
        others = f" (and {len(messages) - 1} more logs alike)" if len(messages) > 1 else ""
        warn(messages[0] + others, LogWarning)
    return logs


@dataclasses.dataclass(frozen=True)
class SimulatorFit:
    """The simulator fit as :func:`fit_logs`'s `method` (settings only; the default,
    the command line's `fit` without --lumped): the logs' `sensor` (a built-in name
    or a spec file) where their metadata names none, the strain `field` and the
    taxels' `num_rays` (default: the logs' own), and whether to show `progress`.
    For stage logs, which have no probe pose, a `rig` (a :class:`hydrotact.data.Rig`
    or its file) places the probe from the stage's columns and fits its offsets,
    home and lag; `drift` is each channel's baseline per log ("none": a constant
    offset, "linear", or a spline knot spacing in s); readings at or above
    `saturation_pa` are masked as clipped (besides the part's range limits);
    `gains` each responding channel's gain: "fixed" (1), "free" (needs force
    columns), "relative" (geometric mean 1), or None (free with force columns,
    relative for stage logs, else fixed: :func:`make_fit_problem`)."""

    sensor: str | None = None
    field: str | None = None
    num_rays: int | None = None
    progress: bool = True
    rig: object = None
    drift: object = "none"
    saturation_pa: float | None = None
    gains: str | None = None


def fit_logs(paths, output, *, method=None, terms="auto", solver=None, tare=False, mapping=None, plot=None, max_steps=None) -> dict:
    """Fit the logs at `paths` with `method` and write material.json, report.json
    (and, with `plot`, the pictures) into `output`. `method` is a
    :class:`SimulatorFit` (the default: the sensor simulated, its material's Prony
    terms, gains and offsets fitted) or a :class:`hydrotact.sysid.lumped.LumpedFit`
    (the lumped press model of :func:`fit_press_logs`, for stage logs; `plot` then
    draws a PressFit), each holding its own settings. With `tare`, each log is first
    tared on its no-load segments (found automatically; the baseline interpolated in
    time between them), which takes out the slow drift of aged sensors that constant
    offsets cannot (simulator fits only). `plot(result, output) -> {name: path}`
    draws the pictures (the command line passes `hydrotact.viz.plot_fit`; the stage
    draws nothing itself). `solver` is a solver object (default:
    Levenberg–Marquardt) or the name of one of SOLVERS; `mapping` a column mapping
    for logs in other formats; `max_steps` caps the solver's steps. What may mislead
    (clipped readings, a poor χ², parameters the logs cannot identify) is issued as
    a :class:`HydrotactWarning`. Returns the report (with `files`)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from .lumped import LumpedFit

    method = SimulatorFit() if method is None else method
    if not isinstance(method, (SimulatorFit, LumpedFit)):
        raise HydrotactError(f"method: expected SimulatorFit(...) or LumpedFit(...), got {method!r}")
    output = check_output(output, directory=True, what="the fit")
    given = solver
    if solver is None or isinstance(solver, str):
        solver = make_solver(solver or "lm")
    name = solver_name(solver)
    terms = parse_terms(terms)
    if isinstance(method, LumpedFit):  # the solver as given: a named one steps with the press model's settings
        return _fit_press_files(paths, output, method, mapping, terms, given, tare, plot, max_steps)
    with jax.enable_x64(True):  # absolute readings (~1e5 Pa) to a Pa, and normal equations: float64 whatever the caller's precision
        sensor, field, num_rays, progress = method.sensor, method.field, method.num_rays, method.progress
        rig = read_rig(method.rig) if isinstance(method.rig, (str, Path)) else method.rig
        drift = parse_drift(method.drift)
        logs = read_logs([Path(p) for p in paths], mapping, sensor)
        for log, path in zip(logs, paths):  # every log checked before the first is simulated
            if rig is None:
                check_pose_columns(log, str(path))
            else:
                rig.stage_columns(log, str(path))
            if sensor_spec(log.metadata["sensor"], str(path)) is None:
                raise HydrotactError(
                    f"{path}: sensor: {log.metadata['sensor']!r} is neither a built-in sensor nor a sensor JSON file here: a full fit simulates the sensor "
                    "(name an existing spec in the log's metadata, relative to this folder), or fit --lumped"
                )
            if rig is None:
                log_probe(log, str(path))
        sensors = list(dict.fromkeys(log.metadata["sensor"] for log in logs))
        if len(sensors) > 1:  # each sensor keeps its own gains; the material is one
            warn(
                f"the logs come from {len(sensors)} sensors ({', '.join(sensors)}): one material is fitted to all of them, right only if they are cast "
                "from the same elastomer (fit each sensor on its own otherwise)"
            )
        if tare:
            logs = [tare_log(log, source=str(path))[0] for log, path in zip(logs, paths)]
        for log, path in zip(logs, paths):
            clipped = find_clipped_readings(log, log.channels, method.saturation_pa).sum(axis=0)
            if clipped.any():
                names = [name for name, n in zip(log.metadata["channels"], clipped) if n]
                warn(
                    f"{path}: {int(clipped.sum())} readings on {len(names)} channels ({', '.join(names[:4])}{', ...' if len(names) > 4 else ''}) sit at the "
                    "part's range limits (the barometer clipped them): masked, not fitted"
                )
        problem = make_fit_problem(
            logs, field=field, num_rays=num_rays, sources=[str(p) for p in paths], progress=progress, rig=rig, drift=drift,
            saturation_pa=method.saturation_pa, gains=method.gains,
        )
        counts = list(range(MAX_AUTO_TERMS + 1)) if terms == "auto" else [terms]
        with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total} fits"), TimeElapsedColumn(), transient=True, disable=not progress) as bar:
            task = bar.add_task(f"fitting ({name})", total=len(counts))
            if terms == "auto":
                result = fit_auto(problem, solver, progress=lambda k: bar.update(task, advance=1, description=f"fitting ({name}): {k} terms done"), max_steps=max_steps)
            else:
                result = fit_problem(problem, terms, solver, max_steps=max_steps)
                bar.update(task, advance=1)
        messages = []
        if not result.converged:
            messages.append(f"the {name} solver stopped before converging ({result.num_steps} steps; raise --max-steps); the numbers below are its last iterate")
        if result.reduced_chi_square > CHI_SQUARE_WARNING:
            messages.append(
                f"reduced χ² {result.reduced_chi_square:.3g}: the model misses the data by {math.sqrt(result.reduced_chi_square):.2g} noise stds RMS; "
                "are the sensor, the channel names and the units right? (see residuals.png)"
            )
        outside = result.gains_outside_the_mean()
        if outside:
            messages.append(
                f"{', '.join(name.split('/')[-1] for name in outside)}: the readings move over {OUTLIER_GAIN:g} × more or less than the model's response "
                "of the channel, against the other channels: a barometer dead, misplaced or beyond the model; its gain is fitted on its own, outside "
                "the gains' mean (which sets E's scale)"
            )
        unidentified = result.unidentified()
        if unidentified:
            messages.append(f"not identified by these logs: {', '.join(unidentified)} (marked in the table and report.json; fewer --terms, or longer logs)")
        for message in messages:
            warn(message)
        report = write_fit_outputs(result, output, paths=[str(p) for p in paths], plot=plot)
        return report


def _fit_press_files(paths, output, method, mapping, terms, solver, tare, plot, max_steps) -> dict:
    from .lumped import MAX_TERMS, fit_press_logs, write_press_fit_outputs

    sensor, options = method.sensor, dict(method.press_options(), **({"max_steps": max_steps} if max_steps is not None else {}))

    if tare:
        raise HydrotactError("--tare: a lumped fit fits each channel's drifting baseline itself (--drift); leave --tare out")
    if terms != "auto" and terms > MAX_TERMS:
        raise HydrotactError(f"--terms: a lumped fit takes 0 to {MAX_TERMS} Prony terms or auto, got {terms}")
    logs = read_logs([Path(p) for p in paths], mapping, sensor, require_sensor=False)
    sensors = {log.metadata.get("sensor") for log in logs}
    if len(sensors) > 1:
        first = logs[0].metadata.get("sensor")
        other = next(k for k, log in enumerate(logs) if log.metadata.get("sensor") != first)
        raise HydrotactError(
            f"{paths[other]}: from sensor {logs[other].metadata.get('sensor')!r}, but {paths[0]} is from {first!r}: a lumped fit is one sensor's "
            "channel law (fit each sensor on its own)"
        )
    fit = fit_press_logs(logs, [str(p) for p in paths], terms=terms, solver=solver, **options)
    return write_press_fit_outputs(fit, output, paths=[str(p) for p in paths], plot=plot)
