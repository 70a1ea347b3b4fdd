"""`hydrotact fit`: fit the elastomer's Prony material (and channel gains and offsets)
to barometer logs; print the parameters with standard errors.

`--lumped` is for a sensor nobody has modelled, pressed by a stage: the logs need the
stage's travel towards the skin (--indentation) and, when the probe moves between
presses, its position (--position-columns); see hydrotact.sysid.fit_press_logs."""

import json
from pathlib import Path

from .._errors import HydrotactError
from ._arguments import number


def add_parser(subparsers):
    parser = subparsers.add_parser("fit", help="fit the elastomer's Prony material (and channel gains and offsets) to barometer logs")
    parser.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="barometer logs (.parquet, or .csv with its .json or a --mapping); several are fitted jointly")
    parser.add_argument("--sensor", metavar="S", help="the sensor spec (built-in name or JSON file); default: the log's own")
    parser.add_argument(
        "--lumped", action="store_true",
        help="no sensor model: a stage pressed the skin at sites (positions that never change during a press); each channel's reading at a site is a law "
        "of the depth past the press's contact onset (fitted per press) through the relaxation, on a drifting baseline; the shape of E(t) is shared, "
        "its scale not identified (E_inf = 1); no --sensor needed",
    )
    parser.add_argument(
        "--indentation", default="indentation", metavar="COL",
        help="--lumped: the stage's travel towards the skin, m (not the depth: the onsets are fitted; default indentation)",
    )
    parser.add_argument(
        "--position-columns", default="stage_x,stage_y", metavar="COLS",
        help="--lumped: the stage position columns naming the sites (default stage_x,stage_y; absent ones are ignored: then one site per press)",
    )
    parser.add_argument(
        "--rig", type=Path, metavar="RIG.json",
        help="full mode for stage logs (no probe pose columns): the stage rig (data_schemas/rig.schema.json: the probe, the stage-to-sensor offsets, "
        "the home and the lag, each fixed or fitted within bounds); with --sensor or the logs' own",
    )
    parser.add_argument(
        "--drift", default=None, metavar="S|linear|none",
        help="each channel's baseline per log: cubic B-splines with knots S seconds apart, a line, or a constant "
        "(default: 30 s knots with --lumped or --rig, else a constant)",
    )
    parser.add_argument(
        "--drift-from", default="all", choices=("all", "unloaded"),
        help="--lumped: fit each baseline jointly with the laws over all samples (default), or from the samples out of contact alone "
        "(no relaxation can pass into the drift: a check that a slow term is not drift)",
    )
    parser.add_argument("--lag", type=number, default=0.0, metavar="S", help="--lumped: how far the pressures lag the logged stage, s (default 0; the start with --estimate-lag)")
    parser.add_argument("--estimate-lag", action="store_true", help="--lumped: fit the lag per log (within ±0.5 s)")
    parser.add_argument(
        "--saturation", type=number, metavar="PA",
        help="readings at or above this are clipped and masked (default: the part's upper limit for absolute logs of a known sensor; --lumped: flat maxima always)",
    )
    parser.add_argument(
        "--gains", choices=("fixed", "free", "relative"),
        help="full mode: each responding channel's gain: 1 (fixed), its own (free: needs force columns, which fix E's scale), or relative (their "
        "geometric mean 1: each barometer's own sensitivity, the mean is E's); default free with force columns, relative with --rig, else fixed",
    )
    parser.add_argument(
        "--press-threshold", type=number, default=0.05, metavar="F",
        help="--lumped: a press is where the travel is above its rest level by this fraction of its range (default 0.05)",
    )
    parser.add_argument(
        "--starts", default="auto", metavar="auto|N",
        help=(
            "--lumped: relaxation shapes to start from (the lowest chi2 is kept): auto (default) tries the next of 3 while the best ends above a reduced "
            "chi2 of 1.5, and stops when two end within 1 %% of each other (one minimum: the rest is the model's misfit); N (1-3) tries the first N"
        ),
    )
    parser.add_argument("--max-steps", type=int, metavar="N", help="solver steps before it stops (default 400; the minimisers 4000)")
    parser.add_argument("--mapping", type=Path, metavar="MAP.json", help="column mapping for logs of your own layout")
    parser.add_argument("--terms", default="auto", metavar="N|auto", help="Prony terms, or auto (default: the lowest BIC over 0-4 terms; with --lumped, 0-3 terms, auto over 1-3)")
    parser.add_argument("--solver", default="lm", choices=["lm", "gn", "dogleg", "bfgs", "lbfgsb"], help="lm (Levenberg-Marquardt, default), gn, dogleg, bfgs or lbfgsb (jaxopt, bounded)")
    parser.add_argument("--tare", action="store_true", help="tare each log on its no-load segments first (drifting, aged sensors)")
    parser.add_argument("--field", choices=["laplace", "distance"], help="full mode: the sensor's strain field (default: the log's, else laplace)")
    parser.add_argument("--rays", type=int, metavar="N", help="full mode: rays per taxel (default: the log's, else 64)")
    parser.add_argument("-o", "--output", required=True, type=Path, metavar="FITDIR", help="folder for material.json, report.json and plots")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    from ..sysid import LumpedFit, SimulatorFit, fit_logs, parse_drift, parse_starts
    from ..viz import plot_fit, plot_press_fit

    drift = parse_drift(args.drift if args.drift is not None else ("30" if args.lumped or args.rig else "none"))
    if args.lumped:
        if args.gains is not None:
            raise HydrotactError("--gains: a lumped fit has its own law per channel (no gains to fix or free); leave out --gains or --lumped")
        if args.rig is not None:
            raise HydrotactError("--rig: a lumped fit has no sensor model to place the probe on; leave out --lumped (a full fit of stage logs) or --rig")
        method = LumpedFit(
            sensor=args.sensor, indentation=args.indentation, position_columns=tuple(name for name in args.position_columns.split(",") if name),
            drift=drift, drift_from=args.drift_from, lag=args.lag, estimate_lag=args.estimate_lag, saturation_pa=args.saturation,
            threshold=args.press_threshold, starts=parse_starts(args.starts),
        )
    else:
        method = SimulatorFit(
            sensor=args.sensor, field=args.field, num_rays=args.rays, progress=not args.json, rig=args.rig, drift=drift,
            saturation_pa=args.saturation, gains=args.gains,
        )
    report = fit_logs(
        args.logs, args.output, method=method, mapping=args.mapping, terms=args.terms, solver=args.solver, tare=args.tare,
        plot=plot_press_fit if args.lumped else plot_fit, max_steps=args.max_steps,
    )
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        if args.lumped:
            print_press_table(report)
        else:
            print_fit_table(report)
        print(f"hydrotact fit: results in {args.output}/")
        for path in report["files"].values():
            print(f"  {path}")



def print_fit_table(report: dict, truth: dict | None = None) -> None:
    """Parameters ± standard errors as a table (with the truth, if known)."""
    from rich.console import Console
    from rich.table import Table

    relative = report.get("modulus_scale") == "relative"
    table = Table(title=f"fitted material ({report['mode']} mode, {report['num_terms']} Prony terms, {report['solver']}, reduced χ² {report['reduced_chi_square']:.3f})")
    table.add_column("parameter")
    if truth is not None:
        table.add_column("truth", justify="right")
    table.add_column("fitted", justify="right")
    table.add_column("± std. error", justify="right")
    table.add_column("rel.", justify="right")
    notes = {}

    def row(name, estimate, true=None, unit=""):
        value, std = estimate["value"], estimate["std"]
        cells = [name]
        if truth is not None:
            cells.append("" if true is None else f"{true:.6g}{unit}")
        if estimate.get("identified", True) and std is None:  # no finite standard error (report.json says null)
            cells += [f"{value:.6g}{unit}", "no finite error", ""]
        elif estimate.get("identified", True):
            cells += [f"{value:.6g}{unit}", f"{std:.3g}{unit}", f"{std / abs(value):.2%}" if value else ""]
        else:  # the solver's last word, not a measurement: no error bar that looks like one
            cells += [f"({value:.3g}{unit})", "NOT IDENTIFIED", ""]
            notes.setdefault(estimate.get("note", ""), []).append(name)
        table.add_row(*cells)

    pa = "" if relative else " Pa"
    row("E∞ (long-term)" if not relative else "E∞ (relative, ≡ 1)", report["long_term_modulus_Pa"], truth and truth.get("long_term_modulus"), pa)
    for k, term in enumerate(report["prony_terms"]):
        row(f"E{k + 1}", term["modulus_Pa"], truth and _get(truth, "moduli", k), pa)
        row(f"τ{k + 1}", term["tau_s"], truth and _get(truth, "taus", k), " s")
    row("E0 (instantaneous)", report["instantaneous_modulus_Pa"], truth and truth.get("instantaneous_modulus"), pa)
    for name, gain in list(report["gains"].items())[:8]:
        row(f"gain {name}", gain, truth and truth.get("gains", {}).get(name))
    if len(report["gains"]) > 8:
        table.add_row(f"... {len(report['gains']) - 8} more gains in report.json", *[""] * (len(table.columns) - 1))
    for name, estimate in report.get("rig", {}).items():
        if estimate["fitted"]:
            unit = " s" if name == "lag_s" else "" if name.startswith("slope_x") else " mm"
            scaled = estimate if unit != " mm" else {**estimate, "value": 1e3 * estimate["value"], "std": None if estimate["std"] is None else 1e3 * estimate["std"]}
            row(f"rig {name.removesuffix('_s')}", scaled, truth and truth.get("rig", {}).get(name), unit)
    Console().print(table)
    for note, names in notes.items():
        print(f"  not identified: {', '.join(names)}: {note}")


def print_press_table(report: dict) -> None:
    """A lumped fit's shape, lags and fit statistics; parameters the data do not
    identify are marked so, not printed as exact."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"lumped press fit ({report['num_terms']} Prony terms, {report['solver']}, reduced χ² {report['reduced_chi_square']:.3f}; E∞ ≡ 1)")
    for column in ("parameter", "fitted", "± std. error", ""):
        table.add_column(column, justify="left" if column in ("parameter", "") else "right")

    def row(name, entry, unit=""):
        note = "" if entry["identified"] else f"NOT IDENTIFIED: {entry.get('note', '')}"
        table.add_row(name, f"{entry['value']:.6g}{unit}", "no finite error" if entry["std"] is None else f"{entry['std']:.3g}{unit}", note)

    for k, term in enumerate(report["prony_terms"]):
        row(f"E{k + 1}/E∞", term["ratio"])
        row(f"τ{k + 1}", term["tau_s"], " s")
    for log in report["logs"][:8]:
        if log["lag_s"].get("note") != "given":
            row(f"lag {log['source']}", log["lag_s"], " s")
    Console().print(table)
    if report.get("num_starts", 1) > 1:
        ends = ", ".join(f"{c:,.6g}" for c in report.get("start_chi_squares", []))
        print(f"  fitted from {report['num_starts']} relaxation shapes (--starts; χ² at their ends {ends}); the lowest χ² is kept")
    for entry in report["residuals"]:
        cells = ", ".join(f"{name} {c['rms_Pa']:.3g} Pa (R² {c['r2']:.5f})" for name, c in entry["channels"].items() if c["rms_Pa"] is not None)
        print(f"  {entry['source']}: RMS residual {cells}")


def _get(truth, key, k):
    values = truth.get(key)
    return None if values is None or k >= len(values) else values[k]
