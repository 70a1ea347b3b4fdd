"""Estimator training speed: sequences with a burn-in against the paper's windows, and
inference latency per step.

On one sphere8 dataset (`--dataset DIR`, or generated here with `--events`), the
default binned GRU is trained twice, in the same process, from the same
initialisation, for the same wall-clock budget each:

- `sequences`: `sequence_length` 256 labels after a 128-sample burn-in (the library's
  default);
- `windows`: the paper's method, a 512-sample history per label (`sequence_length` 1,
  `burn_in` 511), batch 50 as the paper's.

Each epoch's validation loss (on the held-out split, each method's own context) is
recorded with the time spent so far; the table gives training labels per second, the
best validation loss within the budget, and the time each method took to reach the
windows method's best (the claim: sequences get there sooner). Then the latency of one
estimator step: the jitted JAX step, `StreamingEstimator.update` (with its Python
overhead), and the exported C step compiled with the system compiler at -O2.

    .venv/bin/python benchmarks/train.py [--dataset DIR | --events 300] [--budget 600]

Writes benchmarks/results/train-BACKEND.json and prints a table.
"""

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from _machine import describe_machine, write_results  # noqa: E402

from hydrotact.datasets import DatasetConfig, generate_dataset, load_dataset  # noqa: E402
from hydrotact.models import StreamingEstimator, TrainConfig, calc_estimator_step, export_c_header, make_initial_state, train_estimator  # noqa: E402
from hydrotact.sensors import load_sensor  # noqa: E402

METHODS = {"sequences": {"sequence_length": 256, "burn_in": 128}, "windows": {"sequence_length": 1, "burn_in": 511}}


def _train(dataset, sensor, method: str, budget: float) -> dict:
    """Train for about `budget` seconds: epochs until the budget is spent (the epoch that
    crosses it finishes)."""
    spent, curve = [0.0], []

    class Spent(Exception):
        pass

    def on_epoch(entry):
        spent[0] += entry["seconds"]
        curve.append((spent[0], entry["validation_loss"]))
        if spent[0] >= budget:
            raise Spent

    config = TrainConfig(max_epochs=10_000, patience=10_000, schedule="constant", **METHODS[method])
    started = time.perf_counter()
    try:
        train_estimator(dataset, sensor, config, on_epoch=on_epoch)
    except Spent:
        pass
    labels = sum(b - a for a, b in dataset.manifest["split"]["train"])
    return {"method": method, **METHODS[method], "epochs": len(curve), "seconds": spent[0], "wall_s": time.perf_counter() - started,
            "labels_per_s": labels * len(curve) / spent[0], "best_validation_loss": min(v for _, v in curve), "curve": curve}


def _reach(curve, level: float):
    return next((t for t, v in curve if v <= level), None)


C_MAIN = r"""
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c99 */
#include <stdio.h>
#include <time.h>
#include "model.h"
int main(void) {
  hydrotact_state state = {0}; hydrotact_output out; float r[HYDROTACT_NUM_INPUTS];
  for (int j = 0; j < HYDROTACT_NUM_INPUTS; ++j) r[j] = 101325.0f + 10.0f * j;
  struct timespec a, b; clock_gettime(CLOCK_MONOTONIC, &a);
  const int n = 200000; float sink = 0.0f;
  for (int t = 0; t < n; ++t) { r[t % HYDROTACT_NUM_INPUTS] += 0.01f; hydrotact_step(&state, r, &out); sink += out.force[3]; }
  clock_gettime(CLOCK_MONOTONIC, &b);
  printf("%.9g %g\n", ((b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec)) / n, sink);
  return 0;
}
"""


def _latency(trained, folder: Path) -> dict:
    spec, params = trained.spec, trained.params
    step = jax.jit(lambda state, x: calc_estimator_step(spec, params, state, x))
    state, x = make_initial_state(spec, np.float32), np.zeros(spec.num_inputs, np.float32)
    jax.block_until_ready(step(state, x))
    start = time.perf_counter()
    for _ in range(2000):
        state, out = step(state, x)
    jax.block_until_ready(out)
    jax_step = (time.perf_counter() - start) / 2000
    stream = StreamingEstimator(trained)
    reading = np.full(spec.num_inputs, 101325.0)
    stream.update(reading)
    start = time.perf_counter()
    for _ in range(500):
        stream.update(reading)
    streaming = (time.perf_counter() - start) / 500
    result = {"jax_step_s": jax_step, "streaming_update_s": streaming}
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler:
        export_c_header(trained, folder / "model.h")
        (folder / "main.c").write_text(C_MAIN)
        subprocess.run([compiler, "-std=c99", "-O2", "-o", str(folder / "bench"), str(folder / "main.c"), "-lm"], check=True, cwd=folder)
        result["c_step_s"] = float(subprocess.run([str(folder / "bench")], capture_output=True, text=True, check=True).stdout.split()[0])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", type=Path)
    parser.add_argument("--events", type=int, default=300)
    parser.add_argument("--budget", type=float, default=600.0, help="seconds of training per method")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="hydrotact-train-bench-"))
    if args.dataset is None:
        args.dataset = folder / "dataset"
        generate_dataset("sphere8", args.dataset, config=DatasetConfig(events=args.events, seed=11), progress=True)
    dataset, sensor = load_dataset(args.dataset), load_sensor("sphere8")
    rows = [_train(dataset, sensor, method, args.budget) for method in METHODS]
    target = rows[1]["best_validation_loss"]
    for row in rows:
        row["seconds_to_windows_best"] = _reach(row["curve"], target)
    trained = train_estimator(dataset, sensor, TrainConfig(max_epochs=1))
    latency = _latency(trained, folder)
    machine = describe_machine()
    path = write_results("train", machine, rows + [{"latency": latency, "dataset": str(args.dataset), "rows": dataset.num_rows}])
    print(f"\n{machine['cpu']} ({machine['cores']} cores), JAX {machine['jax']} on {machine['jax_backend']}; {dataset}")
    print("| method | labels/s | epochs | best validation loss | s to the windows' best |\n|---|---:|---:|---:|---:|")
    for row in rows:
        reach = row["seconds_to_windows_best"]
        print(f"| {row['method']} | {row['labels_per_s']:.0f} | {row['epochs']} | {row['best_validation_loss']:.4g} | {'-' if reach is None else f'{reach:.0f}'} |")
    print("latency per step: " + ", ".join(f"{k} {v * 1e6:.1f} us" for k, v in latency.items()))
    print(json.dumps({"written": str(path)}))


if __name__ == "__main__":
    sys.exit(main())
