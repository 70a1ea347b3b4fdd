"""`hydrotact compare`: predict held-out stage logs from a lumped fit or a full-mode
fit through a rig (everything but each log's baseline and home fixed) and report how
close the prediction comes."""

import json
from pathlib import Path


def add_parser(subparsers):
    parser = subparsers.add_parser("compare", help="predict held-out logs from a lumped or rig fit and compare (RMS, R², hold shape)")
    parser.add_argument(
        "fit_dir", type=Path, metavar="FITDIR",
        help="the folder `hydrotact fit --lumped` (its material.json carries the channel law) or `hydrotact fit --rig` (its rig_table.npz) wrote",
    )
    parser.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="stage logs of the same sensor and stage (.parquet, or .csv with its .json or a --mapping)")
    parser.add_argument("--mapping", type=Path, metavar="MAP.json", help="column mapping for logs of your own layout")
    parser.add_argument(
        "--tare", default="no-load", metavar="no-load|first:S|all",
        help=(
            "each log's baseline: fitted to its samples the model says are unloaded (default: between presses, and in presses where "
            "a channel's push is 0), the mean of its first S seconds, or fitted to all samples (the fit's own)"
        ),
    )
    parser.add_argument(
        "--home", default="estimate", choices=("estimate", "fit"),
        help="the stage's home (the travel column's zero) differs between sessions: fit it to each log (default: one shift of every onset, or a rig fit's home), "
        "or use the fit's (its onsets; a rig fit's home for its own logs, else their mean)",
    )
    parser.add_argument(
        "--labels", action="store_true",
        help="a rig fit only: also write each log with an estimator's labels (contact, contact_x, contact_y, depth: where the fitted rig "
        "put the probe and the fitted model's force) as NAME_labelled.parquet, for hydrotact evaluate and fine-tuning",
    )
    parser.add_argument("-o", "--output", required=True, type=Path, metavar="DIR", help="folder for compare.json, the predicted logs and plots")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    from ..sysid import compare_fit
    from ..viz import plot_comparisons

    report = compare_fit(args.fit_dir, args.logs, args.output, mapping=args.mapping, tare=args.tare, home=args.home, plot=plot_comparisons, labels=args.labels)
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for entry in report["logs"]:
        home = entry["home_shift_m"]
        shift = "" if home is None else f" (home shifted {home['value'] * 1e3:+.4f} ± {home['std'] * 1e3:.4f} mm from the fit's: its home)"
        print(f"{entry['source']}:{shift}")
        for name, c in entry["channels"].items():
            print(
                # the band is wide where the log presses and narrow at rest, so its RMS over the log says little of a
                # sample's: the normalized error is each sample's over its own √(noise² + band²), then the RMS
                f"  {name}: RMS {_fmt(c['rms_Pa'])} Pa (noise {_fmt(c['noise_Pa'])} Pa, prediction band RMS {_fmt(c['prediction_std_Pa'])} Pa; "
                f"per sample, error / √(noise² + band²) RMS {_fmt(c['normalized_rms'])}), R² {_fmt(c['r2'], '.5f')}, hold shape RMS {_fmt(c['hold_shape_rms_Pa'])} Pa"
            )
    print(f"hydrotact compare: results in {args.output}/")
    for path in report["files"].values():
        print(f"  {path}")


def _fmt(value, spec: str = ".3g") -> str:
    return "n/a" if value is None else format(value, spec)

