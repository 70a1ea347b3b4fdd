"""The 5x5-array probe sweep of the hydroelastic tactile paper, in simulation.

A 2 mm flat-ended cylinder traverses the pad5x5 sensor along its x axis (y = 0) from
the centre of the leftmost cell to the centre of the rightmost in 0.0125 mm steps (the
paper's stage resolution), and along the diagonal from cell b00 to cell b44 in steps of
the same length. At each position the probe presses down until the reference force
(the axial force on the probe, -F_z on the sensor) reaches 0.35 N: the depth is solved
by Newton's method on the differentiable contact force (optimistix), not by stepping.
All 25 taxels are recorded at that depth, with the library's default 64 rays per
taxel (footprint rays: each integrates the pressure over its own square of the
receptive field, so the curves are smooth without more rays), and again with 1024
rays at every 16th position, the converged reference the 64-ray curves are measured
against.

Outputs (in --output, default experiments/results/):
- `probe_sweep_pad5x5.png`: normalised responses of the three innermost cells along
  each sweep (the paper's Fig. 6 layout), and the solved depth;
- `probe_sweep_pad5x5.json`: per cell, the peak position (expected at the cell's
  centre), the full width at half maximum, the cross-talk ratio at the neighbouring
  cell's centre, and the roughness (max |second difference| of the normalised curve,
  which shows ridge-and-dent artefacts), the largest difference from the 1024-ray
  reference (as a share of the cell's peak), plus the settings and timings;
- `probe_sweep_pad5x5.npz`: the raw traces.

`--barometers elastic` runs the same sweeps with every barometer reading the
elastomer's pressure at its port (`{"kind": "elastic"}`: 0.5 mm ports, nu 0.49; the
first run solves pad5x5's 25 receptive fields, minutes, then reads them from the
cache) instead of the paper's ray-cast disks; its outputs are named
`probe_sweep_pad5x5_elastic.*`, there is no ray reference (an elastic reading has no
rays), and when the disk run's `probe_sweep_pad5x5.npz` is in --output it also draws
`probe_sweep_pad5x5_models.png`, the two models' curves over each other.

Each sweep and its reference run in chunks; finished chunks are kept in hidden
`.probe_sweep_pad5x5.*.partial.npz` files, so an interrupted run resumes. `--smoke` runs a few coarse positions (for the tests).

Run: `.venv/bin/python experiments/probe_sweep_pad5x5.py [--barometers disk|elastic] [--rays 64] [--reference-rays 1024] [--smoke]`.
"""

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

from hydrotact._files import atomic_path, digest, write_text_atomic  # noqa: E402
from hydrotact.contact import calc_contact_surface, compute_contact_surface, make_cylinder_probe, make_pose  # noqa: E402
from hydrotact.sensors import load_sensor, with_receptive_fields  # noqa: E402
from hydrotact.sim import SimCapacity, calc_unit_response, make_sensor_model  # noqa: E402
from hydrotact.taxel import TaxelCapacity  # noqa: E402

PITCH = 2.2e-3
TOP = 4e-3
TARGET_FORCE = 0.35
NAME = "probe_sweep_pad5x5"


def _cell(row: int, col: int) -> int:
    return 5 * row + col


# The three innermost cells of each sweep, and the coordinate of their centres along it.
SWEEPS = {
    "x axis": {"cells": {"b21": _cell(2, 1), "b22": _cell(2, 2), "b23": _cell(2, 3)}, "direction": np.array([1.0, 0.0])},
    "diagonal": {"cells": {"b11": _cell(1, 1), "b22": _cell(2, 2), "b33": _cell(3, 3)}, "direction": np.array([1.0, 1.0]) / np.sqrt(2.0)},
}


def sensor(barometers: str):
    """pad5x5 as built in (`disk`: the paper's ray-cast taxels), or with every barometer
    `elastic` (the elastomer's pressure over a 0.5 mm port, nu 0.49), the layout the same."""
    pad = load_sensor("pad5x5")
    return pad if barometers == "disk" else with_receptive_fields(pad, {"kind": "elastic"})


def sweep_positions(name: str, step: float, smoke: bool, every: int = 1):
    """(s, xy): the coordinate along the sweep (0 at the centre cell) and the probe's
    (x, y), from the first cell's centre to the last's (every `every`-th of them)."""
    half = 2 * PITCH * (np.sqrt(2.0) if name == "diagonal" else 1.0)
    if smoke:
        s = np.linspace(-1.2 * PITCH, 1.2 * PITCH, 7) * (np.sqrt(2.0) if name == "diagonal" else 1.0)
    else:
        s = np.arange(-half, half + 0.5 * step, step)
    s = s[::every]
    return s, s[:, None] * SWEEPS[name]["direction"][None]


def _reference_force(model, probe, capacity, modulus, depth, xy):
    """The axial force on the probe (-F_z on the sensor) at `depth` below the top."""
    X_SR = make_pose(jnp.concatenate([xy, jnp.reshape(TOP - depth, (1,))]))
    surface = calc_contact_surface(model.field, probe, X_SR, capacity.contact, model.clusters)
    force, _ = surface.calc_wrench()
    return -modulus * force[2], surface.did_overflow


@eqx.filter_jit
def solve_depths(model, probe, capacity, modulus, xys, depth0):
    """Depths at which the reference force is TARGET_FORCE for a batch of (x, y):
    Newton's method on the differentiable contact force (vmapped).

    **Returns:** (depths, forces there, overflow flags, converged flags)."""

    def residual(depth, xy):
        return _reference_force(model, probe, capacity, modulus, depth, xy)[0] - TARGET_FORCE

    solver = optx.Newton(rtol=1e-10, atol=1e-9 * TARGET_FORCE)

    def one(xy):
        solution = optx.root_find(residual, solver, depth0, args=xy, max_steps=40, throw=False)
        force, overflow = _reference_force(model, probe, capacity, modulus, solution.value, xy)
        return solution.value, force, overflow, solution.result == optx.RESULTS.successful

    return jax.vmap(one)(xys)


@eqx.filter_jit
def _responses(model, probe, xys, depths, capacity):
    def one(xy, depth):
        X_SR = make_pose(jnp.concatenate([xy, jnp.reshape(TOP - depth, (1,))]))
        return calc_unit_response(model, probe, X_SR, capacity)

    return jax.vmap(one)(xys, depths)


def run_sweep(name, model, probe, capacity, modulus, step, smoke, chunk, partial, progress=True, every=1, depths=None):
    """Solve depths and record taxels along one sweep (every `every`-th position),
    chunk by chunk, resumably; with `depths` (one per position recorded), record the
    taxels at those depths instead of solving."""
    from tqdm.auto import tqdm

    s, xys = sweep_positions(name, step, smoke, every)
    key = digest(name, model.num_rays, modulus, np.ascontiguousarray(xys).tobytes(), capacity.contact, capacity.taxel_pairs)
    done = {}
    if partial.is_file():
        try:
            with np.load(partial, allow_pickle=False) as saved:
                if str(saved["key"]) == key:
                    done = {k: saved[k] for k in saved.files if k != "key"}
        except (OSError, ValueError, KeyError):
            done = {}
    num_done = len(done.get("depth", []))
    chunk = min(chunk, len(s))
    label = f"{name} sweep, " + (f"{model.num_rays} rays" if model.uses_rays else "elastic")
    with tqdm(total=len(s), initial=num_done, unit="position", desc=label, disable=not progress) as bar:
        for start in range(num_done, len(s), chunk):
            index = np.minimum(np.arange(start, start + chunk), len(s) - 1)
            xy = jnp.asarray(xys[index])
            while True:  # grow the buffers if the contact at the solved depths needs it
                if depths is None:
                    depth, force, overflow, converged = solve_depths(model, probe, capacity, jnp.asarray(modulus), xy, jnp.asarray(0.45e-3))
                else:
                    depth, overflow = jnp.asarray(depths[index]), jnp.zeros(len(index), bool)
                    force, converged = jnp.full(len(index), jnp.nan), jnp.ones(len(index), bool)  # solved by the sweep
                unit = _responses(model, probe, xy, depth, capacity)
                if not bool(jnp.any(overflow | unit.did_overflow)):
                    break
                # the one growth rule: to what the overflowing responses needed (every
                # buffer doubled when only the depth search overflowed)
                capacity = capacity.grown_to(np.asarray(unit.needed)[np.asarray(unit.did_overflow)])
            used = min(chunk, len(s) - start)
            piece = {
                "depth": np.asarray(depth)[:used],
                "force": np.asarray(force)[:used],
                "converged": np.asarray(converged)[:used],
                "taxels": modulus * np.asarray(unit.taxel_pressures)[:used],
            }
            done = piece if not done else {k: np.concatenate([done[k], piece[k]]) for k in piece}
            with atomic_path(partial, suffix=".npz") as tmp:
                np.savez(tmp, key=np.array(key), **done)
            bar.update(used)
    return s, xys, done


def half_maximum_width(s, curve):
    """Full width at half maximum of a single-peaked curve, by linear interpolation."""
    peak = int(np.argmax(curve))
    half = 0.5 * curve[peak]
    left = peak
    while left > 0 and curve[left] > half:
        left -= 1
    right = peak
    while right < len(curve) - 1 and curve[right] > half:
        right += 1
    if curve[left] > half or curve[right] > half:
        return float("nan")  # the curve does not fall to half within the sweep

    def crossing(i, j):
        return s[i] + (half - curve[i]) * (s[j] - s[i]) / (curve[j] - curve[i])

    return float(crossing(right - 1, right) - crossing(left, left + 1))


def refined_peak(s, curve):
    """The peak's position: the vertex of the parabola through the largest sample and
    its two neighbours (the sample itself at either end of the sweep)."""
    k = int(np.argmax(curve))
    if k == 0 or k == len(curve) - 1:
        return float(s[k])
    left, middle, right = curve[k - 1], curve[k], curve[k + 1]
    bend = left - 2 * middle + right
    shift = 0.5 * (left - right) / bend if bend < 0 else 0.0
    return float(s[k] + shift * (s[k + 1] - s[k]))


def cell_metrics(s, taxels, cells, along, reference=None):
    """Peak, width, cross-talk and roughness of each cell's normalised curve; with
    `reference` (s, taxels) at more rays, the largest difference from it."""
    metrics = {}
    centres = {cell: (i - 1) * along for i, cell in enumerate(cells)}
    for cell, index in cells.items():
        curve = taxels[:, index]
        peak_value = float(curve.max())
        normalised = curve / peak_value if peak_value > 0 else curve
        peak_at = refined_peak(s, curve)
        neighbours = [c for c in cells if c != cell and abs(centres[c] - centres[cell]) < 1.5 * along]
        crosstalk = {c: float(np.interp(centres[c], s, normalised)) for c in neighbours}
        roughness = float(np.max(np.abs(np.diff(normalised, 2)))) if len(s) > 2 else float("nan")
        metrics[cell] = {
            "centre_mm": 1e3 * centres[cell],
            "peak_mm": 1e3 * peak_at,
            "peak_error_mm": 1e3 * (peak_at - centres[cell]),
            "peak_within_0.1mm": bool(abs(peak_at - centres[cell]) <= 1e-4),
            "peak_pressure_Pa": peak_value,
            "fwhm_mm": 1e3 * half_maximum_width(s, normalised),
            "crosstalk_at_neighbour_centre": crosstalk,
            "roughness_max_abs_second_difference": roughness,
        }
        if reference is not None:
            reference_s, reference_taxels = reference
            at = np.searchsorted(s, reference_s - 1e-12)  # the reference positions are sweep positions
            difference = np.max(np.abs(curve[at] - reference_taxels[:, index])) / max(float(reference_taxels[:, index].max()), 1e-300)
            metrics[cell]["max_difference_from_reference_of_peak"] = float(difference)
    return metrics


def plot(results, path, title, references=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(2, 2, figsize=(11, 6.5), sharex="col", gridspec_kw={"height_ratios": [3, 1]})
    for column, (name, result) in enumerate(results.items()):
        s_mm = 1e3 * result["s"]
        for cell, index in SWEEPS[name]["cells"].items():
            curve = result["taxels"][:, index]
            line = axes[0, column].plot(s_mm, curve / max(curve.max(), 1e-300), lw=1.2, label=cell)[0]
            if references is not None:
                reference = references[name]
                axes[0, column].plot(1e3 * reference["s"], reference["taxels"][:, index] / max(curve.max(), 1e-300), "o", ms=2.5, mfc="none", color=line.get_color())
        axes[0, column].set_title(f"{name} sweep" + ("" if references is None else f" (circles: {references['rays']} rays)"))
        axes[0, column].set_ylabel("normalised response")
        axes[0, column].legend(fontsize=8)
        axes[0, column].grid(alpha=0.3)
        axes[1, column].plot(s_mm, 1e3 * result["depth"], "k", lw=1)
        axes[1, column].set_ylabel("depth [mm]")
        axes[1, column].set_xlabel("probe position along the sweep [mm]")
        axes[1, column].grid(alpha=0.3)
    figure.suptitle(title)
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=130)
    plt.close(figure)


def _trace_key(sweep: str, name: str) -> str:
    """The name of one sweep's array in `probe_sweep_pad5x5*.npz`."""
    return f"{sweep.replace(' ', '_')}/{name}"


def read_traces(path) -> dict:
    """A run's traces as written to its .npz: {sweep: {"s", "taxels"}}."""
    with np.load(path) as saved:
        return {sweep: {k: saved[_trace_key(sweep, k)] for k in ("s", "taxels")} for sweep in SWEEPS}


def plot_models(disk, elastic, path):
    """The two barometer models' normalised curves of the three innermost cells along
    each sweep, over each other (solid: elastic, dashed: ray-cast disks)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for axis, sweep in zip(axes, SWEEPS):
        for cell, index in SWEEPS[sweep]["cells"].items():
            line = None
            for result, style, label in ((elastic, "-", "elastic"), (disk, "--", "disk rays")):
                curve = result[sweep]["taxels"][:, index]
                kwargs = {"color": line.get_color()} if line is not None else {}
                drawn = axis.plot(1e3 * result[sweep]["s"], curve / max(curve.max(), 1e-300), style, lw=1.2, label=f"{cell}, {label}", **kwargs)[0]
                line = line or drawn
        axis.set_title(f"{sweep} sweep")
        axis.set_xlabel("probe position along the sweep [mm]")
        axis.grid(alpha=0.3)
        axis.legend(fontsize=7)
    axes[0].set_ylabel("normalised response")
    figure.suptitle(f"pad5x5, 2 mm cylinder at {TARGET_FORCE} N: elastic barometers (solid) against the ray-cast disks (dashed)")
    figure.tight_layout()
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=130)
    plt.close(figure)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="a few coarse positions and 16 rays (for the tests)")
    parser.add_argument("--barometers", choices=("disk", "elastic"), default="disk", help="the barometer model: the paper's ray-cast disks (default) or the elastomer's pressure")
    parser.add_argument("--rays", type=int, default=64, help="rays per taxel (default 64, the library's)")
    parser.add_argument("--reference-rays", type=int, default=1024, help="rays per taxel of the converged reference (default 1024)")
    parser.add_argument("--reference-every", type=int, default=16, help="the reference at every this many positions (default 16)")
    parser.add_argument("--step", type=float, default=0.0125e-3, help="step along each sweep in metres (default 0.0125 mm)")
    parser.add_argument("--modulus", type=float, default=1e6, help="hydroelastic modulus in Pa (default 1e6)")
    parser.add_argument("--chunk", type=int, default=32, help="positions per jitted call")
    parser.add_argument("--output", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args(argv)
    rays = 16 if args.smoke and args.rays == 64 else args.rays
    reference_rays = 64 if args.smoke and args.reference_rays == 1024 else args.reference_rays
    every = 2 if args.smoke and args.reference_every == 16 else args.reference_every
    elastic = args.barometers == "elastic"
    name = NAME + ("_elastic" if elastic else "")
    started = time.perf_counter()
    model = make_sensor_model(sensor(args.barometers), num_rays=rays)
    reference_model = dataclasses.replace(model, num_rays=reference_rays)  # the same field, more rays
    probe = make_cylinder_probe(2e-3)
    # Buffers that hold the deepest contact of the sweeps (found once, then fixed).
    probes = jax.vmap(make_pose)(jnp.array([[x, y, TOP - 0.9e-3] for x in (-4.4e-3, 0.0, 1.1e-3) for y in (-4.4e-3, 0.0, 0.55e-3)]))
    _, contact_capacity = compute_contact_surface(model.field, probe, probes, clusters=model.clusters)
    capacity = SimCapacity.of(contact_capacity, TaxelCapacity(1 << 13))
    args.output.mkdir(parents=True, exist_ok=True)
    results, references = {}, {"rays": reference_rays}
    # An elastic reading has no rays, so no ray reference.
    parts = (("sweep", model, 1, results),) + (() if elastic else (("reference", reference_model, every, references),))
    for sweep in SWEEPS:
        for part, sweep_model, stride, store in parts:
            partial = args.output / f".{name}.{sweep.replace(' ', '_')}.{part}.partial.npz"
            # the reference at the depths already solved (the contact does not depend on the rays)
            depths = None if part == "sweep" else results[sweep]["depth"][::stride]
            s, xys, recorded = run_sweep(sweep, sweep_model, probe, capacity, args.modulus, args.step, args.smoke, args.chunk, partial, every=stride, depths=depths)
            store[sweep] = {"s": s, "xy": xys, **recorded}
    report = {
        "experiment": "probe sweep over pad5x5 (hydroelastic tactile paper, Fig. 6 procedure)",
        "smoke": args.smoke,
        "barometers": args.barometers,
        "probe": "cylinder:d=2mm",
        "target_force_N": TARGET_FORCE,
        "modulus_Pa": args.modulus,
        "rays_per_taxel": None if elastic else rays,
        "reference_rays_per_taxel": None if elastic else reference_rays,
        "reference_every": None if elastic else every,
        "step_mm": 1e3 * args.step,
        "seconds": time.perf_counter() - started,
        "sweeps": {},
    }
    for sweep, result in results.items():
        along = PITCH * (np.sqrt(2.0) if sweep == "diagonal" else 1.0)
        reference = None if elastic else (references[sweep]["s"], references[sweep]["taxels"])
        report["sweeps"][sweep] = {
            "num_positions": int(len(result["s"])),
            "all_converged": bool(np.all(result["converged"])),
            "max_force_error_N": float(np.max(np.abs(result["force"] - TARGET_FORCE))),
            "depth_mm": [1e3 * float(result["depth"].min()), 1e3 * float(result["depth"].max())],
            "cells": cell_metrics(result["s"], result["taxels"], SWEEPS[sweep]["cells"], along, reference),
        }
    stem = args.output / name
    write_text_atomic(stem.with_suffix(".json"), json.dumps(report, indent=2) + "\n")
    with atomic_path(stem.with_suffix(".npz"), suffix=".npz") as tmp:
        np.savez_compressed(tmp, **{_trace_key(sweep, k): v for sweep, r in results.items() for k, v in r.items()})
    model_text = "elastic barometers (the elastomer's pressure, 0.5 mm ports)" if elastic else f"{rays} rays per taxel"
    plot(results, stem.with_suffix(".png"), f"pad5x5, 2 mm cylinder at {TARGET_FORCE} N, {model_text}", None if elastic else references)
    written = [stem.with_suffix(".json"), stem.with_suffix(".png"), stem.with_suffix(".npz")]
    disk_traces = args.output / f"{NAME}.npz"
    if elastic and disk_traces.is_file():
        plot_models(read_traces(disk_traces), results, args.output / f"{NAME}_models.png")
        written.append(args.output / f"{NAME}_models.png")
    for sweep in SWEEPS:
        for part in ("sweep", "reference"):
            (args.output / f".{name}.{sweep.replace(' ', '_')}.{part}.partial.npz").unlink(missing_ok=True)
    print("results: " + ", ".join(map(str, written)))
    return report


if __name__ == "__main__":
    main(sys.argv[1:])
