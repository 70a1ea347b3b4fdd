"""Fine-tuning a pretrained estimator on a few minutes of a real sensor's logs, against
training the same model from scratch on them: the gain as a curve over the size of the
small set.

The pretrained model is the binned GRU of `ablation_table1.py` (sphere8, seed 0,
trained on its 2500-event dataset of a 10 MPa silicone; `--pretrained` names another
model folder). A simulated sensor stands in for the user's real one: sphere8 cast in
another, much softer silicone (E(0) 2.2 MPa: E∞ 1.2 MPa, one 1 MPa term at 1.5 s), with
its own channel gains (±10 %), offsets (±300 Pa) and barometer positions (jittered by
0.3 mm), its own events. Its training split is cut into recordings of
`--recording-seconds` and written and read back as logs in the log schema (with
labels, as from a gantry with a force sensor); its held-out blocks are the validation
logs. For each size (a number of recordings) and seed, `fine_tune_estimator` continues
the pretrained model on the first recordings, and the same call from a fresh
initialisation (the seed's) is the scratch baseline; both are evaluated on the held-out
logs (Table I's metrics and the best validation loss). Both train until the held-out
loss has not improved for the default patience (8 epochs), at most `--max-epochs`.

Outputs (in --output, default experiments/results/): `fine_tuning_curve.json` (every
run), `fine_tuning_curve.md` (the table) and `fine_tuning_curve.png` (validation loss,
Fn RMSE and θ RMSE against minutes of logs, tuned and scratch, mean and spread over
seeds). The stand-in dataset is kept under `fine_tuning_curve.work/`.

The smoke run leaves the barometers where they are: jittered, sphere8's eight elastic
fields are solved anew (minutes on a 2-core CPU; tests/test_elastic.py checks the jitter
on a coarse pad).

Run: `.venv/bin/python experiments/fine_tuning_curve.py [--sizes 1,2,4,8,16] [--seeds 3] [--smoke]`.
"""

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from ablation_table1 import SMOKE_REGIME  # noqa: E402  (its neighbour in experiments/: the same tiny regime)

from hydrotact._files import atomic_path, write_text_atomic  # noqa: E402
from hydrotact.data import BarometerLog, make_material_document, read_log, write_log, write_material  # noqa: E402
from hydrotact.datasets import DatasetConfig, generate_dataset, load_dataset  # noqa: E402
from hydrotact.models import (  # noqa: E402
    TrainConfig,
    calc_skin_radius,
    evaluate_estimator,
    fine_tune_estimator,
    init_estimator,
    load_estimator,
)
from hydrotact.sensors import load_sensor  # noqa: E402

NAME = "fine_tuning_curve"
STAND_IN_MATERIAL = (1.2e6, [1.0e6], [1.5])
VARIATION = dict(gain_spread=0.1, offset_spread=300.0, position_jitter=0.3e-3)
SMOKE_VARIATION = dict(VARIATION, position_jitter=0.0)  # no fields to solve anew (see above)
LABELS = ("fx", "fy", "fz", "fn", "theta", "phi", "contact")
METRICS = ("fn_rmse", "fx_rmse", "theta_rmse", "phi_rmse", "contact_bce", "arc_length_mean")


def _stand_in(folder: Path, events: int, smoke: bool):
    material = write_material(folder.parent / f"{folder.name}.material.json", make_material_document(*STAND_IN_MATERIAL, name="the stand-in's silicone"))
    config = DatasetConfig(events=events, seed=9, **(SMOKE_VARIATION if smoke else VARIATION), **(SMOKE_REGIME if smoke else {}))
    generate_dataset("sphere8", folder, material=material, config=config, progress=not smoke)
    return load_dataset(folder)


def _logs(dataset, folder: Path, recording_seconds: float) -> tuple[list, list]:
    """(training recordings cut to `recording_seconds`, held-out blocks), each written
    and read back as a log (the columns a real log with labels has)."""
    folder.mkdir(parents=True, exist_ok=True)
    metadata = {"format": "hydrotact.barometer_log", "version": 1, "sensor": "sphere8", "source": "simulated", "pressure": "absolute", "channels": list(dataset.channels)}
    names = ("time", *dataset.channels, *LABELS)
    rate = float(dataset.manifest["config"]["rate_hz"])
    length = int(round(recording_seconds * rate))
    pieces = {"train": [], "test": list(dataset.blocks("test", names))}
    for block in _contiguous(dataset.blocks("train", names), rate):
        pieces["train"] += [{name: block[name][start : start + length] for name in names} for start in range(0, len(block["time"]) - length + 1, length)]
    logs = {}
    for split, blocks in pieces.items():
        logs[split] = [read_log(write_log(folder / f"{split}-{k:03d}.parquet", BarometerLog(metadata, block))).columns for k, block in enumerate(blocks)]
    return logs["train"], logs["test"]


def _contiguous(blocks: list, rate: float) -> list:
    """The split's blocks with those that follow each other in the session joined
    (the split's blocks are pieces of one timeline; a recording is cut from one run)."""
    runs = []
    for block in blocks:
        if runs and abs(block["time"][0] - runs[-1]["time"][-1] - 1.0 / rate) < 0.25 / rate:
            runs[-1] = {name: np.concatenate([runs[-1][name], block[name]]) for name in block}
        else:
            runs.append(dict(block))
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    here = Path(__file__).parent
    parser.add_argument("--pretrained", type=Path, default=here / "results" / "ablation_table1.work" / "sphere8_gru_binned_0", help="a model folder")
    parser.add_argument("--events", type=int, default=240, help="the stand-in's events (default 240: about 13 min of logs)")
    parser.add_argument("--recording-seconds", type=float, default=30.0)
    parser.add_argument("--sizes", default="1,2,4,8,16", help="numbers of recordings to fine-tune on")
    parser.add_argument("--seeds", type=int, default=3)
    # A few recordings make one or two batches an epoch: scratch needs hundreds of
    # epochs to converge (both runs stop early, `patience` epochs past their best).
    parser.add_argument("--max-epochs", type=int, default=400)
    parser.add_argument("--output", type=Path, default=here / "results")
    parser.add_argument("--smoke", action="store_true", help="a tiny stand-in, sizes 1 and 2, one seed, two epochs: for the tests")
    args = parser.parse_args()
    smoke = {}
    if args.smoke:
        args.events, args.recording_seconds, args.sizes, args.seeds, args.max_epochs = 10, 1.0, "1,2", 1, 2
        smoke = {"sequence_length": 64, "burn_in": 32, "batch_size": 8}
    if not (args.pretrained / "model.json").is_file():
        sys.exit(f"--pretrained {args.pretrained}: no model.json (run experiments/ablation_table1.py first, or name a model folder from hydrotact train)")
    started = time.perf_counter()
    pretrained = load_estimator(args.pretrained)
    work = args.output / f"{NAME}.work"
    dataset = _stand_in(work / "stand_in_dataset", args.events, args.smoke)
    train, held_out = _logs(dataset, work / "logs", args.recording_seconds)
    sizes = [int(n) for n in args.sizes.split(",") if n and int(n) <= len(train)]
    if not sizes:
        sys.exit(f"the stand-in has {len(train)} training recordings of {args.recording_seconds} s: fewer than the smallest size")
    radius = calc_skin_radius(load_sensor("sphere8"))
    rate = float(dataset.manifest["config"]["rate_hz"])
    runs = []
    for size in sizes:
        for seed in range(args.seeds):
            config = TrainConfig(seed=seed, max_epochs=args.max_epochs, **smoke)
            for start, params in (("pretrained", pretrained.params), ("scratch", init_estimator(pretrained.spec, jax.random.PRNGKey(1000 + seed)))):
                t = time.perf_counter()
                tuned = fine_tune_estimator(dataclasses.replace(pretrained, params=params), train[:size], held_out, config)
                metrics = evaluate_estimator(tuned, held_out, rate, radius)["metrics"]
                runs.append({
                    "recordings": size, "minutes": size * args.recording_seconds / 60.0, "seed": seed, "start": start,
                    "best_validation_loss": min(entry["validation_loss"] for entry in tuned.history), "epochs": len(tuned.history),
                    "seconds": time.perf_counter() - t, "metrics": metrics,
                })
                print(f"{size} recordings, seed {seed}, {start}: validation loss {runs[-1]['best_validation_loss']:.4g}, "
                      + ", ".join(f"{k} {metrics[k]:.3g}" for k in METRICS if k in metrics), flush=True)
    # The pretrained model as it is, on the stand-in (its own normalisation): what fine-tuning starts from.
    untuned = evaluate_estimator(pretrained, held_out, rate, radius)["metrics"]
    curve = _curve(runs)
    document = {
        "settings": {"pretrained": str(args.pretrained), "events": args.events, "recording_seconds": args.recording_seconds, "sizes": sizes, "seeds": args.seeds,
                     "max_epochs": args.max_epochs, "smoke": args.smoke, "stand_in_material": STAND_IN_MATERIAL, "variation": SMOKE_VARIATION if args.smoke else VARIATION,
                     "training_recordings": len(train), "held_out_recordings": len(held_out)},
        "untuned_metrics": untuned, "runs": runs, "curve": curve, "seconds": time.perf_counter() - started,
    }
    args.output.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.output / f"{NAME}.json", json.dumps(document, indent=2) + "\n")
    write_text_atomic(args.output / f"{NAME}.md", _markdown(curve, untuned))
    _plot(curve, args.output / f"{NAME}.png")
    print(_markdown(curve, untuned))
    print(f"written {args.output / NAME}.json, .md, .png")


def _curve(runs: list) -> list:
    """Per size and start: the mean and standard deviation over seeds."""
    groups = {}
    for run in runs:
        groups.setdefault((run["recordings"], run["start"]), []).append(run)
    curve = []
    for (size, start), members in sorted(groups.items()):
        entry = {"recordings": size, "minutes": members[0]["minutes"], "start": start, "seeds": len(members)}
        values = {"best_validation_loss": [m["best_validation_loss"] for m in members]} | {k: [m["metrics"][k] for m in members if k in m["metrics"]] for k in METRICS}
        entry |= {k: {"mean": float(np.mean(v)), "std": float(np.std(v))} for k, v in values.items() if v}
        curve.append(entry)
    return curve


def _markdown(curve: list, untuned: dict) -> str:
    names = ("best_validation_loss", *METRICS)
    head = "| recordings | minutes | start | " + " | ".join(names) + " |\n|---:|---:|---|" + "---:|" * len(names) + "\n"
    cell = lambda e, n: f"{e[n]['mean']:.3g} ± {e[n]['std']:.2g}" if n in e else "-"
    body = "".join(f"| {e['recordings']} | {e['minutes']:.2g} | {e['start']} | " + " | ".join(cell(e, n) for n in names) + " |\n" for e in curve)
    before = ", ".join(f"{k} {untuned[k]:.3g}" for k in METRICS if k in untuned)
    return ("Held-out logs of the stand-in sensor; RMSE in N and rad, arc length in m; mean ± standard deviation over seeds. "
            f"The pretrained model before fine-tuning: {before}.\n\n" + head + body)


def _plot(curve: list, path: Path) -> None:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(12, 3.8))
    axes = figure.subplots(1, 3)
    for axis, name, label in zip(axes, ("best_validation_loss", "fn_rmse", "theta_rmse"), ("best validation loss", "Fn RMSE (N)", "θ RMSE (rad)")):
        for start, colour in (("pretrained", "tab:blue"), ("scratch", "tab:orange")):
            entries = [e for e in curve if e["start"] == start and name in e]
            minutes = [e["minutes"] for e in entries]
            mean = np.array([e[name]["mean"] for e in entries])
            spread = np.array([e[name]["std"] for e in entries])
            axis.plot(minutes, mean, "o-", color=colour, label="fine-tuned" if start == "pretrained" else "from scratch")
            axis.fill_between(minutes, mean - spread, mean + spread, color=colour, alpha=0.2)
        axis.set_xscale("log")
        ticks = sorted({e["minutes"] for e in curve})
        axis.set_xticks(ticks, [f"{m:g}" for m in ticks])
        axis.tick_params(axis="x", which="minor", labelbottom=False)
        axis.set_xlabel("minutes of the sensor's logs")
        axis.set_ylabel(label)
        axis.legend(fontsize=8)
    figure.suptitle("Fine-tuning the pretrained binned GRU against training from scratch, on a stand-in sensor's held-out logs", fontsize=9)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=130)


if __name__ == "__main__":
    sys.exit(main())
