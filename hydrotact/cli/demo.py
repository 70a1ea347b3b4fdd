"""`hydrotact demo`: hydrotact's main job, end to end, on built-in data.

1. A probe trajectory over the pad5x5 sensor: a Ø2 mm flat cylinder presses six
   taxels in turn (0.4 s ramps, holds of 3 to 25 s, rests between), as a stage would.
2. A known viscoelastic material (E∞ and three Prony terms with well-separated τ),
   written as `truth_material.json`.
3. `hydrotact simulate --material truth_material.json --barometer`: absolute BMP388
   readings (ambient, per-channel gain and offset, noise, 0.016 Pa LSB, 100 Hz) and
   load-cell forces with noise -> `demo_log.parquet` and its plot.
4. `hydrotact fit demo_log.parquet`: the material, gains and offsets fitted back ->
   `fit/` (material.json, report.json, traces, residuals, relaxation plots).
5. Truth vs fit ± standard errors, printed and saved in `summary.json`.
"""

import json
from pathlib import Path

import numpy as np

from .._files import check_output, write_text_atomic

TOP = 4e-3  # pad5x5's skin height, m
PRESSES = (  # (x, y) m, depth m, hold s, rest after s
    ((0.0, 0.0), 0.45e-3, 25.0, 12.0),
    ((2.2e-3, 0.0), 0.35e-3, 4.0, 4.0),
    ((-2.2e-3, 2.2e-3), 0.5e-3, 12.0, 20.0),
    ((0.0, -2.2e-3), 0.3e-3, 3.0, 3.0),
    ((2.2e-3, 2.2e-3), 0.4e-3, 8.0, 10.0),
    ((-2.2e-3, -2.2e-3), 0.45e-3, 18.0, 8.0),
)
RAMP = 0.4
MOVE = 0.1  # s, lateral moves between presses
# A soft silicone skin (E(0) = 180 kPa): the deepest press swings a BMP388 by ~18 kPa,
# inside its 30-125 kPa range at sea level (a stiffer skin saturates it: see simulate).
TRUTH = {"long_term_modulus": 1.0e5, "moduli": [4.0e4, 2.5e4, 1.5e4], "taus": [0.3, 3.0, 30.0]}


def make_demo_trajectory(presses=PRESSES) -> np.ndarray:
    """Waypoints (time s, x, y, z m) of the demo's presses; the stage moves linearly
    between them (z is the probe tip, 0.3 mm above the skin between presses)."""
    rows, time = [], 0.0
    clear = TOP + 0.3e-3
    x0, y0 = presses[0][0]
    rows.append((time, x0, y0, clear))
    time += 2.0
    rows.append((time, x0, y0, clear))
    rest_before = 0.0
    for (x, y), depth, hold, rest in presses:
        if (x, y) != tuple(rows[-1][1:3]):  # move over the next taxel, then wait there
            time += MOVE
            rows.append((time, x, y, clear))
            time += rest_before
            rows.append((time, x, y, clear))
        rest_before = rest
        time += RAMP * (1 + 0.3e-3 / depth)
        rows.append((time, x, y, TOP - depth))
        time += hold
        rows.append((time, x, y, TOP - depth))
        time += RAMP * (1 + 0.3e-3 / depth)
        rows.append((time, x, y, clear))
    time += rest_before
    rows.append((time, *rows[-1][1:]))
    return np.array(rows)


SMOKE_PRESSES = (((0.0, 0.0), 0.45e-3, 12.0, 6.0), ((2.2e-3, 0.0), 0.35e-3, 3.0, 3.0))


def run_demo(out_dir, progress: bool = True, smoke: bool = False) -> dict:
    """Simulate the demo log, fit it, write everything into out_dir; returns the
    summary (also out_dir/summary.json). `smoke`: two presses, two Prony terms
    (0.3 s, 3 s), 16 rays: the same job at test-suite size."""
    from ..data import make_material_document, material_prony, write_material
    from ..sim import BarometerSettings, make_trajectory, simulate_log
    from ..sysid import SimulatorFit, fit_logs
    from ..viz import plot_fit
    from .fit import print_fit_table
    from .simulate import write_simulated_log

    out_dir = check_output(out_dir, directory=True, what="the demo")
    out_dir.mkdir(parents=True, exist_ok=True)
    # The numbers of the trajectory file are the ones simulated (9 significant digits).
    waypoints = np.array([[float(f"{value:.9g}") for value in row] for row in make_demo_trajectory(SMOKE_PRESSES if smoke else PRESSES)])
    trajectory_path = out_dir / "demo_trajectory.csv"
    write_text_atomic(trajectory_path, "time,x,y,z\n" + "".join(",".join(f"{value:.9g}" for value in row) + "\n" for row in waypoints))
    truth_numbers = dict(TRUTH)
    if smoke:
        truth_numbers.update(moduli=TRUTH["moduli"][:2], taus=TRUTH["taus"][:2])
    truth = make_material_document(
        truth_numbers["long_term_modulus"], truth_numbers["moduli"], truth_numbers["taus"], name="demo truth",
        description="The material the demo log is simulated with.", provenance={"method": "simulation"},
    )
    truth_path = out_dir / "truth_material.json"
    write_material(truth_path, truth)
    barometer = BarometerSettings(seed=1, noise_rms=0.5, gain_spread=0.05, offset_spread=30.0, force_noise=0.005)
    probe = "cylinder:d=2mm"
    log, samples = simulate_log(
        "pad5x5", probe, make_trajectory(waypoints[:, 0], waypoints[:, 1:4], source=str(trajectory_path)), material_prony(truth, "demo truth"),
        num_rays=16 if smoke else 32, barometer=barometer, progress=progress,
    )
    log_path = out_dir / "demo_log.parquet"
    simulated = write_simulated_log(log, samples, log_path, out_dir / "demo_log.png")
    # step 4 is what a user runs on their own log: `hydrotact fit demo_log.parquet`
    report = fit_logs([log_path], out_dir / "fit", method=SimulatorFit(progress=progress), terms=2 if smoke else "auto", plot=plot_fit)
    gains = {f"pad5x5/{name}": g for name, g in zip(log.metadata["channels"], log.metadata["barometer"]["gains"])}
    truth_numbers = {**truth_numbers, "instantaneous_modulus": truth_numbers["long_term_modulus"] + sum(truth_numbers["moduli"]), "gains": gains}
    print_fit_table(report, truth_numbers)
    summary = {
        "truth": truth_numbers,
        "fit": {key: report[key] for key in ("num_terms", "long_term_modulus_Pa", "prony_terms", "instantaneous_modulus_Pa", "reduced_chi_square", "converged", "seconds")},
        "criterion": report.get("criterion"),
        "simulation": simulated,
        "files": {"trajectory": str(trajectory_path), "truth_material": str(truth_path), "log": str(log_path), "log_png": str(out_dir / "demo_log.png"), **report["files"]},
    }
    write_text_atomic(out_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    return summary


def add_parser(subparsers):
    parser = subparsers.add_parser("demo", help="the main job on built-in data: simulate a pad5x5 log with a known viscoelastic material, fit it back; results and pictures in out/")
    parser.add_argument("-o", "--output", type=Path, default=Path("out"), metavar="DIR", help="the folder to write the results and pictures in (default out)")
    parser.add_argument("--smoke", action="store_true", help="the same job at test-suite size (two presses, two Prony terms)")
    return parser


def run(args) -> None:
    summary = run_demo(args.output, smoke=args.smoke)
    print(f"hydrotact demo: results in {args.output}/")
    for path in summary["files"].values():
        print(f"  {path}")
    print(f"  {args.output / 'summary.json'}")
