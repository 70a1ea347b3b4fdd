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
    parser.add_argument("-o", "--output", type=Path, metavar="DIR", help="also write evaluation.json there")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    import json

    from .._files import write_text_atomic
    from ..models import calc_skin_radius, evaluate_estimator, load_estimator
    from ..sensors import load_sensor

    model = load_estimator(args.model)
    document = json.loads((args.model / "model.json").read_text())
    sensor = load_sensor(document["sensor"])
    radius = calc_skin_radius(sensor)
    report, everything = {"model": str(args.model)}, {}
    for name, blocks, rate in recordings(model, args.sources, args.split):
        result = evaluate_estimator(model, blocks, rate, radius)
        everything[name] = {"metrics": result["metrics"], "detection": result["detection"]}
        report |= {f"{name}: {k}": v for k, v in result["metrics"].items()}
        for detector, values in result["detection"].items():
            report[f"{name}: {detector} accuracy"] = values["accuracy"]
            report[f"{name}: {detector} onset latency median s"] = values["onset_latency"]["median_s"]
            report[f"{name}: {detector} release latency median s"] = values["release_latency"]["median_s"]
    if args.output is not None:
        args.output.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.output / "evaluation.json", json.dumps(everything, indent=2) + "\n")
        report["written"] = str(args.output / "evaluation.json")
    print_report("estimator evaluation", report, args.json)
