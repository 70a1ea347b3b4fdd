"""The moving-press part of benchmarks/sysid.py: `hydrotact fit --lumped` on a stage
log where the probe moves between presses, against scipy.optimize.least_squares on
the same projected model and data, in one run.

Data: the stage-log stand-in (`hydrotact.sim.simulate_stage_log`, the FINGERTIP_SENSOR
with 4 barometers pressed by a 2 mm sphere at 20 sites 1 mm apart): ~16 Hz with 7-20
ms jitter and a 15-20 s gap, 0.05 s lag, unknown onsets, drifting baselines, a
clipped channel and a silent one; a 3-term material (E_inf 150 kPa; 20 kPa at 0.4
s, 15 kPa at 3 s, 10 kPa at 20 s), holds of 10-25 s, rests of 6-18 s and ramps at
0.5 mm/s: ~11k samples, the size of a real file. Simulated once per seed and kept
in the temp folder (`hydrotact-bench/`), since the full forward model takes minutes.

Both codes fit the same thing: the log prepared once by hydrotact
(`prepare_press_logs`: presses, sites, masks, noise, onset starts, the B-spline
baseline basis), the same parameters (log E_i/E_inf, log tau_i, the onsets' and the
lag's tanh coordinates), the same start x0, the same model (the site-split
hereditary integrals of the four powers of the depth, the active set found in two
frozen passes, the amplitudes — where a channel responds — and baselines projected
out per channel by the Jacobi-scaled normal equations). scipy's is written in NumPy as a user without JAX
would: the hereditary integral as its exact recursion over the jittered steps (a
loop over the samples, vectorised over terms, sites and powers), the Jacobian by
finite differences (jac='2-point'), methods 'trf' and 'lm'. hydrotact: the jitted
Levenberg-Marquardt with the hand-written Golub-Pereyra Jacobian; "warm" is the
second call of `fit_press_logs` (the whole fit: preparation, solve, standard errors).

The command line as a user runs it (`hydrotact fit --lumped --estimate-lag`, a fresh
process each): "cold" with empty caches (no compiled programs, the interpreter and
JAX imported from scratch), "second run" a fresh process once the first has filled
hydrotact's persistent compilation cache; one log with 3 terms and with `--terms
auto`, and three logs (three sessions, seeds seed..seed+2) calibrated together with 3
terms. The issue's targets on the 2-core CPU: three logs in 60 s cold, one log with
`--terms auto` in 30 s cold.
"""

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import scipy.optimize

from hydrotact.data import read_log, write_log
from hydrotact.sim import FINGERTIP_SENSOR, StageSession, simulate_stage_log
from hydrotact.sysid import fit_press_logs
from hydrotact.sysid.lumped._lumped import LAG_BOUND, ONSET_HALF_RANGE, PressLayout, press_residual_fn
from hydrotact.sysid.lumped._press_data import prepare_press_logs, site_responses
from hydrotact.sysid.lumped._press_projection import ACTIVE_PASSES, RIDGE
from hydrotact.sysid.lumped._press_solve import _initial_x
from hydrotact.sysid.lumped._press_windows import DEPTH_SCALE, POWERS
from hydrotact.visco import Prony

MATERIAL = Prony(jnp.asarray(150e3), jnp.asarray([20e3, 15e3, 10e3]), jnp.asarray([0.4, 3.0, 20.0]))
SESSION = {"hold_range": (10.0, 25.0), "rest_range": (6.0, 18.0), "speed": 0.5e-3, "overload": "f0", "silent": ("f3",), "home_spread": 0.0}
SMOKE_SESSION = {"sites": ((0.0, 0.0), (1e-3, 0.0), (0.0, 1e-3)), "hold_range": (4.0, 6.0), "rest_range": (1.0, 2.0), "num_gaps": 0, "silent": ("f3",), "home_spread": 0.0}


def standin_log(seed: int, smoke: bool):
    """The stand-in log (simulated once, then read from the temp folder) and its path."""
    name = f"press-{'smoke' if smoke else 'full'}-seed{seed}.parquet"
    path = Path(tempfile.gettempdir()) / "hydrotact-bench" / name
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        print(f"simulating the stand-in ({name}; minutes at full size) ...", flush=True)
        session = StageSession(**(SMOKE_SESSION if smoke else SESSION), seed=seed)
        log, _ = simulate_stage_log(str(FINGERTIP_SENSOR), "sphere:r=2mm,subdivisions=2", MATERIAL, session, num_rays=16)
        write_log(path, log)
    return read_log(path), path


# --- the same model in NumPy -----------------------------------------------------


def _hereditary(ratios, taus, times, values):
    """(T, W): u + sum_k g_k h_k, h_k the exact recursion h' = a h + c du over the steps."""
    steps = np.diff(times)[:, None] / taus[None, :]  # (T-1, K)
    decay = np.exp(-steps)
    gain = -np.expm1(-steps) / steps
    increments = np.diff(values, axis=0)
    state = np.repeat(values[:1], len(taus), axis=0)  # (K, W): the step at t0
    out = np.empty_like(values)
    out[0] = values[0] + ratios @ state
    for n in range(len(times) - 1):
        state = decay[n][:, None] * state + gain[n][:, None] * increments[n][None, :]
        out[n + 1] = values[n + 1] + ratios @ state
    return out


class NumpyPressModel:
    """One log's projected residuals, as `press_residual_fn` computes them."""

    def __init__(self, log, num_terms, num_sites):
        self.log, self.k, self.num_sites = log, num_terms, num_sites
        self.responds = site_responses([log], num_sites)  # (C, S): a channel's law is fitted only where it responds
        data = log.to_data(num_sites, self.responds)
        self.times = np.asarray(data.times)
        self.travel = np.asarray(data.travel)
        self.press = np.asarray(data.press)
        self.press_site = np.asarray(data.press_site)
        self.observed = np.asarray(data.observed)
        self.w = np.asarray(data.weights)
        self.baseline = np.asarray(data.baseline)
        self.onset_start = np.asarray(log.onset_start)
        self.evaluations = 0

    def residuals(self, x):
        self.evaluations += 1
        k = self.k
        ratios, taus = np.exp(x[:k]), np.exp(x[k : 2 * k])
        num_presses = len(self.onset_start)
        onsets = self.onset_start + ONSET_HALF_RANGE * np.tanh(x[2 * k : 2 * k + num_presses])
        lag = LAG_BOUND * np.tanh(x[2 * k + num_presses])
        travel = np.interp(self.times - lag, self.times, self.travel)
        inside = self.press >= 0
        depths = np.where(inside, np.maximum(travel - onsets[np.maximum(self.press, 0)], 0.0), 0.0)
        law = np.where(depths[:, None] > 0, (depths[:, None] / DEPTH_SCALE) ** np.asarray(POWERS)[None, :], 0.0)  # (T, J)
        site = np.where(inside, self.press_site[np.maximum(self.press, 0)], -1)
        inputs = (site[:, None] == np.arange(self.num_sites)[None, :])[:, :, None] * law[:, None, :]
        bases = _hereditary(ratios, taus, self.times, inputs.reshape(len(self.times), -1))  # (T, S J)
        contact = depths > 0
        active = np.repeat(contact[:, None], self.observed.shape[1], axis=1)
        for _ in range(ACTIVE_PASSES):
            amplitudes = self._solve(bases, active)[1]
            active = contact[:, None] & (bases @ amplitudes.T > 0)
        return self._solve(bases, active)[0].ravel()

    def _solve(self, bases, active):
        """Per channel: the weighted normal equations (Jacobi scaled, ridged), solved."""
        residuals = np.empty_like(self.observed)
        amplitudes = np.empty((self.observed.shape[1], bases.shape[1]))
        for c in range(self.observed.shape[1]):
            w = self.w[:, c]
            law = np.repeat(self.responds[c], len(POWERS)).astype(float)  # (S J)
            columns = np.hstack([self.baseline * w[:, None], bases * (w * active[:, c])[:, None] * law[None, :]])
            target = self.observed[:, c] * w
            normal = columns.T @ columns
            diagonal = np.diagonal(normal)
            scale = np.where(diagonal > 0, np.sqrt(np.where(diagonal > 0, diagonal, 1.0)), 1.0)
            scaled = normal / np.outer(scale, scale) + RIDGE * np.eye(len(scale))
            coefficients = np.linalg.solve(scaled, (columns.T @ target) / scale) / scale
            residuals[:, c] = target - columns @ coefficients
            amplitudes[c] = coefficients[self.baseline.shape[1] :]
        return residuals, amplitudes


def bench_press_fit(args, rows):
    """Time hydrotact's lumped press fit and scipy's on the stand-in; append rows."""
    log, path = standin_log(args.seed, args.smoke)
    num_terms = 3
    print(f"moving-press stand-in: {path} ({log.num_samples} samples, {num_terms} terms)", flush=True)
    start = time.perf_counter()
    fit = fit_press_logs([log], [str(path)], terms=num_terms, estimate_lag=True)
    first = time.perf_counter() - start
    start = time.perf_counter()
    fit = fit_press_logs([log], [str(path)], terms=num_terms, estimate_lag=True)
    warm = time.perf_counter() - start
    ours = {
        "task": "press fit", "method": "hydrotact fit_press_logs (lm, hand Jacobian)", "samples": log.num_samples,
        "presses": int(sum(len(p.onset_start) for p in fit.logs)), "parameters": 2 * num_terms + sum(len(p.onset_start) for p in fit.logs) + 1,
        "first_call_s": first, "warm_s": warm, "steps": fit.num_steps, "converged": fit.converged, "chi_square": fit.chi_square,
        "ratios": [r.value for r in fit.ratios], "taus": [t.value for t in fit.taus], "lag_s": fit.lags[0].value,
    }
    rows.append(ours)
    print(f"hydrotact: first call {first:.1f} s, warm {warm:.2f} s, {fit.num_steps} steps, chi2 {fit.chi_square:.2f}", flush=True)

    prepared, _, sites, _ = prepare_press_logs([log], [str(path)])
    layout = PressLayout(num_terms, (len(prepared[0].onset_start),), True)
    x0 = np.asarray(_initial_x(layout, prepared))
    model = NumpyPressModel(prepared[0], num_terms, len(sites))
    data = prepared[0].to_data(len(sites), site_responses(prepared, len(sites)))
    check = np.asarray(press_residual_fn(layout)(jnp.asarray(x0), ((data,), (jnp.asarray(prepared[0].onset_start),), (jnp.asarray(0.0),))))
    agreement = float(np.abs(model.residuals(x0) - check).max())
    print(f"NumPy model vs hydrotact's at x0: largest residual difference {agreement:.2e} (noise units)", flush=True)
    # The same cost for both: the projected model's (the solver's objective) at hydrotact's solution.
    # fit.chi_square is the model's own (each baseline re-solved given the amplitudes), which differs.
    x_ours = np.concatenate([
        np.log([r.value for r in fit.ratios]), np.log([t.value for t in fit.taus]),
        np.arctanh((fit.onsets[0] - prepared[0].onset_start) / ONSET_HALF_RANGE), [np.arctanh(fit.lags[0].value / LAG_BOUND)],
    ])
    projected = model.residuals(x_ours)
    ours["chi_square_projected"] = float(projected @ projected)
    print(f"hydrotact's solution: projected chi2 {ours['chi_square_projected']:.2f} (its reported, the model's own: {fit.chi_square:.2f})", flush=True)
    for method in args.scipy_methods:
        model.evaluations = 0
        start = time.perf_counter()
        result = scipy.optimize.least_squares(model.residuals, x0, jac="2-point", method=method, xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=args.press_max_evaluations)
        seconds = time.perf_counter() - start
        chi_square = float(result.fun @ result.fun)
        row = {
            "task": "press fit", "method": f"scipy least_squares {method} (2-point)", "seconds": seconds, "evaluations": model.evaluations,
            "status": int(result.status), "chi_square": chi_square, "chi_square_minus_hydrotact": chi_square - ours["chi_square_projected"],
            "ratio_vs_warm": seconds / warm, "ratio_vs_first_call": seconds / first, "model_agreement_at_x0": agreement,
            "ratios": np.exp(result.x[:num_terms]).tolist(), "taus": np.exp(result.x[num_terms : 2 * num_terms]).tolist(),
        }
        rows.append(row)
        print(f"scipy {method}: {seconds:.1f} s, {model.evaluations} evaluations, chi2 {chi_square:.2f} ({row['chi_square_minus_hydrotact']:+.2f} vs hydrotact), "
              f"{row['ratio_vs_warm']:.1f}x hydrotact warm", flush=True)


def _command_line(paths, terms, output, caches):
    """Wall time of `hydrotact fit --lumped` on `paths` in a fresh process, with its
    caches (hydrotact's and the XLA compilation cache) in `caches`."""
    environment = dict(os.environ, HYDROTACT_CACHE_DIR=str(caches), JAX_COMPILATION_CACHE_DIR=str(Path(caches) / "xla"))
    command = [str(Path(sys.executable).parent / "hydrotact"), "fit", *map(str, paths), "--lumped", "--estimate-lag", "--terms", str(terms), "--output", str(output), "--json"]
    start = time.perf_counter()
    done = subprocess.run(command, env=environment, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} exited {done.returncode}:\n{done.stderr[-2000:]}")
    return seconds


def bench_press_command_line(args, rows):
    """Cold and second-run wall times of the command line (see the module's docstring)."""
    cases = [("one log, 3 terms", [args.seed], 3), ("one log, --terms auto", [args.seed], "auto")]
    if not args.smoke:
        cases.append(("three logs, 3 terms", [args.seed, args.seed + 1, args.seed + 2], 3))
    with tempfile.TemporaryDirectory(prefix="hydrotact-cold-") as folder:
        for name, seeds, terms in cases:
            paths = [standin_log(seed, args.smoke)[1] for seed in seeds]
            caches = Path(folder) / f"caches-{len(rows)}"
            cold = _command_line(paths, terms, Path(folder) / "fit", caches)
            second = _command_line(paths, terms, Path(folder) / "fit", caches)
            samples = sum(read_log(path).num_samples for path in paths)
            rows.append({"task": "press fit, command line", "method": f"hydrotact fit --lumped ({name})", "samples": samples, "cold_s": cold, "second_run_s": second})
            print(f"command line, {name} ({samples} samples): cold {cold:.1f} s, second run {second:.1f} s", flush=True)


def print_press_table(rows):
    lines = [row for row in rows if row["task"] == "press fit, command line"]
    if lines:
        print("\nThe command line (a fresh process each; cold: empty caches):")
        print("| command | samples | cold | second run |")
        print("|---|---:|---:|---:|")
        for row in lines:
            print(f"| {row['method']} | {row['samples']} | {row['cold_s']:.1f} s | {row['second_run_s']:.1f} s |")
    ours = next((row for row in rows if row["task"] == "press fit" and row["method"].startswith("hydrotact")), None)
    if ours is None:
        return
    print(f"\nMoving-press fit ({ours['samples']} samples, {ours['presses']} presses, {ours['parameters']} nonlinear parameters):")
    print("| method | time | steps / evaluations | chi2 | chi2 - hydrotact's | scipy / hydrotact warm | scipy / hydrotact first call |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    print(f"| {ours['method']} | {ours['warm_s']:.2f} s warm, {ours['first_call_s']:.1f} s first | {ours['steps']} steps | {ours['chi_square_projected']:.2f} | - | - | - |")
    for row in rows:
        if row["method"].startswith("scipy"):
            print(f"| {row['method']} | {row['seconds']:.1f} s | {row['evaluations']} evals | {row['chi_square']:.2f} | {row['chi_square_minus_hydrotact']:+.2f} | "
                  f"{row['ratio_vs_warm']:.1f} | {row['ratio_vs_first_call']:.1f} |")
