"""Benchmark: the soft-rigid contact kernel of a git revision against the working
tree's, in one process, interleaved (the only comparison this machine's +-15 %
run-to-run spread allows), and where the working tree's time goes.

Each case draws benchmarks/contact.py's seeded poses (64 of them; not the first 64 of
contact.py's 1,024, which are drawn from the same seed in another order), grows each
kernel's buffers to those poses (contact.py grows them to all 1,024), then times both
kernels three times each, alternating: the force, torque and area, as contact.py times
them (time per batch: the median of three runs, vmapped in chunks of 16; best of the
three rounds). The forces of the two must agree (they print their largest relative
difference). `--trace` also sums XLA's own per-fusion times (`jax.profiler.trace`) of
the working tree's kernel by array size, so the stage that costs shows by its
buffer (polygons, pairs, ...).

Run: `.venv/bin/python benchmarks/contact_ab.py REV [--cases tilted sphere8] [--trace]`
(REV: a commit, e.g. HEAD~1).
"""

import argparse
import subprocess
import sys
import types
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import contact  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _machine import describe_machine, time_over_poses  # noqa: E402

import hydrotact.contact._soft_rigid as working  # noqa: E402
from hydrotact.contact import Capacity, make_pose, make_tet_clusters  # noqa: E402
from hydrotact.field import calc_distance_field, make_pressure_field  # noqa: E402
from hydrotact.mesh import make_seed_mesh  # noqa: E402

ROOT = Path(__file__).parents[1]
POSES = 64
CHUNK = 16

# name: benchmarks/contact.py's case (its sensor, probe and seeded poses)
CASES = {
    "upright": "pad5x5 + 2 mm cylinder",
    "tilted": "pad5x5 + tilted 2 mm cylinder",
    "edge": "pad5x5 + edge-first box",
    "corner": "pad5x5 + corner-first box",
    "sphere8": "sphere8 + 6 mm sphere (generator)",
    "ellipsoid8": "ellipsoid8 + 6 mm sphere (generator)",
}


def _kernel_at(revision):
    """The soft-rigid kernel module (and the clipping it imports) as at `revision`."""

    def load(path, name, replace=()):
        source = subprocess.run(["git", "show", f"{revision}:{path}"], capture_output=True, text=True, check=True, cwd=ROOT).stdout
        source = source.replace("from ..", "from hydrotact.").replace("from ._", "from hydrotact.contact._")
        for old, new in replace:
            source = source.replace(old, new)
        module = types.ModuleType(name)
        sys.modules[name] = module
        exec(compile(source, f"{revision}:{path}", "exec"), module.__dict__)
        return module

    load("hydrotact/contact/_polygon.py", "_baseline_polygon")
    return load("hydrotact/contact/_soft_rigid.py", "_baseline_soft_rigid", [("from hydrotact.contact._polygon import", "from _baseline_polygon import")])


def _grown(kernel, field, probe, X, clusters):
    capacity = Capacity(64, 64, 64, 256)
    for _ in range(12):
        run = jax.jit(jax.vmap(lambda X, capacity=capacity: kernel.calc_soft_rigid_surface(field, probe, X, capacity, False, clusters)))
        out = run(X)
        if not bool(jnp.any(out.did_overflow)):
            return capacity
        capacity = capacity.grown_to(np.asarray(out.needed).max(axis=0))
    raise RuntimeError("the buffers did not settle")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("revision", help="the git revision whose kernel is the baseline (e.g. HEAD~1)")
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    parser.add_argument("--trace", action="store_true", help="also sum XLA's per-fusion times of the working tree's kernel by buffer")
    args = parser.parse_args()
    baseline = _kernel_at(args.revision)
    print(f"machine: {describe_machine()}")
    print(f"| case | {args.revision} surfaces/s | working tree surfaces/s | speedup | force rel. difference |\n|---|---:|---:|---:|---:|")
    fields = {}
    for name in args.cases:
        sensor, probe_name, draw = contact.CASES[CASES[name]]
        if sensor not in fields:
            mesh = make_seed_mesh(sensor)
            field = make_pressure_field(mesh, calc_distance_field(mesh), 2e5)
            fields[sensor] = (field, make_tet_clusters(field.vertices, field.tets))
        field, clusters = fields[sensor]
        probe = contact.PROBES[probe_name]()
        poses = draw(POSES, probe, contact.case_rng(0, CASES[name]))
        X = jax.vmap(make_pose)(jnp.asarray(poses[:, :3]), jnp.asarray(poses[:, 3:]))
        kernels = {"baseline": baseline, "working": working}
        capacities = {label: _grown(kernel, field, probe, X, clusters) for label, kernel in kernels.items()}

        def wrench(kernel, capacity, field=field, probe=probe, clusters=clusters):
            # What benchmarks/contact.py times: the force, the torque and the area (with the
            # force alone XLA drops the moments' integrals, and the kernel runs faster).
            def run(row):
                surface = kernel.calc_soft_rigid_surface(field, probe, make_pose(row[:3], row[3:]), capacity, False, clusters)
                return (*surface.calc_wrench(), surface.total_area)

            return run

        seconds, forces = {label: [] for label in kernels}, {}
        for _ in range(3):
            for label, kernel in kernels.items():
                s, outputs = time_over_poses(wrench(kernel, capacities[label]), poses, CHUNK, 3)
                forces[label] = outputs[0]
                seconds[label].append(s)
        old, new = min(seconds["baseline"]), min(seconds["working"])
        difference = np.max(np.abs(forces["baseline"] - forces["working"])) / np.max(np.abs(forces["baseline"]))
        print(f"| {name} | {POSES / old:,.0f} | {POSES / new:,.0f} | {old / new:.2f} | {difference:.1e} |", flush=True)
        if args.trace:
            parts, _ = contact.time_by_buffer(wrench(working, capacities["working"]), poses, capacities["working"], CHUNK)
            print("  working tree, us a pose by buffer " + str(capacities["working"].sizes) + ": " + ", ".join(f"{k} {v:.0f}" for k, v in parts.items()))


if __name__ == "__main__":
    main()
