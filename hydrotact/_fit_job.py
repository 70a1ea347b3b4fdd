"""The `hydrotact fit` job: barometer logs -> a fitted material, a report and plots.

Everything the user gave is read and checked before anything is written; the outputs
(material.json, report.json, PNGs) are each written atomically into the output folder.
Unit responses of full-mode fits are cached (they are the expensive part), so a second
fit of the same logs with other options starts at once.
"""

import warnings
from pathlib import Path

from ._errors import HydrotactError
from .sysid import MAX_AUTO_TERMS, SOLVERS


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


def read_logs(paths, mapping=None, sensor=None, report_warning=None):
    """Read and check every log first (one error line, nothing written)."""
    from .data import LogWarning, read_log

    if not paths:
        raise HydrotactError("no logs given")
    logs = []
    for path in paths:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LogWarning)
            logs.append(read_log(path, mapping, sensor=sensor))
        for warning in caught:
            if issubclass(warning.category, LogWarning) and report_warning is not None:
                report_warning(str(warning.message))
            else:
                warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    return logs


def run_fit(paths, output, *, sensor=None, lumped=False, indentation="indentation", mapping=None, terms="auto", solver="lm", tare=False, field=None, num_rays=None, progress=True, report_warning=None) -> dict:
    """Fit the logs at `paths` and write material.json, report.json and plots into
    `output`. With `tare`, each log is first tared on its no-load segments (found
    automatically; the baseline interpolated in time between them), which takes out
    the slow drift of aged sensors that constant offsets cannot. Returns the report
    (with `files`)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from .sysid import fit_auto, fit_problem, make_fit_problem, write_fit_outputs

    output = Path(output)
    if output.exists() and not output.is_dir():
        raise HydrotactError(f"{output}: exists and is not a folder; -o names the folder the fit writes into")
    if solver not in SOLVERS:
        raise HydrotactError(f"--solver: unknown solver {solver!r}; use one of {', '.join(SOLVERS)}")
    terms = parse_terms(terms)
    logs = read_logs([Path(p) for p in paths], mapping, sensor, report_warning)
    if tare:
        from .data import tare_log

        logs = [tare_log(log, source=str(path))[0] for log, path in zip(logs, paths)]
    mode = "lumped" if lumped else "full"
    problem = make_fit_problem(logs, mode=mode, indentation=indentation, field=field, num_rays=num_rays, sources=[str(p) for p in paths], progress=progress)
    counts = list(range(MAX_AUTO_TERMS + 1)) if terms == "auto" else [terms]
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total} fits"), TimeElapsedColumn(), transient=True, disable=not progress) as bar:
        task = bar.add_task(f"fitting ({solver})", total=len(counts))
        if terms == "auto":
            result = fit_auto(problem, SOLVERS[solver](), progress=lambda k: bar.update(task, advance=1, description=f"fitting ({solver}): {k} terms done"))
        else:
            result = fit_problem(problem, terms, SOLVERS[solver]())
            bar.update(task, advance=1)
    if not result.converged:
        message = f"the {solver} solver stopped before converging ({result.num_steps} steps); the numbers below are its last iterate"
        if report_warning is not None:
            report_warning(message)
    report = write_fit_outputs(result, output, paths=[str(p) for p in paths])
    return report


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
