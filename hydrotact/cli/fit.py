"""`hydrotact fit`: fit the elastomer's Prony material (and channel gains and offsets)
to barometer logs; print the parameters with standard errors."""

import json
import sys
from pathlib import Path


def add_parser(subparsers):
    parser = subparsers.add_parser("fit", help="fit the elastomer's Prony material (and channel gains and offsets) to barometer logs")
    parser.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="barometer logs (.parquet, or .csv with its .json or a --mapping); several are fitted jointly")
    parser.add_argument("--sensor", metavar="S", help="the sensor spec (built-in name or JSON file); default: the log's own")
    parser.add_argument("--lumped", action="store_true", help="no sensor model: each channel a power law of the indentation column, fitted with the kernel")
    parser.add_argument("--indentation", default="indentation", metavar="COL", help="the indentation column of a --lumped fit (default indentation)")
    parser.add_argument("--mapping", type=Path, metavar="MAP.json", help="column mapping for logs of your own layout")
    parser.add_argument("--terms", default="auto", metavar="N|auto", help="Prony terms, or auto (lowest BIC over 0-4; default)")
    parser.add_argument("--solver", default="lm", choices=["lm", "gn", "dogleg", "bfgs", "lbfgsb"], help="lm (Levenberg-Marquardt, default), gn, dogleg, bfgs or lbfgsb (jaxopt, bounded)")
    parser.add_argument("--tare", action="store_true", help="tare each log on its no-load segments first (drifting, aged sensors)")
    parser.add_argument("--field", choices=["laplace", "distance"], help="full mode: the sensor's strain field (default: the log's, else laplace)")
    parser.add_argument("--rays", type=int, metavar="N", help="full mode: rays per taxel (default: the log's, else 64)")
    parser.add_argument("-o", "--output", required=True, type=Path, metavar="FITDIR", help="folder for material.json, report.json and plots")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    return parser


def run(args) -> None:
    from ..sysid import fit_logs
    from ..viz import plot_fit

    report = fit_logs(
        args.logs, args.output, sensor=args.sensor, lumped=args.lumped, indentation=args.indentation, mapping=args.mapping,
        terms=args.terms, solver=args.solver, tare=args.tare, field=args.field, num_rays=args.rays, progress=not args.json,
        report_warning=_warn, plot=plot_fit,
    )
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print_fit_table(report)
        print(f"hydrotact fit: results in {args.output}/")
        for path in report["files"].values():
            print(f"  {path}")


def _warn(message: str) -> None:
    print(f"hydrotact: warning: {message}", file=sys.stderr)


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

    def row(name, estimate, true=None, unit=""):
        value, std = estimate["value"], estimate["std"]
        cells = [name]
        if truth is not None:
            cells.append("" if true is None else f"{true:.6g}{unit}")
        cells += [f"{value:.6g}{unit}", f"{std:.3g}{unit}", f"{std / abs(value):.2%}" if value else ""]
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
    Console().print(table)


def _get(truth, key, k):
    values = truth.get(key)
    return None if values is None or k >= len(values) else values[k]
