"""Table I of the barometric estimation paper, in simulation: binned and plain angle
heads x our two-layer GRU, the paper's one-layer tanh RNN and its MLP, on sphere8 and
ellipsoid8, several seeds; then the ageing test of its Fig. 8.

For each sensor a dataset is generated in the paper's regime (`hydrotact.datasets`,
2500 events by default) with a viscoelastic silicone (E(0) = 10 MPa, the generator's default modulus: E∞ 6 MPa
and two Prony terms, 2.5 MPa at 0.8 s and 1.5 MPa at 12 s). Every model is trained on its
training split (`hydrotact.models.train_estimator`, the defaults of `hydrotact train`)
and evaluated on its held-out blocks, each run from the zero state
(`evaluate_estimator`). Rows: GRU (sized to the 6000-parameter budget), GRU at the
paper's RNN's parameter count (18 + 18 units), the paper's RNN (48 units) and MLP, each
binned and plain; the table gives the mean and spread (standard deviation) over seeds.

Ageing (Fig. 8): a second sphere8 dataset from the same seed (same events, same sensor
variation) with an aged material (E∞ +30 %, the slow term's τ doubled), evaluated by
the first seed's binned GRU after a tare: each channel shifted by the difference of
the median no-contact readings of the two datasets' training splits.

Outputs (in --output, default experiments/results/): `ablation_table1.json` (every
run's metrics, the settings and the timings), `ablation_table1.md` (the table) and
`ablation_table1.png` (force and angle RMSEs per row) and `ablation_table1_error_map_SENSOR.png`
(the paper's Fig. 5: each row's localisation error over the skin), each dataset's channel swing
beside the paper's 3-9 kPa in the table's text, and `ablation_table1_models.md`, the table beside
another run's (`--compare`, by default the committed run under the cones). Datasets and training runs are
kept under `ablation_table1.work/` and resume when the script is run again. Each finished model's
record (its metrics and error map, with the settings it ran under) is also written to
`ablation_table1.runs/` beside the outputs, a small file meant to be committed: a run under the
same settings reads it back instead of training that model again, so a long run continues on
another checkout, where the work folder is gone (the datasets are made again, byte for byte).

Run: `.venv/bin/python experiments/ablation_table1.py [--events 2500] [--seeds 3] [--smoke]`.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from hydrotact._files import atomic_path, digest, write_text_atomic  # noqa: E402
from hydrotact.data import make_material_document, write_material  # noqa: E402
from hydrotact.datasets import DatasetConfig, generate_dataset, load_dataset  # noqa: E402
from hydrotact.models import (  # noqa: E402
    TrainConfig,
    calc_error_map,
    calc_skin_radius,
    count_parameters,
    evaluate_estimator,
    make_estimator_spec,
    save_estimator,
    train_estimator,
)
from hydrotact.sensors import load_sensor  # noqa: E402

NAME = "ablation_table1"
MATERIAL = (6e6, [2.5e6, 1.5e6], [0.8, 12.0])
AGED = (6e6 * 1.3, [2.5e6, 1.5e6], [0.8, 24.0])
ROWS = (("gru", None, "GRU (budget)"), ("gru", (18, 18), "GRU (= RNN count)"), ("rnn", None, "RNN (paper)"), ("mlp", None, "MLP (paper)"))
# Smoke: the test suite's tiny regime (8 rays, short holds and gaps, fast presses, the
# 3 mm sphere meshed coarsely: the contacts cost a fifth, and the layout smoke's design
# presses the same mesh, so its contact kernels compile once for both).
SMOKE_REGIME = dict(probe="sphere:r=3mm,subdivisions=1", num_rays=8, hold_range=(0.3, 0.8), gap_range=(0.2, 0.4), speed_range=(0.01, 0.02), force_range=(0.2, 4.0))
METRICS = ("fx_rmse", "fy_rmse", "fz_rmse", "fn_rmse", "theta_rmse", "phi_rmse", "contact_bce", "arc_length_mean")

def _dataset(folder: Path, sensor: str, material: tuple, events: int, smoke: bool) -> Path:
    material_file = write_material(folder.parent / f"{folder.name}.material.json", make_material_document(*material, name=folder.name))
    config = DatasetConfig(events=events, **(SMOKE_REGIME if smoke else {}))
    generate_dataset(sensor, folder, material=material_file, config=config, progress=not smoke)
    return folder


def read_record(path: Path, settings: dict):
    """The record at `path` if it was written under `settings` (else None: trained again)."""
    if not path.is_file():
        return None
    document = json.loads(path.read_text())
    return document["record"] if document.get("settings") == json.loads(json.dumps(settings)) else None


def write_record(path: Path, settings: dict, record: dict) -> None:
    write_text_atomic(path, json.dumps({"settings": settings, "record": record}, indent=1) + "\n")


def _tare(dataset, reference) -> np.ndarray:
    """Per channel, the median no-contact reading of `dataset`'s training split minus `reference`'s."""
    shifts = []
    for name in dataset.channels:
        a, b = dataset.arrays("train", [name, "contact"]), reference.arrays("train", [name, "contact"])
        shifts.append(np.median(a[name][a["contact"] == 0]) - np.median(b[name][b["contact"] == 0]))
    return np.asarray(shifts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=2500)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--sensors", default="sphere8,ellipsoid8")
    parser.add_argument("--max-epochs", type=int, default=TrainConfig().max_epochs)
    parser.add_argument("--output", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--smoke", action="store_true", help="tiny datasets (sphere8 only), one seed, two epochs: for the tests")
    parser.add_argument("--compare", type=Path, default=Path(__file__).parent / "results" / f"{NAME}_cones.json",
                        help="another run's ablation_table1.json to set beside this one's table (default: the committed run under the cones, if there)")
    args = parser.parse_args()
    smoke = {}
    if args.smoke:
        args.events, args.seeds, args.sensors, args.max_epochs = 12, 1, "sphere8", 2
        smoke = {"sequence_length": 64, "burn_in": 32, "batch_size": 8}
    output = args.output
    work = output / f"{NAME}.work"
    work.mkdir(parents=True, exist_ok=True)
    records = output / f"{NAME}.runs"
    records.mkdir(exist_ok=True)
    settings = {"events": args.events, "max_epochs": args.max_epochs, "smoke": args.smoke, "material": MATERIAL, "aged": AGED}
    started = time.perf_counter()
    runs, timings, swing = [], {}, {}
    sensors = [name for name in args.sensors.split(",") if name]
    trained_for_ageing = ageing_settings = ageing = None
    for sensor_name in sensors:
        sensor = load_sensor(sensor_name)
        t = time.perf_counter()
        dataset = load_dataset(_dataset(work / f"{sensor_name}_dataset", sensor_name, MATERIAL, args.events, args.smoke))
        timings[f"generate {sensor_name}"] = time.perf_counter() - t
        swing[sensor_name] = dict(zip(dataset.channels, dataset.manifest["statistics"]["channel_std_Pa"]))
        radius = calc_skin_radius(sensor)
        rate = float(dataset.manifest["config"]["rate_hz"])
        # Records are read back only for this very dataset (its request and its shards' bytes).
        dataset_settings = settings | {"dataset": digest(json.dumps([dataset.manifest["request_digest"], dataset.manifest["shards"]], sort_keys=True))}
        for architecture, hidden, label in ROWS:
            for binned in (True, False):
                for seed in range(args.seeds):
                    config = TrainConfig(architecture=architecture, binned=binned, hidden=hidden, seed=seed, max_epochs=args.max_epochs, **smoke)
                    folder = work / f"{sensor_name}_{architecture}{'_' + '-'.join(map(str, hidden)) if hidden else ''}_{'binned' if binned else 'plain'}_{seed}"
                    record = records / f"{folder.name}.json"
                    ageing_needs_it = sensor_name == "sphere8" and architecture == "gru" and hidden is None and binned and seed == 0
                    if ageing_needs_it:  # the ageing test's record goes with this model's dataset
                        ageing_settings = dataset_settings
                        ageing = read_record(records / "ageing.json", ageing_settings)
                    if (run := read_record(record, dataset_settings)) is not None and not (ageing_needs_it and ageing is None):
                        runs.append(run)
                        print(f"{sensor_name} {label} {'binned' if binned else 'plain'} seed {seed}: read back from {record}", flush=True)
                        continue
                    folder.mkdir(exist_ok=True)
                    t = time.perf_counter()
                    trained = train_estimator(dataset, sensor, config, folder=folder)
                    seconds = time.perf_counter() - t
                    save_estimator(trained, folder, sensor_name)  # a model folder, as from hydrotact train (fine_tuning_curve.py starts from one)
                    result = evaluate_estimator(trained, dataset.blocks("test"), rate, radius)
                    error_map = calc_error_map(result["location_errors"], sensor.theta_range, sensor.phi_range)
                    runs.append({
                        "sensor": sensor_name, "row": label, "architecture": architecture, "hidden": list(trained.spec.hidden), "binned": binned,
                        "seed": seed, "parameters": count_parameters(trained.spec), "epochs": len(trained.history), "best_epoch": trained.best_epoch,
                        "train_seconds": sum(e["seconds"] for e in trained.history), "wall_seconds": seconds,
                        "metrics": result["metrics"], "detection": {k: v["accuracy"] for k, v in result["detection"].items()},
                        "error_map": {k: np.asarray(v).tolist() for k, v in error_map.items() if k in ("theta_edges", "phi_edges", "count")}
                        | {"mean": [[None if np.isnan(x) else float(x) for x in row] for row in error_map["mean"]], "unit": error_map["unit"]},
                    })
                    write_record(record, dataset_settings, runs[-1])
                    print(f"{sensor_name} {label} {'binned' if binned else 'plain'} seed {seed}: {runs[-1]['parameters']} parameters, "
                          + ", ".join(f"{k} {v:.3g}" for k, v in result["metrics"].items()), flush=True)
                    if ageing_needs_it:
                        trained_for_ageing = (trained, dataset)
    if ageing is None and trained_for_ageing is not None:
        trained, dataset = trained_for_ageing
        aged = load_dataset(_dataset(work / "sphere8_aged_dataset", "sphere8", AGED, args.events, args.smoke))
        shift = _tare(aged, dataset)
        rate = float(aged.manifest["config"]["rate_hz"])
        radius = calc_skin_radius(load_sensor("sphere8"))
        tared = [block | {name: block[name] - s for name, s in zip(trained.channels, shift)} for block in aged.blocks("test")]
        ageing = {
            "material": {"fresh": MATERIAL, "aged": AGED}, "tare_Pa": shift.tolist(),
            "fresh": evaluate_estimator(trained, dataset.blocks("test"), rate, radius)["metrics"],
            "aged_untared": evaluate_estimator(trained, aged.blocks("test"), rate, radius)["metrics"],
            "aged_tared": evaluate_estimator(trained, tared, rate, radius)["metrics"],
        }
        write_record(records / "ageing.json", ageing_settings, ageing)
    table = _table(runs)
    document = {
        "settings": {"events": args.events, "seeds": args.seeds, "sensors": sensors, "max_epochs": args.max_epochs, "smoke": args.smoke, "material": MATERIAL},
        "runs": runs, "table": table, "ageing": ageing, "timings_s": timings | {"total": time.perf_counter() - started},
        "budgets": {s: {label: count_parameters(make_estimator_spec(load_sensor(s), a, True, h)) for a, h, label in ROWS} for s in sensors},
        "channel_swing_Pa": swing,
    }
    output.mkdir(parents=True, exist_ok=True)
    write_text_atomic(output / f"{NAME}.json", json.dumps(document, indent=2) + "\n")
    summary = (f"{args.events} events per dataset, {args.seeds} seed(s), at most {args.max_epochs} epochs{' (smoke)' if args.smoke else ''}; "
               f"{document['timings_s']['total'] / 60:.0f} min in this invocation (datasets and models read back from the work folder or the records not counted).")
    write_text_atomic(output / f"{NAME}.md", summary + " " + _markdown(table, ageing) + _swing_markdown(swing))
    if args.compare is not None and args.compare.is_file():
        other = json.loads(args.compare.read_text())
        write_text_atomic(output / f"{NAME}_models.md", side_by_side(table, other["table"], args.compare.name))
        print(f"written {output / NAME}_models.md (this run beside {args.compare})")
    _plot(table, output / f"{NAME}.png")
    for sensor_name in sensors:
        _plot_error_maps(runs, sensor_name, output / f"{NAME}_error_map_{sensor_name}.png")
    print(summary + " " + _markdown(table, ageing))
    print(f"written {output / NAME}.json, .md, .png, _error_map_*.png")


def _table(runs: list) -> list:
    rows = {}
    for run in runs:
        rows.setdefault((run["sensor"], run["row"], run["binned"]), []).append(run)
    table = []
    for (sensor, label, binned), members in rows.items():
        entry = {"sensor": sensor, "row": label, "binned": binned, "parameters": members[0]["parameters"], "seeds": len(members)}
        table.append(entry | summarise_metrics(members, METRICS))
    return table


def summarise_metrics(runs: list, names) -> dict:
    """{metric: {"mean", "std"}} over `runs` (the seeds of one row), for each of
    `names` that the runs report."""
    summary = {}
    for name in names:
        values = [run["metrics"][name] for run in runs if name in run["metrics"]]
        if values:
            summary[name] = {"mean": float(np.mean(values)), "std": float(np.std(values))}
    return summary


def _markdown(table: list, ageing) -> str:
    head = "| sensor | model | angles | parameters | " + " | ".join(METRICS) + " |\n|---|---|---|---:|" + "---:|" * len(METRICS) + "\n"
    cell = lambda e, n: f"{e[n]['mean']:.3g} ± {e[n]['std']:.2g}" if n in e else "-"
    body = "".join(f"| {e['sensor']} | {e['row']} | {'binned' if e['binned'] else 'plain'} | {e['parameters']} | " + " | ".join(cell(e, n) for n in METRICS) + " |\n" for e in table)
    text = "RMSE in N (forces) and rad (angles); arc length in m; mean ± standard deviation over seeds.\n\n" + head + body
    if ageing:
        cases = [(k, ageing[k]) for k in ("fresh", "aged_untared", "aged_tared")]
        text += "\nAgeing (sphere8, binned GRU, seed 0): " + "; ".join(f"{k}: Fn RMSE {v['fn_rmse']:.3g} N, theta RMSE {v['theta_rmse']:.3g} rad" for k, v in cases) + "\n"
    return text


def _swing_markdown(swing: dict) -> str:
    """Each dataset's channel swing (std over the session), beside the paper's 3-9 kPa."""
    lines = [f"- {sensor}: " + ", ".join(f"{name} {1e-3 * value:.2f}" for name, value in channels.items()) for sensor, channels in swing.items()]
    return "\nChannel swing (each channel's standard deviation over the session, kPa; the paper's sensor: 3-9 kPa):\n" + "\n".join(lines) + "\n"


SIDE_BY_SIDE = {"theta_rmse": "θ (rad)", "phi_rmse": "φ (rad)", "arc_length_mean": "arc (mm)", "fn_rmse": "Fn (N)", "contact_bce": "contact BCE"}


def side_by_side(table: list, other: list, other_name: str) -> str:
    """This run's table beside another's (`other`, e.g. the run under the cones), row by
    row: each metric's mean over seeds as "this / other". Rows pair by sensor (a
    "-cones" suffix dropped, so sphere8 meets sphere8-cones), model and angle head."""
    def key(entry):
        return entry["sensor"].removesuffix("-cones"), entry["row"], entry["binned"]

    others = {key(entry): entry for entry in other}
    unit = {"arc_length_mean": 1e3}
    head = "| sensor | model | angles | " + " | ".join(SIDE_BY_SIDE.values()) + " |\n|---|---|---|" + "---:|" * len(SIDE_BY_SIDE) + "\n"
    def mean(entry, name):
        return f"{unit.get(name, 1.0) * entry[name]['mean']:.3g}" if entry is not None and name in entry else "-"

    body = ""
    for entry in table:
        match = others.get(key(entry))
        cells = " | ".join(f"{mean(entry, name)} / {mean(match, name)}" for name in SIDE_BY_SIDE)
        body += f"| {key(entry)[0]} | {entry['row']} | {'binned' if entry['binned'] else 'plain'} | {cells} |\n"
    return f"Held-out errors, mean over seeds: this run / {other_name}.\n\n" + head + body


def _plot(table: list, path: Path) -> None:
    from matplotlib.figure import Figure

    labels = [f"{e['sensor']}\n{e['row']}\n{'binned' if e['binned'] else 'plain'}" for e in table]
    figure = Figure(figsize=(max(8.0, 0.9 * len(table) + 3), 4.5))
    axes = figure.subplots(1, 2)
    x = np.arange(len(table))
    for axis, names, unit in ((axes[0], ("fx_rmse", "fy_rmse", "fz_rmse", "fn_rmse"), "N"), (axes[1], ("theta_rmse", "phi_rmse"), "rad")):
        for k, name in enumerate(names):
            means = [e[name]["mean"] if name in e else np.nan for e in table]
            spread = [e[name]["std"] if name in e else 0.0 for e in table]
            axis.bar(x + (k - len(names) / 2 + 0.5) * 0.8 / len(names), means, 0.8 / len(names), yerr=spread, label=name.removesuffix("_rmse"))
        axis.set_xticks(x, labels, fontsize=6)
        axis.set_ylabel(f"held-out RMSE ({unit})")
        axis.legend(fontsize=7)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=130)


def _plot_error_maps(runs: list, sensor: str, path: Path) -> None:
    """The paper's Fig. 5 for one sensor: each row's mean localisation error over the
    skin (its seeds' contacts pooled)."""
    from hydrotact.viz import plot_error_maps

    maps = {}
    for run in runs:
        if run["sensor"] != sensor:
            continue
        entry = run["error_map"]
        mean, count = np.array(entry["mean"], dtype=float), np.asarray(entry["count"])
        label = f"{run['row']}, {'binned' if run['binned'] else 'plain'}"
        total = maps.setdefault(label, {"theta_edges": np.asarray(entry["theta_edges"]), "phi_edges": np.asarray(entry["phi_edges"]), "sum": 0.0, "count": 0, "unit": entry["unit"]})
        total["sum"] = total["sum"] + np.nan_to_num(mean) * count
        total["count"] = total["count"] + count
    for total in maps.values():
        with np.errstate(invalid="ignore", divide="ignore"):
            total["mean"] = np.where(total["count"] > 0, total.pop("sum") / np.maximum(total["count"], 1), np.nan)
    plot_error_maps(maps, path, title=f"{sensor}: localisation error over the skin (Fig. 5), held-out contacts, seeds pooled")


if __name__ == "__main__":
    sys.exit(main())
