"""Predicting held-out stage logs from a full-mode fit through a rig (`hydrotact
compare` of a `hydrotact fit --rig` folder).

Everything comes from the fit: the material (material.json), each channel's gain,
the rig's offsets and lag (report.json's `rig`, its `rig_setup`), and the sensor's
response table the fit read (`rig_table.npz`: a held-out log is read off the same
table, so its tips must lie where the table does). Two things come from the log:

- its *tare*, each channel's baseline, as for a lumped fit ("no-load": the drift
  basis fitted to the samples the model says are unloaded; "first:S"; "all");
- its *home*, the tip's height at travel 0, which moves between sessions: with
  home="estimate" (the default) fitted to the log within the rig's bounds (a bounded
  scalar search of the χ² with the tare solved at each home); with home="fit" the
  fit's own for a log it used (the same SHA-256), else the mean of its homes.

No prediction band yet (the fit's covariance is not propagated): compare.json says so.
"""

import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import HydrotactError
from ..data import estimate_noise, material_prony, read_material
from ..sim import CONTACT_THRESHOLD_N, RigTable
from ..visco import calc_contact_response
from ._comparison import HOLD_TOLERANCE, HOMES, parse_tare, summarise_comparison, tare_baseline
from ._drift import drift_basis
from ._problem import file_digest, find_clipped_readings
from ._rig_problem import calc_stage_inputs

UNNAMED = "unnamed"  # the sensor of a mapped log that names none (hydrotact.data.apply_mapping)


def is_rig_fit(fit_dir) -> bool:
    """Whether `fit_dir` holds a full-mode fit through a rig."""
    fit_dir = Path(fit_dir)
    return fit_dir.is_dir() and (fit_dir / "rig_table.npz").is_file()


def read_rig_fit(fit_dir):
    """(the Prony series, report dict, RigTable) of a rig fit's folder; one error
    line naming the file that is missing or does not match."""
    fit_dir = Path(fit_dir)
    material = read_material(fit_dir / "material.json")
    report_path = fit_dir / "report.json"
    if not report_path.is_file():
        raise HydrotactError(f"{fit_dir}: no report.json beside rig_table.npz: compare needs the fit's rig (rerun the fit)")
    report = json.loads(report_path.read_text(encoding="utf-8"))
    if "rig" not in report or "rig_setup" not in report:
        raise HydrotactError(f"{report_path}: no rig or rig_setup: not the report of `hydrotact fit --rig` (rerun the fit)")
    try:
        with np.load(fit_dir / "rig_table.npz") as data:
            table = RigTable(origin=jnp.asarray(data["origin"]), step=jnp.asarray(data["step"]), values=jnp.asarray(data["values"]))
    except (OSError, KeyError, ValueError) as error:
        raise HydrotactError(f"{fit_dir / 'rig_table.npz'}: cannot read the rig's response table ({error}); rerun the fit") from None
    return material_prony(material), report, table


@eqx.filter_jit
def _elastic(prony, table, times, xy, travel, lag, home, gains):
    """(T, C) each channel's predicted elastomer reading (Pa, no baseline)."""
    inputs = calc_stage_inputs(table, times, xy, travel, home, lag, jnp.arange(gains.shape[0]))
    return gains[None, :] * calc_contact_response(prony, times, inputs)


def _place_log(prony, report, table, log, source, tare, home) -> dict:
    """A held-out log placed on the rig fit: its channels, times, tips (xy with the
    offsets), travel, lag, home (estimated, the fit's or the mean of its homes; (T,),
    the height at travel 0 under each sample, where the fit has a slope along the
    stage's x: the log's own, or the mean of the fit's), and
    the prediction there (elastic, baseline), with the observed readings, the mask
    of unclipped samples and the noise. Call inside `jax.enable_x64(True)`."""
    from scipy.optimize import minimize_scalar

    setup, rig = report["rig_setup"], report["rig"]
    columns = dict(setup["columns"])
    sensor = {entry.get("sensor") for entry in report.get("logs", [])} - {None}
    sensor_name = log.metadata.get("sensor")
    if sensor_name in (None, "", UNNAMED) and len(sensor) == 1:  # a log that names no sensor is of the fitted one
        sensor_name = next(iter(sensor))
    if sensor and sensor_name not in sensor:
        raise HydrotactError(f"{source}: sensor {sensor_name!r}, but the fit is of {', '.join(sorted(sensor))}: compare logs of the fitted sensor")
    channels = tuple(log.metadata["channels"])
    if table.values.shape[-1] != len(channels) + 3:
        raise HydrotactError(f"{source}: {len(channels)} channels, but the fit's table has {table.values.shape[-1] - 3}")
    for role in ("travel", "x"):
        if columns[role] not in log.columns:
            raise HydrotactError(f"{source}: no column {columns[role]!r} (the rig's stage {role}); the log has {', '.join(log.columns)}")
    times = np.asarray(log.times, dtype=np.float64)
    travel = np.asarray(log.columns[columns["travel"]], dtype=np.float64)
    y = np.asarray(log.columns[columns["y"]], dtype=np.float64) if columns["y"] in log.columns else np.zeros_like(times)
    stage_x = np.asarray(log.columns[columns["x"]], dtype=np.float64)
    xy = np.column_stack([stage_x + rig["offset_x"]["value"], y + rig["offset_y"]["value"]])
    origin, step, shape = np.asarray(table.origin), np.asarray(table.step), table.values.shape
    for axis, label in ((0, "x"), (1, "y")):
        low, high = origin[axis], origin[axis] + step[axis] * (shape[axis] - 1)
        outside = (xy[:, axis] < low - 1e-9) | (xy[:, axis] > high + 1e-9)
        if outside.any():
            row = int(np.flatnonzero(outside)[0])
            raise HydrotactError(
                f"{source}: row {row + 1}: the tip at {label} = {xy[row, axis] * 1e3:.3f} mm lies outside the fit's response table "
                f"({low * 1e3:.3f} to {high * 1e3:.3f} mm): fit with logs (or rig bounds) that cover it"
            )
    gains = np.array([report.get("gains", {}).get(f"{sensor_name}/{channel}", {}).get("value", 1.0) for channel in channels])
    observed = np.column_stack([np.asarray(log.columns[channel], dtype=np.float64) for channel in channels])
    mask = ~find_clipped_readings(log, observed, setup.get("saturation_pa"))
    noise = np.array([estimate_noise(observed[mask[:, c], c : c + 1])[0] for c in range(len(channels))])
    basis = drift_basis(times, setup["drift"])
    homes = [rig[key]["value"] for key in rig if key.startswith("home[")]
    low, high = setup["bounds"]["home"]
    digest = file_digest(source)
    own = [k for k, entry in enumerate(report.get("logs", [])) if digest is not None and entry.get("sha256") == digest]
    lag = float(rig["lag_s"]["value"])
    slopes = [rig[key]["value"] for key in rig if key.startswith("slope_x[")]
    slope = (slopes[own[0]] if own else float(np.mean(slopes))) if slopes else 0.0
    rise = slope * stage_x  # (T,) the height at travel 0 above the home (a sloped stage)
    arguments = (prony, table, jnp.asarray(times), jnp.asarray(xy), jnp.asarray(travel), jnp.asarray(lag))

    def predict(height):
        elastic = np.asarray(_elastic(*arguments, jnp.asarray(height + rise), jnp.asarray(gains)))
        baseline, used, _ = tare_baseline(tare, times, observed, elastic, mask, basis, source, channels, _solve_baseline)
        return elastic, baseline

    def cost(height):
        elastic, baseline = predict(height)
        return float(np.sum(np.where(mask, (observed - baseline - elastic) / noise, 0.0) ** 2))

    estimated = None
    if own:
        height = homes[own[0]]
    elif home == "estimate" and high > low:
        # a coarse scan first (the χ² in the home is not convex: a press may move into another cell of the table), then the bounded search around its best
        grid = np.linspace(low, high, 41)
        best = grid[int(np.argmin([cost(h) for h in grid]))]
        width = grid[1] - grid[0]
        found = minimize_scalar(cost, bounds=(max(low, best - width), min(high, best + width)), method="bounded", options={"xatol": 1e-7})
        height = float(found.x)
        step = 1e-6  # the home's standard error from the χ²'s curvature (Δχ² = 1)
        curvature = (cost(height + step) - 2.0 * cost(height) + cost(height - step)) / step**2
        estimated = (height - float(np.mean(homes)), float(np.sqrt(2.0 / curvature)) if curvature > 0.0 else float(width))
    else:
        height = float(np.mean(homes))
    deepest = float(np.min(height + rise - travel))
    if deepest < origin[2] - 1e-9:
        raise HydrotactError(
            f"{source}: its deepest press puts the tip at {deepest * 1e3:.3f} mm, below the fit's response table ({origin[2] * 1e3:.3f} mm): "
            "a press deeper than any the fit's logs and bounds allow; fit with logs as deep"
        )
    elastic, baseline = predict(height)
    return {"sensor": sensor_name, "channels": channels, "times": times, "xy": xy, "travel": travel, "lag": lag, "home": height + rise, "home_shift": estimated,
            "observed": observed, "mask": mask, "noise": noise, "elastic": elastic, "baseline": baseline}


def _placed(prony, report, table, log, source, tare, home) -> dict:
    with jax.enable_x64(True):  # absolute readings of ~1e5 Pa to a pascal, whatever the caller's precision
        prony, table = jax.tree_util.tree_map(lambda a: jnp.asarray(a, jnp.float64), (prony, table))
        return _place_log(prony, report, table, log, source, tare, home) | {"prony": prony, "table": table}


def _compared(placed, source):
    channels, observed, mask, elastic = placed["channels"], placed["observed"], placed["mask"], placed["elastic"]
    predicted = placed["baseline"] + elastic
    for c, name in enumerate(channels):
        bad = mask[:, c] & ~np.isfinite(predicted[:, c])
        if bad.any():
            raise HydrotactError(f"{source}: channel {name!r}: the prediction is not finite at {int(bad.sum())} of its samples: nothing compared")
    hold = _holds(placed["travel"], np.any(elastic != 0.0, axis=1))
    return summarise_comparison(source, channels, placed["times"], observed, predicted, mask, hold, placed["noise"], np.full(observed.shape, np.nan), home_shift=placed["home_shift"])


def _labelled(placed, log, source, contact_force, prony=None):
    from ..data import BarometerLog

    times, xy, travel = placed["times"], placed["xy"], placed["travel"]
    count = len(placed["channels"])
    with jax.enable_x64(True):
        unit = calc_stage_inputs(placed["table"], jnp.asarray(times), jnp.asarray(xy), jnp.asarray(travel), jnp.asarray(placed["home"]), jnp.asarray(placed["lag"]), jnp.arange(count, count + 3))
        prony = placed["prony"] if prony is None else jax.tree_util.tree_map(lambda a: jnp.asarray(a, jnp.float64), prony)
        force = np.asarray(calc_contact_response(prony, jnp.asarray(times), unit))
    contact = np.linalg.norm(force, axis=1) > contact_force
    tips = placed["home"] - np.interp(times - placed["lag"], times, travel)
    depth = _skin_heights(placed["sensor"], xy, source) - tips
    nothing = np.full(len(times), np.nan)
    labels = {"contact": contact.astype(np.float64), "contact_x": np.where(contact, xy[:, 0], nothing),
              "contact_y": np.where(contact, xy[:, 1], nothing), "depth": np.where(contact, depth, nothing)}
    return BarometerLog(log.metadata, dict(log.columns) | labels, log.source_columns)


def compare_rig_log(prony, report, table, log, source, *, tare="no-load", home="estimate"):
    """One held-out log against the rig fit's prediction (a Comparison)."""
    return _compared(_placed(prony, report, table, log, source, tare, home), source)


def label_rig_log(fit_dir, log, source: str = "log", *, tare="no-load", home="estimate", contact_force: float = CONTACT_THRESHOLD_N, material=None):
    """A stage log with the labels an estimator of a stage rig learns, from the rig
    fit in `fit_dir`: the log again (a BarometerLog) with `contact` (the fitted
    model's force on the sensor over `contact_force` N: by default a dataset's
    label's 0.1 N), `contact_x`, `contact_y` (the tip's position in the sensor frame:
    the stage's plus the fitted offsets) and `depth` (the tip past the skin below it:
    the skin's height there, cast down on the sensor's mesh, less the tip's height,
    the home (placed as :func:`compare_rig_log` places it, with `tare` and `home`)
    less the travel `lag` s before), each NaN without contact. `material` (a
    material document's path) computes the force from another fit's material (one
    state's material fitted well, another's poorly, the rubber the same)."""
    prony, report, table = read_rig_fit(fit_dir)
    other = None if material is None else material_prony(read_material(material))
    return _labelled(_placed(prony, report, table, log, source, parse_tare(tare), home), log, source, contact_force, other)


def _skin_heights(sensor, xy, source) -> np.ndarray:
    """(T,) the skin's height (m) straight below each tip position `xy` (T, 2): the
    first surface of the fitted `sensor`'s mesh (as :func:`_place_log` resolved it) a
    ray cast down meets (NaN where none)."""
    from ..sensors import load_sensor
    from ..taxel import calc_first_hits

    try:
        mesh = load_sensor(sensor).make_mesh(check=False)
    except (HydrotactError, OSError) as error:
        raise HydrotactError(f"{source}: the fit's sensor {sensor!r} cannot be read to find its skin ({error})") from None
    vertices = np.asarray(mesh.vertices)
    above = float(vertices[:, 2].max()) + 1e-3
    sites, index = np.unique(np.round(xy, 9), axis=0, return_inverse=True)
    origins = np.column_stack([sites, np.full(len(sites), above)])
    reach = calc_first_hits(origins, np.tile([0.0, 0.0, -1.0], (len(sites), 1)), vertices, np.asarray(mesh.boundary_faces), 0.0)
    return np.where(np.isfinite(reach), above - reach, np.nan)[np.ravel(index)]


def _solve_baseline(basis, observed, elastic, used):
    """(D, C) each channel's baseline coefficients by least squares on its `used` samples."""
    coefficients = []
    for c in range(observed.shape[1]):
        rows = used[:, c]
        if rows.sum() < basis.shape[1]:
            rows = np.ones(len(basis), dtype=bool) if rows.sum() == 0 else rows
        coefficients.append(np.linalg.lstsq(basis[rows], (observed - elastic)[rows, c], rcond=None)[0])
    return np.column_stack(coefficients)


def _holds(travel, loaded):
    """(T,) the press each sample holds at (its deepest travel within a run of
    loaded samples), -1 elsewhere."""
    hold = np.full(len(travel), -1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], loaded.astype(int), [0]])))
    for p, (start, end) in enumerate(zip(edges[::2], edges[1::2])):
        deepest = travel[start:end].max()
        hold[start:end][travel[start:end] >= deepest - HOLD_TOLERANCE] = p
    return hold


def compare_fit(fit_dir, paths, output, *, mapping=None, tare="no-load", home="estimate", plot=None, labels: bool = False) -> dict:
    """Compare held-out logs with a fit's prediction and write, into `output`,
    `compare.json`, `NAME_predicted.parquet` per log and (with `plot`) the pictures:
    a lumped fit's (:func:`hydrotact.sysid.lumped.compare_fit`: the band, the
    onsets' home shift) or a full-mode fit's through a rig (:func:`compare_rig_log`:
    the home estimated per log, no band yet). With `labels` (a rig fit only), also
    `NAME_labelled.parquet` per log, the log with an estimator's labels
    (:func:`label_rig_log`). Everything is read and checked before anything is
    written. Returns the report (with `files`)."""
    from .._files import check_output
    from ._comparison import write_comparisons
    from ._fit_logs import read_logs
    from .lumped import compare_fit as compare_lumped_fit

    if not is_rig_fit(fit_dir):
        if labels:
            raise HydrotactError(f"--labels: {fit_dir} is not a fit through a rig (hydrotact fit --rig): without the stage's offsets and home there is no contact position or depth to label")
        return compare_lumped_fit(fit_dir, paths, output, mapping=mapping, tare=tare, home=home, plot=plot)
    output = check_output(output, directory=True, what="the comparison")
    tare = parse_tare(tare)
    if home not in HOMES:
        raise HydrotactError(f"--home: expected one of {', '.join(HOMES)}, got {home!r}")
    prony, report, table = read_rig_fit(fit_dir)
    logs = read_logs([Path(p) for p in paths], mapping, None, require_sensor=False)
    placed = [_placed(prony, report, table, log, str(path), tare, home) for log, path in zip(logs, paths)]
    comparisons = [_compared(entry, str(path)) for entry, path in zip(placed, paths)]
    labelled = [_labelled(entry, log, str(path), CONTACT_THRESHOLD_N) for entry, log, path in zip(placed, logs, paths)] if labels else []
    header = {"fit": str(fit_dir), "tare": tare if isinstance(tare, str) else f"first:{tare[1]:g}", "home": home, "prediction_band": None}
    files = {}
    if labelled:
        from ..data import write_log

        output.mkdir(parents=True, exist_ok=True)
        for log, path in zip(labelled, paths):
            files[f"{Path(path).stem}_labelled"] = str(write_log(output / f"{Path(path).stem}_labelled.parquet", log))
    return write_comparisons(comparisons, paths, output, header, plot, files)
