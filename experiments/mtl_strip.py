"""The MTL strip end to end, from its public design files (issue 47). First stage: the
sensor from its mould and board, and each barometer's spatial profile, measured and
simulated.

The data are a public strip sensor's (the MSc project `JiannnH/MTL-BaroTactileSensor`):
pass `--data DIR`, a checkout of that repository (`Mold/Mold_v6/mould_b_V6.STL`,
`PCB/BarometerMTL_1D_V1/*.brd`, `Data_collection/tip1/*.csv`) or a folder laid out
like it with `design/` and `logs/`. Only the six calibration logs named in
mtl_calibration.CALIBRATION are read; the repository's other logs of the strip are
kept apart to judge the results and are never opened here. Nothing of the data goes
into this repository: the committed results are the table and the figure.

1. **The sensor** (`mtl_strip_sensor.json`, in the output's work folder): the
   elastomer is the mould's cavity (`hydrotact.mesh.make_mould_cavity`, the pocket
   side on the board: `ymax` in the mould's coordinates), its pockets found on the
   cast (the flat ceilings facing the board), the board's barometer packages (the
   Eagle file's elements P1…P16) matched to them in order along the strip by one
   translation (fitted; the worst package more than 0.2 mm from its pocket is
   refused), and the four logged channels Sensor_0…3 (P1…P4, the data's README) as
   barometers at their pockets' ceiling centres, three ways: reading the air sealed in
   the pocket (`pocket`: an elastic field's `cavity` reading, the pressure that holds
   the pocket's volume), the rubber's stress at the port (`elastic`), and the heuristic
   cone (`cone`, 40°).
2. **The spatial profile**: a 10 mm steel ball (R = 5 mm: the authors' later rig; the
   indenter is not recorded with these logs) pressed `--depth` deep at each x along
   the strip, each channel's reading against x for each receptive field (an elastic
   material of 1 MPa: the shape, not the scale, is compared); and each calibration
   log's presses, each channel's rise over its pre-press level at the press's
   deepest sample against the stage's x, shifted by the stage-to-board offset that
   puts Sensor_2's and Sensor_3's peaks over their barometers (a first estimate, from
   these files; the full-mode fit will fit it with the rest).

3. **The material, full mode** (`--stages fit`): the pocket model's sensor, a rig
   (`hydrotact.data.Rig`: the 10 mm ball, the stage's x offset fitted within ±2 mm of
   the profile's estimate, the home per log within the README's contact onsets
   (1,600-2,000 steps without the vacuum, 2,050-2,450 with it, a little wider than
   its 1,700-1,950 and 2,150-2,350), the lag within 0-0.2 s), each group of three
   logs (with and without the vacuum) fitted whole and, leaving each log out, from
   the other two (`hydrotact fit --rig` through `fit_logs`: 2 Prony terms, 30 s drift
   knots, each barometer's relative gain (their geometric mean 1), readings above
   140.5 kPa masked), and each left-out log predicted
   (`compare`, its tare its first 20 s: the README's fair comparison), each channel's
   RMS against the lumped fit's on the same split (mtl_calibration.json, where it is
   in --output).

4. **Sim-to-real estimation** (`--stages estimate`): an estimator of the contact's x
   along the strip and the indentation depth (`hydrotact train --targets x,depth`),
   scored on real logs it never saw. Each real log is labelled from its group's whole
   fit (`hydrotact.sysid.label_rig_log`, as `compare --labels`: the tip's x is the
   stage's plus the fitted offset, its depth the home less the lagged travel below
   the skin, contact the model's force over 0.1 N, with the non-vacuum fit's material
   for every log: the vacuum group's fit lets its gains take the scale (E∞ 0.14 MPa
   against 1.26), and its force never reached 0.1 N on its own logs). A synthetic dataset of the strip (`--regime stage`: straight-down
   presses of the ball at random x over the logged span, depths 0.2-2.5 mm, the logs'
   speeds, holds of 0-10 s, at the logs' 16.4 Hz; the pocket model with the
   non-vacuum fit's material) pretrains the GRU. Leaving each real log out in turn,
   its x and depth RMSE (over its contact samples) for (a) the model trained on the
   simulation only, (b) the same architecture trained from scratch on 1 and on 3 real
   logs, (c) the pretrained model fine-tuned on the same 1 and 3 logs (the logs of the
   held-out log's state first; each cut between its presses, every fourth press
   validating). Every
   log's channels are tared (each channel less its median over the log's first 20 s,
   plus the simulation's resting level): a session's baselines move by kPa.

5. **One material for both states?** (`--stages joint`): the six logs fitted at once,
   the vacuum and non-vacuum logs sharing the material, the x offset, the lag and the
   barometers' gains (a home per log), against each state's own fit, by χ² and BIC;
   then all three again with the stage free to tilt against the skin per log (the
   rig's `slope_x` within ±0.08: the vacuum as a changed geometry, the skin pulled
   down more at one end).

Outputs (in --output, default experiments/results/): `mtl_strip.json` (the sensor's
alignment, the simulated profiles, the table), `mtl_strip.md` (the table of each
channel's profile: where it peaks and how wide it is at half its peak, measured (each
log's rises as a share of its largest, their median at each x) and by each model), `mtl_strip.png`
(the profiles; the measured rises in kPa). No reading of the logs is written but
these summaries and the figure. The work folder `mtl_strip.work/` keeps the
sensor file, the rig files and each case's fit and comparison; a finished case is
read back on a re-run (a killed run resumes at the case it was in).

Run: `.venv/bin/python experiments/mtl_strip.py --data PATH [--output DIR] [--depth 1.0] [--stages profile,fit,estimate] [--events 400]`.
"""

import argparse
import json
import re
import sys
import time
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hydrotact._files import write_text_atomic  # noqa: E402

NAME = "mtl_strip"
LOGGED = ("P1", "P2", "P3", "P4")  # the logs' Sensor_0..3 (the data's README)
CHANNELS = ("Sensor_0", "Sensor_1", "Sensor_2", "Sensor_3")
BOARD_SIDE = "ymax"  # the cast's pocket side, in the mould's coordinates (its tray's floor)
EDGE_LENGTH_MM = 1.5
CONE_HALF_ANGLE_DEG = 40.0
BALL_RADIUS_M = 5e-3
MATCH_TOLERANCE_MM = 0.2
MODELS = {  # the receptive fields compared: the pocket's air, the rubber's stress at the port, the cone heuristic
    "pocket": {"kind": "elastic", "reading": "cavity"},
    "elastic": {"kind": "elastic", "port_radius": 0.5, "reading": "pressure"},
    "cone": {"kind": "cone", "half_angle": CONE_HALF_ANGLE_DEG},
}


def find_design(data: Path) -> tuple[Path, Path]:
    """(the mould's STL, the board's Eagle file) under `data`: the repository's layout
    or a `design/` folder; one line naming what is missing otherwise."""
    moulds = [data / "Mold" / "Mold_v6" / "mould_b_V6.STL", data / "design" / "mould_b_V6.STL"]
    boards = sorted((data / "PCB" / "BarometerMTL_1D_V1").glob("*.brd")) + [data / "design" / "Baro_1D_V1.brd"]
    mould = next((path for path in moulds if path.is_file()), None)
    board = next((path for path in boards if path.is_file()), None)
    if mould is None or board is None:
        missing = "the mould (Mold/Mold_v6/mould_b_V6.STL or design/mould_b_V6.STL)" if mould is None else "the board (PCB/BarometerMTL_1D_V1/*.brd or design/Baro_1D_V1.brd)"
        sys.exit(f"{data}: {missing} is not there")
    return mould, board


def read_board_parts(path: Path, pattern: str = r"P\d+") -> dict:
    """{element name: (x, y) mm} of an Eagle board's elements whose names match
    `pattern` (its XML `<element name= x= y=>`; Eagle's unit is the mm)."""
    try:
        root = ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError) as error:
        sys.exit(f"{path}: not an Eagle board file ({error})")
    parts = {}
    for element in root.iter("element"):
        name = element.get("name", "")
        if re.fullmatch(pattern, name):
            try:
                parts[name] = (float(element.get("x")), float(element.get("y")))
            except (TypeError, ValueError):
                sys.exit(f"{path}: element {name} has no numeric x, y")
    if not parts:
        sys.exit(f"{path}: no element named like {pattern!r}")
    return parts


def find_pockets(surface, board_z: float = 0.0) -> np.ndarray:
    """(k, 3) the centres of a cast's pocket ceilings, m, sorted by x: the connected
    patches of faces facing the board (normal -z) above it, each its area-weighted
    centroid."""
    normals = np.asarray(surface.face_normals)
    centres = np.asarray(surface.triangles_center)
    scale = float(np.linalg.norm(np.ptp(surface.vertices, axis=0)))
    ceiling = np.flatnonzero((normals[:, 2] < -0.99) & (centres[:, 2] > board_z + 1e-6 * scale))
    if len(ceiling) == 0:
        return np.zeros((0, 3))
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(surface.faces)[ceiling]  # faces sharing a vertex are one patch
    rows = np.repeat(np.arange(len(ceiling)), 3)
    incidence = coo_matrix((np.ones(rows.size), (rows, faces.reshape(-1))), shape=(len(ceiling), int(faces.max()) + 1)).tocsr()
    labels = connected_components(incidence @ incidence.T, directed=False)[1]
    areas = np.asarray(surface.area_faces)[ceiling]
    pockets = np.array([np.average(centres[ceiling][labels == label], axis=0, weights=areas[labels == label]) for label in np.unique(labels)])
    return pockets[np.argsort(pockets[:, 0])]


def align_board(parts: dict, pockets: np.ndarray) -> tuple[np.ndarray, dict]:
    """(the translation board mm -> sensor m, {part: its pocket's centre, m}): the
    packages sorted by board x matched to the pockets sorted by x, the translation
    their mean offset; refused where a package lies more than MATCH_TOLERANCE_MM from
    its pocket after it, or the counts differ."""
    names = sorted(parts, key=lambda name: parts[name][0])
    if len(names) != len(pockets):
        sys.exit(f"the board has {len(names)} barometer packages but the cast {len(pockets)} pockets")
    board = np.array([parts[name] for name in names]) * 1e-3
    shift = np.mean(pockets[:, :2] - board, axis=0)
    misfit = np.linalg.norm(board + shift - pockets[:, :2], axis=1)
    if misfit.max() > MATCH_TOLERANCE_MM * 1e-3:
        worst = names[int(np.argmax(misfit))]
        sys.exit(f"the board's packages do not sit under the cast's pockets: {worst} is {misfit.max() * 1e3:.2f} mm from its pocket after the best shift")
    return shift, {name: pocket for name, pocket in zip(names, pockets)}


def make_strip_document(mould: Path, ports: dict, field: dict, name: str) -> dict:
    """The strip's sensor document: the mould's cast, a barometer per logged channel
    at its pocket's ceiling centre (mm), facing into the rubber."""
    return {
        "name": name,
        "description": "The MTL strip (JiannnH/MTL-BaroTactileSensor): the cast of mould_b_V6 (pocket side on the board), MPL3115A2 barometers P1-P4 "
        "at their pockets' ceiling centres (logged as Sensor_0-3), placed from the Eagle board by the fitted board-to-cast shift.",
        "units": {"length": "mm", "angle": "deg"},
        "geometry": {"kind": "mould", "paths": [str(mould.resolve())], "mould_units": "mm", "board": BOARD_SIDE, "edge_length": EDGE_LENGTH_MM},
        "part": "MPL3115A2",
        "taxels": [{"name": channel, "position": [float(v) * 1e3 for v in ports[part]], "axis": [0.0, 0.0, 1.0], "receptive_field": field} for channel, part in zip(CHANNELS, LOGGED)],
    }


def simulate_profile(spec, xs: np.ndarray, depth: float) -> np.ndarray:
    """(len(xs), channels) each barometer's reading, Pa, with the ball `depth` deep
    into the skin at each x along the strip (y = 0; an elastic material of 1 MPa)."""
    from hydrotact.contact import make_sphere_probe
    from hydrotact.sim import make_sensor_model, make_trajectory, simulate
    from hydrotact.visco import make_prony

    model = make_sensor_model(spec)
    top = float(np.max(np.asarray(model.field.vertices)[:, 2]))
    tips = np.column_stack([xs, np.zeros_like(xs), np.full_like(xs, top - depth)])
    samples = simulate(model, make_prony(1e6), make_sphere_probe(BALL_RADIUS_M), make_trajectory(np.arange(len(xs)) * 0.01, tips), progress=False)
    return np.asarray(samples.taxel_pressures)


def measure_peaks(path: Path) -> list:
    """Each press of a calibration log: (stage x mm, [each channel's rise over its level
    before the press, at the press's deepest sample, Pa]). The logs' columns as their
    README says: `x` in µm, `z` travel in steps."""
    table = np.genfromtxt(path, delimiter=",", names=True)
    x, z = table["x"], table["z"]
    presses = []
    for site in np.unique(x):
        rows = np.flatnonzero(x == site)
        if not np.any(z[rows] > 0):
            continue
        deepest = rows[int(np.argmax(z[rows]))]
        low = z[rows].min() + 0.05 * np.ptp(z[rows])  # the stage retracted (not always to z = 0)
        before = rows[(z[rows] <= low) & (rows < deepest)][-10:]
        if len(before) == 0:
            continue
        presses.append((float(site) / 1e3, [float(table[c][deepest] - np.mean(table[c][before])) for c in CHANNELS]))
    return presses


def _vertex(xs, values) -> float:
    """Where a sampled profile peaks: the vertex of the parabola through its highest
    sample and its two neighbours (the sample itself at an end)."""
    k = int(np.argmax(values))
    if k == 0 or k == len(values) - 1:
        return float(xs[k])
    a, b, c = values[k - 1], values[k], values[k + 1]
    curvature = a - 2.0 * b + c
    return float(xs[k] + (0.5 * (a - c) / curvature if curvature < 0.0 else 0.0) * (xs[k + 1] - xs[k]))


def _width(xs, values) -> tuple[float, float]:
    """(where a profile peaks, its full width at half its peak), mm."""
    values = np.asarray(values, dtype=float)
    k = int(np.argmax(values))
    above = np.flatnonzero(values >= 0.5 * values[k])
    return float(xs[k]), float(xs[above[-1]] - xs[above[0]]) if len(above) else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="a checkout of the strip's repository, or a folder with design/ and logs/ laid out like it")
    parser.add_argument("--output", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--depth", type=float, default=1.0, help="the simulated ball's depth into the skin, mm")
    parser.add_argument("--stages", default="profile,fit,estimate,joint",
                        help="profile (the barometers' spatial profiles), fit (the material, full mode, with held-out logs), estimate (sim-to-real estimation; "
                        "needs fit), joint (one material for the vacuum and non-vacuum logs; needs fit)")
    parser.add_argument("--events", type=int, default=400, help="presses in the simulated strip dataset of the estimate stage")
    args = parser.parse_args()
    stages = set(args.stages.split(","))
    sys.path.insert(0, str(Path(__file__).parent))
    from mtl_calibration import find_logs

    from hydrotact.mesh import make_mould_cavity
    from hydrotact.sensors import load_sensor

    mould, board = find_design(args.data)
    logs = find_logs(args.data)
    work = args.output / f"{NAME}.work"
    work.mkdir(parents=True, exist_ok=True)
    surface, _ = make_mould_cavity(mould, units="mm", board=BOARD_SIDE)
    pockets = find_pockets(surface)
    shift, ports = align_board(read_board_parts(board), pockets)
    specs = {}
    for kind, field in MODELS.items():
        path = work / f"{NAME}_sensor_{kind}.json"
        write_text_atomic(path, json.dumps(make_strip_document(mould, ports, field, f"mtl-strip-{kind}"), indent=1) + "\n")
        specs[kind] = load_sensor(path)
    xs = np.round(np.arange(-60.0, -11.9, 1.0), 6) * 1e-3
    profiles = {kind: simulate_profile(spec, xs, args.depth * 1e-3) for kind, spec in specs.items()}
    measured = {name: measure_peaks(path) for name, path in logs.items()}
    # Each log's rises as a share of its channel's largest (the logs press 5 or 6 mm,
    # with and without the vacuum: the shape is compared, their median at each stage
    # x); the stage-to-cast offset puts the peaks of the channels whose peak lies
    # inside the presses' span (Sensor_2, Sensor_3: stage x 0-19 mm) over their
    # barometers, each peak the vertex of the parabola through its three highest
    # sites.
    stage, rises = [], []
    for presses in measured.values():
        values = np.array([rise for _, rise in presses])
        stage += [x for x, _ in presses]
        rises.append(values / np.maximum(values.max(axis=0), 1e-9))
    stage, rises = np.array(stage), np.concatenate(rises)
    sites = np.unique(stage)
    medians = np.array([[np.median(rises[stage == site, c]) for c in range(len(CHANNELS))] for site in sites])
    offset = float(np.mean([ports[LOGGED[c]][0] * 1e3 - _vertex(sites, medians[:, c]) for c in (2, 3)]))
    rows = []
    for c, channel in enumerate(CHANNELS):
        row = {"channel": channel, "port_x_mm": float(ports[LOGGED[c]][0] * 1e3)}
        for kind in profiles:
            row[f"{kind}_peak_x_mm"], row[f"{kind}_width_mm"] = _width(xs * 1e3, profiles[kind][:, c])
            row[f"{kind}_min_Pa"], row[f"{kind}_max_Pa"] = float(profiles[kind][:, c].min()), float(profiles[kind][:, c].max())
        row["measured_peak_x_mm"], row["measured_width_mm"] = _width(sites + offset, medians[:, c])
        row["measured_vertex_x_mm"] = _vertex(sites, medians[:, c]) + offset
        rows.append(row)
    document = {
        "settings": {"depth_mm": args.depth, "ball_radius_mm": BALL_RADIUS_M * 1e3, "edge_length_mm": EDGE_LENGTH_MM, "cone_half_angle_deg": CONE_HALF_ANGLE_DEG},
        "alignment": {"board_to_cast_shift_mm": (shift * 1e3).tolist(), "pockets_mm": (pockets * 1e3).tolist(), "stage_to_cast_offset_mm": offset},
        "profile_x_mm": (xs * 1e3).tolist(),
        "profiles_Pa": {kind: values.tolist() for kind, values in profiles.items()},
        "table": rows,
    }
    if stages & {"fit", "estimate", "joint"}:
        document["fit"] = fit_stage(work / f"{NAME}_sensor_pocket.json", logs, work, offset, args.output)
    if "estimate" in stages:
        document["estimate"] = estimate_stage(work / f"{NAME}_sensor_pocket.json", logs, work, offset, args.events)
    if "joint" in stages:
        document["joint"] = joint_stage(work / f"{NAME}_sensor_pocket.json", logs, work, offset)
    args.output.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.output / f"{NAME}.json", json.dumps(document, indent=1) + "\n")
    lines = ["| channel | port x (mm) | measured: peak x (vertex) / width (mm) | " + " | ".join(f"{kind}: peak x / width (mm), min / max (Pa)" for kind in MODELS) + " |",
             "|---|---:|---|" + "---|" * len(MODELS)]
    for row in rows:
        cells = [f"{row[f'{kind}_peak_x_mm']:.1f} / {row[f'{kind}_width_mm']:.1f}, {row[f'{kind}_min_Pa']:.0f} / {row[f'{kind}_max_Pa']:.0f}" for kind in MODELS]
        shape = f"{row['measured_peak_x_mm']:.1f} ({row['measured_vertex_x_mm']:.1f}) / {row['measured_width_mm']:.1f}"
        lines.append(f"| {row['channel']} | {row['port_x_mm']:.1f} | {shape} | " + " | ".join(cells) + " |")
    if "fit" in document:
        lines += ["", *fit_table(document["fit"])]
    if "estimate" in document:
        lines += ["", *estimate_table(document["estimate"])]
    if "joint" in document:
        lines += ["", *joint_lines(document["joint"])]
    write_text_atomic(args.output / f"{NAME}.md", "\n".join(lines) + "\n")
    _plot(document, measured, args.output / f"{NAME}.png")
    print(f"wrote {args.output / NAME}.{{json,md,png}}")


ONSET_STEPS = {"non-vacuum": (1600.0, 2000.0), "vacuum": (2050.0, 2450.0), "both": (1600.0, 2450.0)}  # the README's contact onsets, a little wider
STEPS_PER_M = 480e3  # the README: 480 steps per mm
SATURATION_PA = 140.5e3  # the README: mask samples above ~140.5 kPa
MAX_TRAVEL_MM = 6.0  # the README: zd6 logs travel to 2880 steps
SCORED = ("Sensor_1", "Sensor_2", "Sensor_3")
GAINS = "relative"  # each barometer's own sensitivity, their geometric mean 1 (E keeps the scale)


def make_rig_document(offset_mm: float, skin_top_mm: float, group: str, slope: float | None = None) -> dict:
    """The stage rig of a group of logs (mm): the 10 mm ball, x offset within ±2 mm of
    `offset_mm`, the home (the tip's height at travel 0) where the README puts the
    contact onsets above the skin's top, the lag within 0-0.2 s; with `slope`, the
    stage's x axis may tilt against the skin by up to that ratio either way, per log."""
    low, high = (skin_top_mm + steps / STEPS_PER_M * 1e3 for steps in ONSET_STEPS[group])
    tilt = {} if slope is None else {"slope_x": {"start": 0.0, "min": -slope, "max": slope}}
    return tilt | {
        "format": "hydrotact.rig", "version": 1, "name": f"mtl-stage-{group}",
        "description": "The MTL strip's stage: a 10 mm steel ball (assumed; not recorded with the logs), z travel towards the skin, x along the strip.",
        "units": {"length": "mm"}, "probe": f"sphere:r={BALL_RADIUS_M * 1e3:g}mm", "columns": {"travel": "indentation", "x": "stage_x"},
        "offset_x": {"start": offset_mm, "min": offset_mm - 2.0, "max": offset_mm + 2.0},
        "home": {"start": 0.5 * (low + high), "min": low, "max": high},
        "lag_s": {"start": 0.05, "min": 0.0, "max": 0.2},
        "max_travel": MAX_TRAVEL_MM,  # a held-out log may press to the deepest travel of any (zd6: 2880 steps)
        "table_step": {"xy": 0.5, "height": 0.1},
    }


def fit_stage(spec_path: Path, logs: dict, work: Path, offset_mm: float, output: Path) -> dict:
    """Each group's fit (whole, and each log left out and predicted); resumable: a
    case whose fit and comparison are in `work` is read back."""
    from mtl_calibration import GROUPS, MAPPING

    from hydrotact.sim import make_sensor_model
    from hydrotact.sysid import SimulatorFit, compare_fit, fit_logs

    mapping = work / "mtl_mapping.json"
    write_text_atomic(mapping, json.dumps(MAPPING, indent=1) + "\n")
    top = float(np.max(np.asarray(make_sensor_model(spec_path).field.vertices)[:, 2])) * 1e3
    lumped = _lumped_held_out(output)
    cases = []
    for group, names in GROUPS.items():
        rig = work / f"{NAME}_rig_{group}.json"
        write_text_atomic(rig, json.dumps(make_rig_document(offset_mm, top, group), indent=1) + "\n")
        for left in (None, *names):
            fitted = [n for n in names if n != left]
            folder = work / (f"fit_{GAINS}_{group}" + ("" if left is None else f"_without_{left}"))
            method = SimulatorFit(sensor=str(spec_path), num_rays=16, progress=False, rig=rig, drift=30.0, saturation_pa=SATURATION_PA, gains=GAINS)
            if not (folder / "fit" / "report.json").is_file():
                start = time.perf_counter()
                fit_logs([logs[n] for n in fitted], folder / "fit", method=method, terms=2, mapping=mapping)
                (folder / "seconds.txt").write_text(f"{time.perf_counter() - start:.1f}\n")
            report = json.loads((folder / "fit" / "report.json").read_text())
            case = {
                "group": group, "fitted": fitted, "compared": left, "fit_seconds": float((folder / "seconds.txt").read_text()) if (folder / "seconds.txt").is_file() else None,
                "reduced_chi_square": report["reduced_chi_square"], "long_term_modulus_Pa": report["long_term_modulus_Pa"],
                "prony_terms": report["prony_terms"], "rig": report["rig"],
                "gains": {name.split("/")[-1]: value for name, value in report["gains"].items()},
                "fit_rms_Pa": {entry["source"].split("/")[-1]: {c: v["rms"] for c, v in entry["columns"].items()} for entry in report["residuals"]},
            }
            if left is not None:
                if not (folder / "compare" / "compare.json").is_file():
                    compare_fit(folder / "fit", [logs[left]], folder / "compare", mapping=mapping, tare="first:20")
                entry = json.loads((folder / "compare" / "compare.json").read_text())["logs"][0]
                case["compare_rms_Pa"] = {c: entry["channels"][c]["rms_Pa"] for c in SCORED}
                case["compare_pooled_rms_Pa"] = float(np.sqrt(np.mean([entry["channels"][c]["rms_Pa"] ** 2 for c in SCORED])))
                case["home_shift_mm"] = 1e3 * entry["home_shift_m"]["value"] if entry["home_shift_m"] else None
                case["lumped_compare_pooled_rms_Pa"] = lumped.get((group, left))
            cases.append(case)
            print(f"{group} {'whole' if left is None else 'without ' + left}: E_inf {report['long_term_modulus_Pa']['value'] / 1e6:.3f} MPa"
                  + (f", held out {case['compare_pooled_rms_Pa']:.0f} Pa pooled RMS" if left else ""), flush=True)
    return {"sensor": "pocket", "saturation_Pa": SATURATION_PA, "tare": "first:20", "gains": GAINS, "cases": cases}


ESTIMATE_CONFIG = dict(targets=("x", "depth"), sequence_length=64, burn_in=32, batch_size=16, max_epochs=40, patience=8, seed=0)
SIZES = (1, 3)  # real logs fine-tuned on (and trained on from scratch)
TARE_S = 20.0


def _tared(columns: dict, rest: np.ndarray) -> dict:
    """A log's columns with each channel less its median over the first TARE_S s, plus `rest` (the simulation's resting level)."""
    times = np.asarray(columns["time"])
    first = times - times[0] <= TARE_S
    out = dict(columns)
    for c, channel in enumerate(CHANNELS):
        values = np.asarray(columns[channel], dtype=np.float64)
        out[channel] = values - np.median(values[first]) + rest[c]
    return out


def _split(block: dict, every: int = 4) -> tuple[list, list]:
    """(training pieces, validation pieces) of a log: cut halfway between its presses
    (its contact runs), every `every`-th press (from the third) to validation. A log
    sweeps x from one end to the other, so a cut in time would validate on places the
    training never saw."""
    contact = np.asarray(block["contact"]) > 0
    change = np.diff(np.concatenate([[0], contact.astype(int), [0]]))
    starts, ends = np.flatnonzero(change == 1), np.flatnonzero(change == -1)
    cuts = [0, *((ends[:-1] + starts[1:]) // 2).tolist(), len(contact)]
    pieces = [{k: np.asarray(v)[a:b] for k, v in block.items()} for a, b in zip(cuts[:-1], cuts[1:])]
    return [p for k, p in enumerate(pieces) if k % every != 2], [p for k, p in enumerate(pieces) if k % every == 2]


def estimate_stage(spec_path: Path, logs: dict, work: Path, offset_mm: float, events: int) -> dict:
    """The sim-to-real study (see the module, 4.); resumable: the dataset, the
    pretrained model and each fold's numbers are kept in `work`."""
    import dataclasses
    import warnings

    import jax
    from mtl_calibration import GROUPS

    from hydrotact import HydrotactWarning
    from hydrotact.data import load_mapping, read_log, write_log
    from hydrotact.datasets import DatasetConfig, generate_dataset, load_dataset
    from hydrotact.models import TrainConfig, evaluate_estimator, fine_tune_estimator, init_estimator, load_estimator, save_estimator, train_estimator
    from hydrotact.sensors import load_sensor
    from hydrotact.sysid import label_rig_log

    mapping = load_mapping(work / "mtl_mapping.json")
    material = work / f"fit_{GAINS}_non-vacuum" / "fit" / "material.json"
    labelled = {}
    for group, names in GROUPS.items():
        folder = work / f"labels_{group}"
        folder.mkdir(exist_ok=True)
        for name in names:
            path = folder / f"{name}_labelled.parquet"
            if not path.is_file():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", HydrotactWarning)  # the logs' clock jitter, said by the fit stage
                    log = read_log(logs[name], mapping, require_sensor=False)
                write_log(path, label_rig_log(work / f"fit_{GAINS}_{group}" / "fit", log, str(logs[name]), tare=f"first:{TARE_S:g}", material=material))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", HydrotactWarning)
                labelled[name] = (group, read_log(path))
    # The presses' x on the strip (stage x 0-19 mm plus the fitted offset), a millimetre past each end.
    xs = np.concatenate([log.columns["contact_x"][np.isfinite(log.columns["contact_x"])] for _, log in labelled.values()])
    span = (float(xs.min()) - 1e-3, float(xs.max()) + 1e-3)
    dataset_folder = work / "strip_dataset"
    config = DatasetConfig(
        events=events, seed=0, probe=f"sphere:r={BALL_RADIUS_M * 1e3:g}mm", target="depth", depth_range=(0.2e-3, 2.5e-3), regime="stage",
        stage_x_range=span, stage_y_range=(-0.3e-3, 0.3e-3), speed_range=(0.39e-3, 1.85e-3), hold_range=(0.0, 10.0), gap_range=(1.0, 4.0),
        rate_hz=16.4, num_rays=16, split_blocks=10, test_fraction=0.2,
    )
    if not (dataset_folder / "manifest.json").is_file():
        start = time.perf_counter()
        generate_dataset(str(spec_path), dataset_folder, material=material, config=config, progress=True)
        (work / "strip_dataset_seconds.txt").write_text(f"{time.perf_counter() - start:.1f}\n")
    dataset = load_dataset(dataset_folder)
    sensor = load_sensor(spec_path)
    train = dataset.arrays("train")
    resting = np.asarray(train["contact"]) <= 0
    rest = np.array([np.median(np.asarray(train[c])[resting]) for c in CHANNELS])
    config_train = TrainConfig(**ESTIMATE_CONFIG)
    pretrained_folder = work / "strip_pretrained"
    if not (pretrained_folder / "model.json").is_file():
        save_estimator(train_estimator(dataset, sensor, config_train, folder=pretrained_folder, progress=True), pretrained_folder, sensor.name)
    pretrained = load_estimator(pretrained_folder)
    rate = float(dataset.manifest["config"]["rate_hz"])
    blocks = {name: _tared(log.columns, rest) for name, (_, log) in labelled.items()}
    folds = []
    for held in blocks:
        path = work / f"estimate_without_{held}.json"
        if path.is_file():
            folds.append(json.loads(path.read_text()))
            continue
        group = labelled[held][0]
        pool = sorted((n for n in blocks if n != held), key=lambda n: (labelled[n][0] != group, n))  # the held-out log's state first
        score = lambda model, block=blocks[held]: {k: float(v) for k, v in evaluate_estimator(model, [block], rate)["metrics"].items()}
        fold = {"held_out": held, "group": group, "simulation_only": score(pretrained), "runs": []}
        for size in SIZES:
            parts = [_split(blocks[n]) for n in pool[:size]]
            training, validation = [p for part in parts for p in part[0]], [p for part in parts for p in part[1]]
            tuned_config = dataclasses.replace(config_train, learning_rate=1e-3)
            fresh = dataclasses.replace(pretrained, params=init_estimator(pretrained.spec, jax.random.PRNGKey(1)))
            for kind, start in (("scratch", fresh), ("fine-tuned", pretrained)):
                model = fine_tune_estimator(start, training, validation, tuned_config if kind == "fine-tuned" else config_train)
                fold["runs"].append({"kind": kind, "logs": pool[:size], "metrics": score(model), "epochs": len(model.history)})
        write_text_atomic(path, json.dumps(fold, indent=1) + "\n")
        folds.append(fold)
        summary = ", ".join(f"{r['kind']} {len(r['logs'])}: x {1e3 * r['metrics']['x_rmse']:.2f} mm, depth {1e3 * r['metrics']['depth_rmse']:.2f} mm" for r in fold["runs"])
        print(f"estimate without {held}: {summary}", flush=True)
    return {"dataset": dataset.manifest["config"], "dataset_rows": dataset.num_rows, "train_config": config_train.to_json(),
            "pretrained_validation": pretrained.history[pretrained.best_epoch]["validation_metrics"], "folds": folds}


def estimate_table(estimate: dict) -> list:
    """The estimate stage's table (markdown): per held-out log, x and depth RMSE (mm) of each model."""
    kinds = [("simulation only", None, None)] + [(f"{kind} on {size}", kind, size) for size in SIZES for kind in ("scratch", "fine-tuned")]
    lines = ["| held out | " + " | ".join(f"{label}: x / depth RMSE (mm)" for label, _, _ in kinds) + " |", "|---|" + "---|" * len(kinds)]
    totals = {label: [] for label, _, _ in kinds}
    for fold in estimate["folds"]:
        cells = []
        for label, kind, size in kinds:
            metrics = fold["simulation_only"] if kind is None else next(r["metrics"] for r in fold["runs"] if r["kind"] == kind and len(r["logs"]) == size)
            totals[label].append((metrics["x_rmse"], metrics["depth_rmse"]))
            cells.append(f"{1e3 * metrics['x_rmse']:.2f} / {1e3 * metrics['depth_rmse']:.2f}")
        lines.append(f"| {fold['held_out']} | " + " | ".join(cells) + " |")
    lines.append("| RMS over the folds | " + " | ".join(
        f"{1e3 * np.sqrt(np.mean(np.square([v[0] for v in totals[label]]))):.2f} / {1e3 * np.sqrt(np.mean(np.square([v[1] for v in totals[label]]))):.2f}" for label, _, _ in kinds) + " |")
    return lines


SLOPE = 0.08  # the tilted stage's bound (mm per mm of stage x): 1.5 mm over the 19 mm the presses span


def _whole_fit(spec_path: Path, logs: dict, names: list, work: Path, offset_mm: float, group: str, slope: float | None) -> dict:
    """One fit of the logs `names` whole (resumable: read back when done), the group's
    rig (`both`: either state's onsets), level or with a slope per log; its summary."""
    from mtl_calibration import GROUPS

    from hydrotact.sim import make_sensor_model
    from hydrotact.sysid import SimulatorFit, fit_logs

    sloped = "" if slope is None else "_sloped"
    folder = work / f"fit_{GAINS}_{group}{sloped}"
    if not (folder / "fit" / "report.json").is_file():
        top = float(np.max(np.asarray(make_sensor_model(spec_path).field.vertices)[:, 2])) * 1e3
        rig = work / f"{NAME}_rig_{group}{sloped}.json"
        write_text_atomic(rig, json.dumps(make_rig_document(offset_mm, top, group, slope), indent=1) + "\n")
        start = time.perf_counter()
        method = SimulatorFit(sensor=str(spec_path), num_rays=16, progress=False, rig=rig, drift=30.0, saturation_pa=SATURATION_PA, gains=GAINS)
        fit_logs([logs[n] for n in names], folder / "fit", method=method, terms=2, mapping=work / "mtl_mapping.json")
        (folder / "seconds.txt").write_text(f"{time.perf_counter() - start:.1f}\n")
    report = json.loads((folder / "fit" / "report.json").read_text())
    order = [name for names_ in GROUPS.values() for name in names_ if name in names]
    return {"chi_square": report["chi_square"], "num_residuals": report["num_residuals"], "num_parameters": report["num_parameters"],
            "long_term_modulus_Pa": report["long_term_modulus_Pa"], "prony_terms": report["prony_terms"], "offset_x_mm": 1e3 * report["rig"]["offset_x"]["value"],
            "gains": {name.split("/")[-1]: value["value"] for name, value in report["gains"].items()},
            "slopes": {name: report["rig"][f"slope_x[{k + 1}]"] for k, name in enumerate(order)} if slope is not None else None,
            "seconds": float((folder / "seconds.txt").read_text()) if (folder / "seconds.txt").is_file() else None}


def joint_stage(spec_path: Path, logs: dict, work: Path, offset_mm: float) -> dict:
    """Whether one material explains both states: the six logs fitted at once (one
    rig: the x offset, the lag and each barometer's relative gain shared, a home per
    log within both states' onsets) against the two groups' own fits, by χ² and BIC
    (χ² + parameters × ln(residuals)); and again with the stage free to tilt against
    the skin per log (`slope_x` within ±SLOPE: the vacuum pulling the skin down more
    at one end than the other, a changed boundary), jointly and per state. Resumable
    as the fit stage."""
    from mtl_calibration import GROUPS

    names = [name for group in GROUPS.values() for name in group]
    found = {}
    for slope in (None, SLOPE):
        joint = _whole_fit(spec_path, logs, names, work, offset_mm, "both", slope)
        separate = {group: _whole_fit(spec_path, logs, list(GROUPS[group]), work, offset_mm, group, slope) for group in GROUPS}
        bic = lambda chi, p, n=joint["num_residuals"]: chi + p * np.log(n)
        both = (sum(v["chi_square"] for v in separate.values()), sum(v["num_parameters"] for v in separate.values()))
        found["level" if slope is None else "sloped"] = {
            "joint": joint | {"bic": bic(joint["chi_square"], joint["num_parameters"])}, "separate": separate,
            "separate_bic": bic(*both), "separate_chi_square": both[0], "separate_num_parameters": both[1]}
    return found["level"] | {"sloped": found["sloped"], "slope_bound": SLOPE}


def joint_lines(joint: dict) -> list:
    """The joint stage's table (markdown): level and, where run, tilted stages."""
    lines = ["| stage | fit | E∞ (MPa) | terms (MPa, s) | offset x (mm) | gains Sensor_0-3 | slopes per log (mm/mm) | χ² | parameters |",
             "|---|---|---:|---|---:|---|---|---:|---:|"]
    cases = [("level", joint), *([("tilted", joint["sloped"])] if "sloped" in joint else [])]
    for stage, case in cases:
        for label, value in [("both states, one material", case["joint"]), *((f"{group} alone", value) for group, value in case["separate"].items())]:
            terms = ", ".join(f"{t['modulus_Pa']['value'] / 1e6:.2f} @ {t['tau_s']['value']:.3g}" for t in value["prony_terms"])
            gains = ", ".join(f"{value['gains'].get(c, 1.0):.2f}" for c in CHANNELS)
            slopes = ", ".join(f"{s['value']:+.3f}" for s in value["slopes"].values()) if value.get("slopes") else "-"
            lines.append(f"| {stage} | {label} | {value['long_term_modulus_Pa']['value'] / 1e6:.2f} | {terms} | {value['offset_x_mm']:.2f} | {gains} | {slopes} | "
                         f"{value['chi_square']:.4g} | {value['num_parameters']} |")
    for stage, case in cases:
        lines.append(f"\nBIC, {stage}: one material {case['joint']['bic']:.5g}, one per state {case['separate_bic']:.5g} (lower is better).")
    return lines


def _lumped_held_out(output: Path) -> dict:
    """{(group, left-out log): the lumped fit's pooled RMS on it} from mtl_calibration.json, if there."""
    path = output / "mtl_calibration.json"
    if not path.is_file():
        return {}
    found = {}
    for case in json.loads(path.read_text())["cases"]:
        if case["kind"] == "leave-one-out":
            found[(case["case"].split(" without ")[0], case["compared"])] = case.get("compare_pooled_rms_Pa")
    return found


def fit_table(fit: dict) -> list:
    """The fit stage's table lines (markdown)."""
    lines = ["| group | fitted | E∞ (MPa) | slow term (MPa, s) | offset x (mm) | lag (ms) | gains Sensor_0-3 | held out | RMS Sensor_1-3 (Pa) | pooled (Pa) | lumped, same split (Pa) |",
             "|---|---|---:|---|---:|---:|---|---|---|---:|---:|"]
    for case in fit["cases"]:
        modulus = case["long_term_modulus_Pa"]
        slow = max(case["prony_terms"], key=lambda term: term["tau_s"]["value"])
        identified = slow["modulus_Pa"]["identified"] and slow["tau_s"]["identified"]
        slow_text = f"{slow['modulus_Pa']['value'] / 1e6:.2f}, {slow['tau_s']['value']:.3g}" if identified else "not identified"
        rig = case["rig"]
        held = case["compared"] or "-"
        rms = ", ".join(f"{case['compare_rms_Pa'][c]:.0f}" for c in SCORED) if case["compared"] else "-"
        pooled = f"{case['compare_pooled_rms_Pa']:.0f}" if case["compared"] else "-"
        lumped = f"{case['lumped_compare_pooled_rms_Pa']:.0f}" if case.get("lumped_compare_pooled_rms_Pa") else "-"
        gains = ", ".join(f"{case['gains'][c]['value']:.2f}" if c in case.get("gains", {}) else "1" for c in CHANNELS)
        lines.append(
            f"| {case['group']} | {len(case['fitted'])} logs | {modulus['value'] / 1e6:.2f} ± {modulus['std'] / 1e6:.2f} | "
            f"{slow_text} | {rig['offset_x']['value'] * 1e3:.2f} | {rig['lag_s']['value'] * 1e3:.0f} | {gains} | "
            f"{held} | {rms} | {pooled} | {lumped} |"
        )
    return lines


def _plot(document: dict, measured: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs = np.asarray(document["profile_x_mm"])
    offset = document["alignment"]["stage_to_cast_offset_mm"]
    figure, axes = plt.subplots(1, 1 + len(MODELS), figsize=(4.7 * (1 + len(MODELS)), 3.8))
    for c, channel in enumerate(CHANNELS):
        colour = f"C{c}"
        for axis, kind in zip(axes[1:], MODELS):
            values = np.asarray(document["profiles_Pa"][kind])[:, c]
            axis.plot(xs, values, color=colour, label=channel)
        for k, presses in enumerate(measured.values()):
            axes[0].plot([x + offset for x, _ in presses], [rise[c] / 1e3 for _, rise in presses], ".", color=colour, ms=3, label=None if k else channel)
    axes[0].set(title="measured: rise at each press's deepest sample", xlabel="x along the strip (mm, stage x + offset)", ylabel="kPa")
    titles = {"pocket": "simulated, the pocket's air (cavity)", "elastic": "simulated, the rubber's stress at the port", "cone": f"simulated, cone {CONE_HALF_ANGLE_DEG:g}°"}
    for axis, kind in zip(axes[1:], MODELS):
        axis.set(title=titles[kind], xlabel="ball x (mm)", ylabel="Pa (E = 1 MPa)")
    for axis in axes:
        axis.legend(fontsize=7)
        axis.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


if __name__ == "__main__":
    main()
