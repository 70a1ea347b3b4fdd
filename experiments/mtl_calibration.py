"""The MTL strip's calibration logs through the lumped fit, as a user runs it: each of
the six files fitted alone, the two groups of three fitted together (the vacuum logs;
the others), and each group predicting its own files left out one at a time (fitted
on the other two, compared with the third).

The data are a public strip sensor's (the MSc project `JiannnH/MTL-BaroTactileSensor`,
folder `Data_collection/tip1/`): pass the folder that holds the six logs with `--data`
(a checkout of that repository, or a folder with a `logs/` subfolder laid out alike).
Only the six calibration files named in CALIBRATION are read; the repository's other
logs of the strip are kept apart to judge the results and are never opened here.
Nothing of the data goes into this repository: the committed results are the table.

Every fit and comparison runs the command line in a fresh process (`hydrotact fit
--lumped`, `hydrotact compare`), so the wall times are what a user waits, cold: the
interpreter, JAX's import and the compilations included (the persistent compilation
cache is off). The column mapping (the strip's units, from the data's README: `z` in
motor steps of 1/480 mm towards the skin, `x` in µm, absolute pressures in Pa, 16.4 Hz)
is written beside the results; the fit is `--lumped --position-columns stage_x
--estimate-lag --terms 3 --saturation 140500` (the README: the barometers clip near
141.3 kPa); a comparison tares each channel on the log's own unloaded samples of its
first 20 s (`--tare first:20`, before its first press).

Outputs (in --output, default experiments/results/): `mtl_calibration.json` (per case:
the files, each log's and channel's RMS, the pooled RMS over Sensor_1-3 and the logs
(the root mean square of the per-log, per-channel RMS), the hold-shape RMS of a
comparison, the fitted Prony shape, the wall time) and `mtl_calibration.md` (the
table). The fits' and comparisons' own folders are kept under `mtl_calibration.work/`:
a case whose folder holds its finished report is read back, so an interrupted run
resumes.

Run: `.venv/bin/python experiments/mtl_calibration.py --data PATH [--output DIR] [--cases single,group,leave-one-out]`.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hydrotact._files import write_text_atomic  # noqa: E402

NAME = "mtl_calibration"
GROUPS = {
    "non-vacuum": ("zv1_zd6_t8_20230622_174706", "zv1_zd5_t0_20230622_181109", "zv05_zd5_t8_20230622_185843"),
    "vacuum": ("vac_zv1_zd6_t8_20230626_145851", "vac_zv1_zd6_t0_20230626_153114", "vac_zv05_zd6_t0_20230626_160519"),
}
CALIBRATION = tuple(name for group in GROUPS.values() for name in group)
SCORED = ("Sensor_1", "Sensor_2", "Sensor_3")
MAPPING = {
    "format": "hydrotact.column_mapping",
    "version": 1,
    "description": "MTL strip logs: four MPL3115A2 channels in Pa; stage z in motor steps (480 per mm, towards the skin), x in um.",
    "pressure": "absolute",
    "rate_hz": 16.4,
    "time": {"column": "time", "unit": "s"},
    "channels": {"columns": ["Sensor_0", "Sensor_1", "Sensor_2", "Sensor_3"], "unit": "Pa"},
    "columns": {"indentation": {"column": "z", "unit": "step", "scale": 1.0 / 480e3}, "stage_x": {"column": "x", "unit": "um"}},
}
FIT = ("--lumped", "--position-columns", "stage_x", "--estimate-lag", "--terms", "3", "--saturation", "140500")
TARE = "first:20"


def find_logs(data: Path) -> dict:
    """{name: path} of the six calibration files under `data` (its `logs/` or
    `Data_collection/tip1/`); one line naming what is missing otherwise."""
    for folder in (data / "logs", data / "Data_collection" / "tip1", data):
        found = {name: folder / f"{name}.csv" for name in CALIBRATION if (folder / f"{name}.csv").is_file()}
        if len(found) == len(CALIBRATION):
            return found
    sys.exit(f"{data}: the six calibration logs ({', '.join(CALIBRATION)}.csv) are not all in logs/ or Data_collection/tip1/ there")


def make_cases(kinds) -> list:
    """[(case name, kind, files fitted, file compared or None)]."""
    cases = []
    if "single" in kinds:
        cases += [(f"single {name}", "single", (name,), None) for name in CALIBRATION]
    if "group" in kinds:
        cases += [(f"group {group}", "group", names, None) for group, names in GROUPS.items()]
    if "leave-one-out" in kinds:
        for group, names in GROUPS.items():
            for left in names:
                cases.append((f"{group} without {left}", "leave-one-out", tuple(n for n in names if n != left), left))
    return cases


def _run(command: list, log: Path) -> float:
    """Run a command line in a fresh process (its output to `log`); its wall time, s."""
    environment = dict(os.environ, JAX_ENABLE_COMPILATION_CACHE="false")
    environment.pop("JAX_COMPILATION_CACHE_DIR", None)
    started = time.perf_counter()
    with log.open("w") as handle:
        done = subprocess.run(command, stdout=handle, stderr=subprocess.STDOUT, env=environment, check=False)
    seconds = time.perf_counter() - started
    if done.returncode != 0:
        sys.exit(f"{' '.join(map(str, command))} exited {done.returncode}: see {log}")
    return seconds


def _pooled(rows) -> float | None:
    """The root mean square of per-log, per-channel RMS values (None left out)."""
    values = [value for value in rows if value is not None]
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else None


def _terms(report) -> list:
    """The fit's Prony terms: ratio, tau and whether both are identified."""
    return [
        {"ratio": term["ratio"]["value"], "tau_s": term["tau_s"]["value"], "identified": bool(term["ratio"]["identified"] and term["tau_s"]["identified"])}
        for term in report["prony_terms"]
    ]


def run_case(case, logs: dict, work: Path, mapping: Path) -> dict:
    name, kind, fitted, compared = case
    folder = work / name.replace(" ", "_")
    record = folder / "case.json"
    if record.is_file():
        result = json.loads(record.read_text())
        result["prony_terms"] = _terms(json.loads((folder / "fit" / "report.json").read_text()))  # records written before the flag
        return result
    folder.mkdir(parents=True, exist_ok=True)
    hydrotact = str(Path(sys.executable).parent / "hydrotact")
    seconds = _run([hydrotact, "fit", *(logs[n] for n in fitted), "--mapping", mapping, *FIT, "--output", folder / "fit"], folder / "fit.txt")
    report = json.loads((folder / "fit" / "report.json").read_text())
    result = {
        "case": name, "kind": kind, "fitted": list(fitted), "compared": compared, "fit_seconds": seconds,
        "reduced_chi_square": report["reduced_chi_square"],
        "prony_terms": _terms(report),
        "fit_rms_Pa": {Path(r["source"]).stem: {c: r["channels"].get(c, {}).get("rms_Pa") for c in SCORED} for r in report["residuals"]},
    }
    result["fit_pooled_rms_Pa"] = _pooled(v for log in result["fit_rms_Pa"].values() for v in log.values())
    if compared is not None:
        seconds = _run([hydrotact, "compare", folder / "fit", logs[compared], "--mapping", mapping, "--tare", TARE, "--output", folder / "compare"], folder / "compare.txt")
        channels = json.loads((folder / "compare" / "compare.json").read_text())["logs"][0]["channels"]
        result["compare_seconds"] = seconds
        result["compare_rms_Pa"] = {c: channels.get(c, {}).get("rms_Pa") for c in SCORED}
        result["compare_hold_shape_rms_Pa"] = {c: channels.get(c, {}).get("hold_shape_rms_Pa") for c in SCORED}
        result["compare_pooled_rms_Pa"] = _pooled(result["compare_rms_Pa"].values())
        result["compare_pooled_hold_shape_rms_Pa"] = _pooled(result["compare_hold_shape_rms_Pa"].values())
    write_text_atomic(record, json.dumps(result, indent=1) + "\n")
    return result


def markdown(results) -> str:
    def number(value, digits=0):
        return "n/a" if value is None else f"{value:.{digits}f}"

    lines = [
        "Pooled RMS: the root mean square of the per-log, per-channel RMS over Sensor_1-3, Pa. A fit's is its own logs' residual; "
        f"a left-out log's is its prediction from the other two's fit (tare {TARE}). Wall times are cold command lines.",
        "",
        "| case | fitted on | pooled RMS of the fit | left-out log | its pooled RMS | its hold-shape RMS | reduced χ² | identified terms (Eᵢ/E∞ at τᵢ) | fit s | compare s |",
        "|---|---|---:|---|---:|---:|---:|---|---:|---:|",
    ]
    for r in results:
        terms = ", ".join(f"{t['ratio']:.3g} at {t['tau_s']:.3g} s" for t in r["prony_terms"] if t["identified"]) or "none identified"
        lines.append(
            f"| {r['case']} | {', '.join(r['fitted'])} | {number(r['fit_pooled_rms_Pa'])} | {r['compared'] or '-'} | {number(r.get('compare_pooled_rms_Pa'))} | "
            f"{number(r.get('compare_pooled_hold_shape_rms_Pa'))} | {r['reduced_chi_square']:.3g} | {terms} | {r['fit_seconds']:.0f} | {number(r.get('compare_seconds'))} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="the folder holding the strip's logs (a checkout of the repository, or logs/ inside it)")
    parser.add_argument("--output", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--cases", default="single,group,leave-one-out", help="which kinds of case to run (comma-separated)")
    args = parser.parse_args()
    kinds = {kind for kind in args.cases.split(",") if kind}
    if not kinds <= {"single", "group", "leave-one-out"}:
        sys.exit(f"--cases: expected single, group or leave-one-out, got {args.cases!r}")
    logs = find_logs(args.data)
    work = args.output / f"{NAME}.work"
    work.mkdir(parents=True, exist_ok=True)
    mapping = work / "mtl_mapping.json"
    write_text_atomic(mapping, json.dumps(MAPPING, indent=1) + "\n")
    results = []
    cases = make_cases(kinds)
    for k, case in enumerate(cases):
        print(f"[{k + 1}/{len(cases)}] {case[0]}", flush=True)
        results.append(run_case(case, logs, work, mapping))
    document = {"settings": {"fit": list(FIT), "tare": TARE, "mapping": MAPPING}, "cases": results}
    write_text_atomic(args.output / f"{NAME}.json", json.dumps(document, indent=1) + "\n")
    write_text_atomic(args.output / f"{NAME}.md", markdown(results))
    print(f"written {args.output / NAME}.json, .md")


if __name__ == "__main__":
    main()
