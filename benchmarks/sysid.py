"""Benchmark: time to fit a Prony material to a barometer log (hydrotact's jitted
Levenberg-Marquardt) against scipy.optimize.least_squares on the same residual, and a
relaxation-curve fit against pyvisco, in the same run.

Data (fixed seed): a synthetic log, by default 10 minutes at 100 Hz with 8 barometer
channels and a reference force, from a press / hold / release indentation history
(holds 2-40 s, depths 0.3-0.8 mm, 0.3 s ramps, gaps 2-20 s). Unit-modulus responses
go as depth^1.5 per channel (a Hertz-like contact, a random amplitude per channel);
the truth is E_inf = 6e5 Pa, (E_i, tau_i) = (2.5e5 Pa, 0.3 s), (1.5e5 Pa, 3 s),
(1e5 Pa, 30 s); channel gains 0.8-1.2, offsets N(0, 50 Pa), BMP388 readings
(0.016 Pa LSB, 101325 Pa ambient) with 2 Pa RMS noise (a barometer in silicone is
noisier than the bare part's datasheet figure), force noise 5 mN RMS.

Log fit (3 Prony terms, E_inf, 8 gains, 8 offsets: 23 parameters):

- hydrotact: `fit_problem(problem, 3, make_solver("lm"))` (NNLS start, then optimistix LM with
  forward-mode Jacobians, all jitted). The first call compiles and runs; the second
  runs only; compile = first - second. "solve" is the jitted solver alone (the
  internal `_run`, from the same start x0), to compare with scipy on equal terms.
- scipy: `scipy.optimize.least_squares` on the same residual written in NumPy/SciPy,
  as a user without JAX would: the same parameterisation (log moduli, log taus, log
  gains, offsets in noise units), the same noise weights, the same start x0
  (`make_initial_guess`). Each term's exact recursive update h' = a h + c du is a
  first-order IIR filter (`scipy.signal.lfilter`) at uniform steps (a loop over the
  steps otherwise). Jacobian by finite differences (jac='2-point'), method 'trf' and
  'lm' (MINPACK). Both reach the same chi-square; that is checked before any ratio.

Relaxation curve (pyvisco's task: it fits E(t), not logs): the truth's E(t) at 200
log-spaced times from 1e-2 s to 6e2 s with 0.1 % relative noise, fitted with
`fit_prony_pyvisco(t, E, 3)` (tests/pyvisco_reference.py: pyvisco's N-term step) and
`hydrotact.sysid.fit_relaxation_curve(t, E, 3)`.

The chi-square at the true parameters is printed too: a fit that ends far above it
found a local minimum (the timing comparison still holds when both codes reach the
same one; the parameter errors then say how far off that minimum is).

Moving-press fit (`hydrotact fit --lumped` on a stage log whose probe moves between
presses, against scipy least_squares on the same projected model): see
benchmarks/_press_bench.py.

Run: `.venv/bin/python benchmarks/sysid.py [--minutes 10 --rate 100 --channels 8
--terms 3 --seed 0] [--tasks log relaxation press press-cli] [--smoke] [--output PATH]`.
"""

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.optimize  # noqa: E402
import scipy.signal  # noqa: E402
from _machine import describe_machine, write_results  # noqa: E402
from _press_bench import bench_press_command_line, bench_press_fit, print_press_table  # noqa: E402

from hydrotact.data import BarometerLog  # noqa: E402
from hydrotact.sensors import known_parts  # noqa: E402
from hydrotact.sysid import BoundedLBFGSB, calc_residuals, fit_problem, fit_relaxation_curve, make_fit_problem, make_initial_guess, make_solver  # noqa: E402
from hydrotact.sysid._fit import _run  # noqa: E402
from hydrotact.sysid._model import pack  # noqa: E402
from hydrotact.visco import calc_barometer_readings, calc_contact_response, make_barometer_signal, make_prony  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from pyvisco_reference import _import_pyvisco, fit_prony_pyvisco  # noqa: E402
from sysid_synthetic import make_press_depths  # noqa: E402

TRUE_LONG_TERM = 6e5
TRUE_MODULI = np.array([2.5e5, 1.5e5, 1e5])
TRUE_TAUS = np.array([0.3, 3.0, 30.0])
BAROMETER_NOISE = 2.0  # Pa RMS
FORCE_NOISE = 5e-3  # N RMS


# --- data ---------------------------------------------------------------------------


def make_log(minutes, rate, num_channels, seed):
    """The synthetic log, its unit responses and the truth."""
    rng = np.random.default_rng(seed)
    truth = make_prony(TRUE_LONG_TERM, TRUE_MODULI, TRUE_TAUS)
    times = np.arange(int(round(minutes * 60.0 * rate))) / rate
    depth = make_press_depths(rng, times, holds=(2.0, 40.0), gaps=(2.0, 20.0), ramp=0.3, start=1.0, end_margin=2.0)
    shape = rng.uniform(0.2, 1.0, num_channels) * 1e-3 / (0.5e-3) ** 1.5
    unit = depth[:, None] ** 1.5 * shape  # Pa per Pa of E
    unit_force = np.zeros((len(times), 3))
    unit_force[:, 2] = 3e-6 / (0.5e-3) ** 1.5 * depth**1.5  # N per Pa of E
    response = np.asarray(calc_contact_response(truth, times, np.column_stack([unit, unit_force])))
    gains = rng.uniform(0.8, 1.2, num_channels)
    offsets = rng.normal(0.0, 50.0, num_channels)
    signal = make_barometer_signal(known_parts()["BMP388"], num_channels, gains=gains, offsets=offsets, noise_rms=BAROMETER_NOISE, rate_hz=rate)
    readings = np.asarray(calc_barometer_readings(signal, jnp.asarray(times), jnp.asarray(response[:, :num_channels]), key=jax.random.PRNGKey(seed)))
    force = response[:, num_channels:] + rng.normal(0.0, FORCE_NOISE, (len(times), 3))
    channels = [f"b{k}" for k in range(num_channels)]
    columns = {"time": times, **{name: readings[:, k] for k, name in enumerate(channels)}, "fx": force[:, 0], "fy": force[:, 1], "fz": force[:, 2], "indentation": depth}
    metadata = {"format": "hydrotact.barometer_log", "version": 1, "sensor": "synthetic", "source": "simulated", "pressure": "absolute", "channels": channels}
    return BarometerLog(metadata, columns), (unit, unit_force), gains, offsets


# --- the NumPy / SciPy model ----------------------------------------------------------


class NumpyResidual:
    """The fit's weighted residuals in NumPy/SciPy, for the problem's single log."""

    def __init__(self, problem, layout):
        (log,) = problem.logs
        self.times = np.asarray(log.times)
        self.inputs = np.asarray(log.inputs)
        self.observed = np.asarray(log.observed)
        self.weights = np.asarray(log.weights)
        self.offset_base = np.asarray(log.offset_base)
        self.offset_scale = np.asarray(log.offset_scale)
        self.gain_index = np.asarray(log.gain_index)
        self.num_channels = log.num_channels
        self.num_terms = layout.num_terms
        self.num_gains = layout.num_gains
        steps = np.diff(self.times)
        self.step = float(np.mean(steps))
        self.uniform = bool(np.max(np.abs(steps - self.step)) <= 1e-9 * self.step)
        self.steps = steps[:, None]
        # The drive of each term's filter, before the per-term gain c: the input's
        # step at t0, then its increments.
        self.increments = np.diff(self.inputs, axis=0)
        self.evaluations = 0

    def kernel_response(self, tau):
        """g = exp(-t/tau) * du over piecewise-linear u: (T, columns)."""
        if self.uniform:
            ratio = self.step / tau
            decay = np.exp(-ratio)
            drive = np.empty_like(self.inputs)
            drive[0] = self.inputs[0]
            drive[1:] = (-np.expm1(-ratio) / ratio) * self.increments
            return scipy.signal.lfilter([1.0], [1.0, -decay], drive, axis=0)
        ratio = self.steps / tau
        decay = np.exp(-ratio)
        drive = (-np.expm1(-ratio) / ratio) * self.increments
        out = np.empty_like(self.inputs)
        out[0] = self.inputs[0]
        for n in range(len(drive)):
            out[n + 1] = decay[n] * out[n] + drive[n]
        return out

    def __call__(self, x):
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # solvers probe wild steps
            return self._residuals(x)

    def _residuals(self, x):
        self.evaluations += 1
        k, g = self.num_terms, self.num_gains
        long_term = np.exp(x[0])
        moduli, taus = np.exp(x[1 : 1 + k]), np.exp(x[1 + k : 1 + 2 * k])
        gains = np.append(np.exp(x[1 + 2 * k : 1 + 2 * k + g]), 1.0)[self.gain_index]
        theta = x[1 + 2 * k + g :]
        response = long_term * self.inputs
        for modulus, tau in zip(moduli, taus):
            response += modulus * self.kernel_response(tau)
        response = np.where(self.inputs * response > 0.0, response, 0.0)  # a contact pushes, never pulls
        c = self.num_channels
        predicted = response.copy()
        predicted[:, :c] = self.offset_base + self.offset_scale * theta + gains * response[:, :c]
        return ((self.observed - predicted) * self.weights).ravel()


# --- helpers --------------------------------------------------------------------------


def _timed(fn, *args, **kwargs):
    start = time.perf_counter()
    result = fn(*args, **kwargs)
    return result, time.perf_counter() - start


def _timed_median(repeats, fn, *args):
    """fn(*args) run `repeats` times: (the last result, the median seconds)."""
    runs = [_timed(fn, *args) for _ in range(repeats)]
    return runs[-1][0], statistics.median(seconds for _, seconds in runs)


def _material(x, num_terms):
    """(E_inf, [E_i], [tau_i]) from a flat x (tau ascending)."""
    moduli, taus = np.exp(x[1 : 1 + num_terms]), np.exp(x[1 + num_terms : 1 + 2 * num_terms])
    order = np.argsort(taus)
    return float(np.exp(x[0])), moduli[order], taus[order]


def _errors(long_term, moduli, taus):
    """Relative errors against the truth (NaN where the term count differs)."""
    errors = {"E_inf": long_term / TRUE_LONG_TERM - 1.0}
    for k in range(len(TRUE_MODULI)):
        ok = len(moduli) == len(TRUE_MODULI)
        errors[f"E_{k + 1}"] = float(moduli[k] / TRUE_MODULI[k] - 1.0) if ok else float("nan")
        errors[f"tau_{k + 1}"] = float(taus[k] / TRUE_TAUS[k] - 1.0) if ok else float("nan")
    return errors


def _fmt_time(seconds):
    if seconds is None:
        return "-"
    return f"{seconds * 1e3:.1f} ms" if seconds < 1.0 else f"{seconds:.2f} s"


def _fmt_errors(errors):
    return " | ".join(f"{errors[key]:+.1e}" for key in ["E_inf", "E_1", "tau_1", "E_2", "tau_2", "E_3", "tau_3"])


def _load():
    return os.getloadavg()


# --- benchmark ------------------------------------------------------------------------


def bench_log_fit(args, rows):
    log, (unit, unit_force), gains, offsets = make_log(args.minutes, args.rate, args.channels, args.seed)
    problem = make_fit_problem([log], unit_responses=[(unit, unit_force)])
    num_residuals = problem.num_samples
    num_forces = len(problem.infos[0].force_columns)
    print(f"log: {log.num_samples} samples x ({args.channels} channels + {num_forces} force) = {num_residuals} residuals", flush=True)

    # The shared start (the NNLS fit); the first call compiles its helpers.
    _, init_first = _timed(make_initial_guess, problem, args.terms)
    (layout, x0), init_seconds = _timed(make_initial_guess, problem, args.terms)
    print(f"initial guess: first {init_first:.2f} s, second {init_seconds:.2f} s; {layout.size} parameters", flush=True)

    def gain_error(x):
        fitted = np.exp(x[1 + 2 * args.terms : 1 + 2 * args.terms + layout.num_gains])
        return float(np.max(np.abs(fitted / gains - 1.0)))

    results = {}
    for name in args.solvers:
        solver = make_solver(name)
        first, first_seconds = _timed(fit_problem, problem, args.terms, solver)
        second, second_seconds = _timed(fit_problem, problem, args.terms, solver)
        # The jitted solver alone, from the same x0 (compiled by the calls above).
        bounds = None
        if isinstance(solver, BoundedLBFGSB):
            from hydrotact.sysid._fit import _bounds

            bounds = _bounds(problem, layout, x0)
        # fit_problem may pass _run the problem without its host-side infos (so they
        # do not key the compilation cache): do the same to hit its compiled code.
        run_problem = problem.without_infos() if hasattr(problem, "without_infos") else problem
        out, solve_seconds = _timed_median(
            args.log_repeats, lambda run_problem=run_problem, solver=solver, bounds=bounds: jax.block_until_ready(_run(run_problem, layout, jnp.asarray(x0), solver, bounds, None))
        )
        assert np.allclose(np.asarray(out[0].value), second.x, rtol=0, atol=1e-12), "the timed solve differs from fit_problem's"
        # Compilation on its own (trace + lower + XLA compile, ahead of time): under load
        # first - second call is noisy, as both are dominated by the run.
        jax.clear_caches()  # else the lowering and compilation come from the cache
        start = time.perf_counter()
        _run.lower(run_problem, layout, jnp.asarray(x0), solver, bounds, None).compile()
        aot_seconds = time.perf_counter() - start
        results[name] = second
        row = {
            "task": "log fit",
            "method": f"hydrotact fit_problem({name!r})",
            "first_call_s": first_seconds,
            "second_call_s": second_seconds,
            "compile_s": first_seconds - second_seconds,
            "compile_aot_s": aot_seconds,
            "solve_s": solve_seconds,
            "initial_guess_s": init_seconds,
            "steps": second.num_steps,
            "converged": second.converged,
            "chi_square": second.chi_square,
            "reduced_chi_square": second.reduced_chi_square,
            "residual_rms_in_noise": float(np.sqrt(second.chi_square / num_residuals)),
            "errors": _errors(*_material(second.x, args.terms)),
            "max_gain_error": gain_error(second.x),
            "x": second.x.tolist(),
        }
        rows.append(row)
        print(
            f"hydrotact {name}: first {first_seconds:.2f} s, second {second_seconds:.2f} s, solve {row['solve_s']:.2f} s, AOT compile {aot_seconds:.2f} s, "
            f"{second.num_steps} steps, chi2 {second.chi_square:.6f}, converged {second.converged}",
            flush=True,
        )

    reference = results[args.solvers[0]]
    hydro = rows[0]
    residual = NumpyResidual(problem, layout)
    # The chi-square at the true parameters: what a fit should reach (or beat a little).
    theta = (offsets + float(known_parts()["BMP388"].ambient_pa) - np.asarray(problem.logs[0].offset_base)) / np.asarray(problem.logs[0].offset_scale)
    x_true = pack(layout, long_term=TRUE_LONG_TERM, moduli=TRUE_MODULI, taus=TRUE_TAUS, gains=gains, offsets=theta)
    truth_chi_square = float(np.sum(residual(x_true) ** 2))
    rows.insert(0, {"task": "log fit", "method": "truth", "chi_square": truth_chi_square, "num_residuals": num_residuals, "num_parameters": layout.size})
    print(f"chi2 at the true parameters: {truth_chi_square:.6f} ({num_residuals} residuals, {layout.size} parameters)", flush=True)
    model_difference = float(np.max(np.abs(residual(reference.x) - _jax_residuals(problem, layout, reference.x))))
    print(f"NumPy vs JAX residual at hydrotact's solution: max |diff| {model_difference:.1e} noise units (uniform steps: {residual.uniform})", flush=True)

    for method in args.scipy_methods:
        residual.evaluations = 0
        # scipy's default tolerances (ftol = xtol = gtol = 1e-8), as a user would run it.
        solution, seconds = _timed(scipy.optimize.least_squares, residual, x0, jac="2-point", method=method)
        chi_square = float(np.sum(solution.fun**2))
        relative = chi_square / reference.chi_square - 1.0
        x_difference = float(np.max(np.abs(solution.x[: 1 + 2 * args.terms] - reference.x[: 1 + 2 * args.terms])))
        row = {
            "task": "log fit",
            "method": f"scipy least_squares({method!r}, 2-point)",
            "solve_s": seconds,
            "total_s": seconds + init_seconds,
            "evaluations": residual.evaluations,
            "nfev": int(solution.nfev),
            "status": int(solution.status),
            "chi_square": chi_square,
            "chi_square_vs_hydrotact": relative,
            "chi_square_vs_truth": chi_square / truth_chi_square - 1.0,
            "max_log_material_difference": x_difference,
            "errors": _errors(*_material(solution.x, args.terms)),
            "max_gain_error": gain_error(solution.x),
            "ratio_vs_solve": seconds / hydro["solve_s"],
            "ratio_total_vs_second_call": (seconds + init_seconds) / hydro["second_call_s"],
            "ratio_total_vs_first_call": (seconds + init_seconds) / hydro["first_call_s"],
            "x": solution.x.tolist(),
        }
        rows.append(row)
        print(
            f"scipy {method}: {seconds:.2f} s, {residual.evaluations} residual evaluations, chi2 {chi_square:.6f} (rel. to hydrotact {relative:+.1e}), max "
            f"|d log material| {x_difference:.1e}",
            flush=True,
        )
        if abs(relative) > 1e-6:
            print(f"WARNING: scipy {method} and hydrotact reach different chi-squares ({relative:+.1e} relative)", flush=True)


def _jax_residuals(problem, layout, x):
    return np.asarray(calc_residuals(jnp.asarray(x), problem, layout))


def bench_relaxation(args, rows):
    rng = np.random.default_rng(args.seed)
    times = np.geomspace(1e-2, 6e2, args.relaxation_points)
    clean = TRUE_LONG_TERM + np.exp(-times[:, None] / TRUE_TAUS) @ TRUE_MODULI
    modulus = clean * (1.0 + 1e-3 * rng.standard_normal(times.size))

    _import_pyvisco()
    fit, pyvisco_seconds = _timed_median(args.repeats, fit_prony_pyvisco, times, modulus, args.terms)
    pyvisco = {
        "task": "relaxation curve",
        "method": "pyvisco (N-term fit_time, opt=True)",
        "second_call_s": pyvisco_seconds,
        "residual_rms": fit["residual_rms"],
        "errors": _errors(fit["long_term_modulus"], fit["moduli"], fit["taus"]),
    }

    first, first_seconds = _timed(fit_relaxation_curve, times, modulus, args.terms)
    ours, ours_seconds = _timed_median(args.repeats, fit_relaxation_curve, times, modulus, args.terms)
    hydrotact = {
        "task": "relaxation curve",
        "method": "hydrotact fit_relaxation_curve('lm')",
        "first_call_s": first_seconds,
        "second_call_s": ours_seconds,
        "compile_s": first_seconds - ours_seconds,
        "converged": ours.converged,
        "residual_rms": ours.residual_rms,
        "errors": _errors(ours.long_term_modulus.value, np.array([m.value for m, _ in ours.terms]), np.array([t.value for _, t in ours.terms])),
    }
    pyvisco["ratio_vs_second_call"] = pyvisco["second_call_s"] / hydrotact["second_call_s"]
    pyvisco["ratio_vs_first_call"] = pyvisco["second_call_s"] / hydrotact["first_call_s"]
    rows += [hydrotact, pyvisco]
    for row in (hydrotact, pyvisco):
        print(f"{row['method']}: {row['second_call_s'] * 1e3:.1f} ms, RMS residual {row['residual_rms']:.1f} Pa, errors {_fmt_errors(row['errors'])}", flush=True)


def print_tables(rows):
    truth = next(row for row in rows if row["method"] == "truth")
    log_rows = [row for row in rows if row["task"] == "log fit" and row["method"] != "truth"]
    base = log_rows[0]
    print(f"\nchi2 at the true parameters: {truth['chi_square']:.1f} ({truth['num_residuals']} residuals)")
    print("\nLog fit:")
    print(
        "| method | first call | second call | compile (1st - 2nd) | compile (AOT) | solve only | steps / evaluations | chi2 / truth's | chi2 rel. to "
        "hydrotact LM | solve ratio (x / hydrotact LM solve) | total vs 2nd call | total vs 1st call |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for row in log_rows:
        vs_truth = row["chi_square"] / truth["chi_square"]
        if row["method"].startswith("hydrotact"):
            rel = row["chi_square"] / base["chi_square"] - 1.0
            print(
                f"| {row['method']} | {_fmt_time(row['first_call_s'])} | {_fmt_time(row['second_call_s'])} | {_fmt_time(row['compile_s'])} | "
                f"{_fmt_time(row['compile_aot_s'])} | {_fmt_time(row['solve_s'])} | {row['steps']} steps | {vs_truth:.4f} | {rel:+.1e} | "
                f"{row['solve_s'] / base['solve_s']:.2f} | - | - |"
            )
        else:
            print(
                f"| {row['method']} | - | - | - | - | {_fmt_time(row['solve_s'])} | {row['evaluations']} evals | {vs_truth:.4f} | "
                f"{row['chi_square_vs_hydrotact']:+.1e} | {row['ratio_vs_solve']:.2f} | {row['ratio_total_vs_second_call']:.2f} | "
                f"{row['ratio_total_vs_first_call']:.2f} |"
            )
    print("\nParameter relative errors (vs truth):")
    print("| task | method | E_inf | E_1 | tau_1 | E_2 | tau_2 | E_3 | tau_3 | max gain err / RMS residual |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for row in rows:
        if row["method"] == "truth":
            continue
        extra = f"{row['max_gain_error']:.1e}" if "max_gain_error" in row else f"{row['residual_rms']:.1f} Pa"
        print(f"| {row['task']} | {row['method']} | {_fmt_errors(row['errors'])} | {extra} |")
    relax = [row for row in rows if row["task"] == "relaxation curve"]
    if relax:
        print("\nRelaxation curve:")
        print("| method | first call | second call | compile | pyvisco / hydrotact (2nd) | pyvisco / hydrotact (1st) | RMS residual |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for row in relax:
            ratio2 = f"{row['ratio_vs_second_call']:.2f}" if "ratio_vs_second_call" in row else "-"
            ratio1 = f"{row['ratio_vs_first_call']:.2f}" if "ratio_vs_first_call" in row else "-"
            print(
                f"| {row['method']} | {_fmt_time(row.get('first_call_s'))} | {_fmt_time(row['second_call_s'])} | {_fmt_time(row.get('compile_s'))} | {ratio2} "
                f"| {ratio1} | {row['residual_rms']:.1f} Pa |"
            )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--channels", type=int, default=8)
    parser.add_argument("--terms", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--solvers", nargs="+", default=["lm"], help="hydrotact solvers (the first is the reference; e.g. lm lbfgsb bfgs)")
    parser.add_argument("--scipy-methods", nargs="+", default=["trf", "lm"])
    parser.add_argument("--relaxation-points", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5, help="repeats of the relaxation-curve timings (median)")
    parser.add_argument("--log-repeats", type=int, default=1, help="repeats of the log fit's solve-only timing (median)")
    parser.add_argument("--tasks", nargs="+", choices=("log", "relaxation", "press", "press-cli"), default=["log", "relaxation", "press", "press-cli"],
                        help="press: the lumped fit in process against scipy; press-cli: its command line, cold and on a second run")
    parser.add_argument("--press-max-evaluations", type=int, default=5000, help="scipy's cap on residual evaluations in the moving-press fit")
    parser.add_argument("--smoke", action="store_true", help="a tiny fast run (30 s log at 20 Hz, 3 channels, one repeat)")
    parser.add_argument("--output", type=Path, default=None, help="JSON path (default benchmarks/results/sysid-BACKEND.json; sysid-smoke-BACKEND.json with --smoke)")
    args = parser.parse_args(argv)
    if args.smoke:
        args.minutes, args.rate, args.channels, args.repeats = 0.5, 20.0, 3, 1
        args.relaxation_points = min(args.relaxation_points, 60)
    if args.terms != len(TRUE_MODULI):
        parser.error(f"the synthetic truth has {len(TRUE_MODULI)} terms; --terms must be {len(TRUE_MODULI)} for the parameter errors")

    machine = describe_machine()
    machine["load_average_start"] = _load()
    print(f"machine: {machine}", flush=True)
    config = {"task": "config", **{k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}, "barometer_noise_pa": BAROMETER_NOISE, "force_noise_n": FORCE_NOISE}
    rows = [config]
    log_rows, relax_rows, press_rows = [], [], []
    if "log" in args.tasks:
        bench_log_fit(args, log_rows)
    if "relaxation" in args.tasks:
        bench_relaxation(args, relax_rows)
    if "press" in args.tasks:
        bench_press_fit(args, press_rows)
    if "press-cli" in args.tasks:
        bench_press_command_line(args, press_rows)
    rows += log_rows + relax_rows + press_rows
    machine["load_average_end"] = _load()
    if log_rows:
        print_tables(log_rows + relax_rows)
    print_press_table(press_rows)
    print(f"load average (1, 5, 15 min): start {machine['load_average_start']}, end {machine['load_average_end']}")
    if args.output is None:
        path = write_results("sysid-smoke" if args.smoke else "sysid", machine, rows)
    else:
        path = args.output
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
    print(f"written: {path}")


if __name__ == "__main__":
    main()
