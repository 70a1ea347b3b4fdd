"""`hydrotact evaluate`: a trained estimator's Table I metrics and contact detection on
datasets and labelled logs (hydrotact.models.evaluate_estimator)."""

from pathlib import Path

from ._estimates import recordings
from ._output import print_report


def add_parser(subparsers):
    parser = subparsers.add_parser(
        "evaluate", help="a trained estimator's Table I metrics and contact detection on datasets or logs",
        description="Runs the estimator over each recording from the zero state (a dataset's split, each block on its own; or a log with "
        "labels) and reports the barometric estimation paper's Table I metrics, the arc-length error on a sphere, and two contact "
        "detectors (the contact head; the predicted force over 0.1 N) with their onset and release latencies.",
    )
    parser.add_argument("model", type=Path, metavar="MODEL", help="a model folder from hydrotact train")
    parser.add_argument("sources", type=Path, nargs="+", metavar="DATASET|LOG", help="dataset folders (hydrotact generate) or labelled logs")
    parser.add_argument("--split", choices=("test", "train", "all"), default="test", help="which split of a dataset (default test, the held-out one)")
    parser.add_argument(
        "-o", "--output", type=Path, metavar="DIR",
        help="also write there evaluation.json and, per source, the localisation error over the skin (error_map_NAME.png, the paper's "
        "Fig. 5; sensors with contact angles) and the two contact detectors over a stretch of it (contact_detection_NAME.png, its Fig. 7)",
    )
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    import json

    from .._files import check_output, write_text_atomic
    from ..models import calc_skin_radius, evaluate_estimator, load_estimator
    from ..sensors import load_sensor

    if args.output is not None:
        check_output(args.output, directory=True, what="the evaluation")
    model = load_estimator(args.model)
    document = json.loads((args.model / "model.json").read_text())
    sensor = load_sensor(document["sensor"])
    radius = calc_skin_radius(sensor)
    report, everything, stems = {"model": str(args.model)}, {}, set()
    for name, blocks, rate in recordings(model, args.sources, args.split):
        result = evaluate_estimator(model, blocks, rate, radius)
        everything[name] = {"metrics": result["metrics"], "detection": result["detection"]}
        if args.output is not None:
            everything[name]["pictures"] = _pictures(args.output, _stem(name, stems), sensor, model, blocks, rate, result)
        report |= {f"{name}: {k}": v for k, v in result["metrics"].items()}
        for detector, values in result["detection"].items():
            report[f"{name}: {detector} accuracy"] = values["accuracy"]
            report[f"{name}: {detector} onset latency median s"] = values["onset_latency"]["median_s"]
            report[f"{name}: {detector} release latency median s"] = values["release_latency"]["median_s"]
    if args.output is not None:
        args.output.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.output / "evaluation.json", json.dumps(everything, indent=2) + "\n")
        report["written"] = ", ".join([str(args.output / "evaluation.json")] + [p for entry in everything.values() for p in entry["pictures"]])
    print_report("estimator evaluation", report, args.json)


DETECTION_SECONDS = 20.0  # the stretch contact_detection_NAME.png shows, from 1 s before the first contact


def _stem(name: str, taken: set) -> str:
    """A file-name stem for a source's pictures (added to `taken`): its base name,
    numbered when an earlier source of this run had the same one (two datasets both
    called `dataset`)."""
    import re

    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(name).name.removesuffix(".parquet")) or "source"
    stem, count = base, 2
    while stem in taken:
        stem, count = f"{base}_{count}", count + 1
    taken.add(stem)
    return stem


def _pictures(folder, stem, sensor, model, blocks, rate, result) -> list:
    """Write one source's error map and contact-detection plot; their paths."""
    import numpy as np

    from ..models import CONTACT_FORCE, calc_error_map
    from ..viz import plot_contact_detection, plot_error_maps

    folder.mkdir(parents=True, exist_ok=True)
    written = []
    if result["location_errors"] is not None:
        label = f"{model.spec.architecture} {'binned' if model.spec.binned else 'plain'}"
        error_map = calc_error_map(result["location_errors"], sensor.theta_range, sensor.phi_range)
        plot_error_maps({label: error_map}, folder / f"error_map_{stem}.png", title=f"{stem}: localisation error over the skin")
        written.append(str(folder / f"error_map_{stem}.png"))
    block, predicted = max(zip(blocks, result["predictions"]), key=lambda pair: int(np.sum(pair[0]["contact"] > 0)))
    touching = np.flatnonzero(np.asarray(block["contact"]) > 0)
    first = max(0, int(touching[0]) - int(rate)) if len(touching) else 0
    window = slice(first, first + int(DETECTION_SECONDS * rate))
    times = block["time"] if "time" in block else np.arange(len(block["contact"])) / rate
    forces = ("fx", "fy", "fz")
    if all(k in block for k in forces):
        signal, label = np.linalg.norm(np.column_stack([block[k] for k in forces]), axis=1), "|F| (N)"
    else:  # a stage log labelled by its rig: no force, its depth
        signal, label = 1e3 * np.nan_to_num(np.asarray(block.get("depth", np.zeros(len(times))), dtype=float)), "depth (mm)"
    estimate = np.linalg.norm(np.column_stack([predicted[k] for k in forces]), axis=1)[window] if all(k in predicted for k in forces) else None
    plot_contact_detection(
        np.asarray(times)[window], signal[window], np.asarray(block["contact"])[window], predicted["contact_probability"][window], estimate,
        folder / f"contact_detection_{stem}.png", threshold=CONTACT_FORCE, title=f"{stem}: contact detection", signal=label,
    )
    written.append(str(folder / f"contact_detection_{stem}.png"))
    return written
