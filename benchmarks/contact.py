"""Benchmark: contact surfaces per second, against Drake's query in the same run.

Cases, each at random poses (seeded; random places and random depths, not a line):
pad5x5 (27k tets) pressed by the 2 mm cylinder probe (6 mm long), upright; by the
default 2 mm cylinder (10 mm long) tilted 15 degrees about x, then 10 about y; by a 4 x
4 x 2 mm box turned 45 degrees about x (an edge first) and turned so that a corner
presses first; each at x, y uniform within 4.4 mm of the centre and its lowest point
0.1-0.5 mm below the top. sphere8 and ellipsoid8 pressed by the dataset generator's
probe (a 6 mm sphere) as `hydrotact generate` presses them: at skin points uniform by
area, along the inward normal tilted up to the generator's 20 degrees, 0.3-0.5 mm deep;
and sphere8 by a rigid half-space at random offsets. The distance field throughout, so
Drake computes the same surfaces from the same meshes (tests/test_contact_drake.py
checks they agree).

- Drake: `QueryObject.ComputeContactSurfaces` (polygons), one pose at a time, after
  updating the free body's pose; mean seconds per query over a pass of its poses.
- hydrotact: the contact surface and its wrench for a batch of poses in one jitted
  call (vmap over chunks of poses, lax.map over chunks: by default chunks of
  hydrotact's CPU_POSE_GROUP on a CPU, the whole batch on an accelerator), float64,
  with the clustered tet search, the buffers grown to the batch's poses; timed after
  compilation.
- Timed in turn: `--rounds` rounds, each one pass of Drake's and one call of each
  batch; the table gives the medians over the rounds, and the range of each rate and
  of the rounds' own ratios (on a 2-core CPU hydrotact's rate, on two threads,
  moved up to 2x between calls, Drake's less: benchmarks/RESULTS.md). `taskset -c 0`
  before the command compares one core against one core.

Run: `.venv/bin/python benchmarks/contact.py [--batches 1 64 1024] [--cases box sphere8]`.
"""

import argparse
import collections
import gzip
import json
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _machine import batched_over_poses, describe_machine, write_results  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
from drake_reference import DrakeScene  # noqa: E402
from helpers import lowest_vertex  # noqa: E402

from hydrotact.contact import (  # noqa: E402
    CPU_POSE_GROUP,
    Capacity,
    HalfSpace,
    calc_contact_surface,
    compute_contact_surface,
    make_box_probe,
    make_cylinder_probe,
    make_pose,
    make_sphere_probe,
    make_tet_clusters,
)
from hydrotact.field import calc_distance_field, make_pressure_field  # noqa: E402
from hydrotact.mesh import make_seed_mesh, read_mesh, write_mesh  # noqa: E402

MODULUS = 2e5
PAD_TOP = 4e-3  # pad5x5's top face
PAD_DEPTHS = (0.1e-3, 0.5e-3)  # of the probe's lowest point below it
CURVED_DEPTHS = (0.3e-3, 0.5e-3)  # of the sphere's tip past the skin, along the press
MAX_TILT = 20.0  # degrees: the generator's default press tilt
TILTED = Rotation.from_euler("xy", [15.0, 10.0], degrees=True).as_rotvec()  # 15 degrees about x, then 10 about (fixed) y
EDGE_FIRST = np.array([np.pi / 4, 0.0, 0.0])
CORNER_FIRST = Rotation.align_vectors([[0.0, 0.0, -1.0]], [np.array([2.0, 2.0, 1.0]) / 3.0])[0].as_rotvec()  # the box's corner (2, 2, 1) mm down


# The probes, as `hydrotact.contact` makes them (Drake reads each from an .obj of it).
PROBES = {
    "cylinder": lambda: make_cylinder_probe(2e-3, length=6e-3),
    "tilted": lambda: make_cylinder_probe(2e-3),
    "box": lambda: make_box_probe((4e-3, 4e-3, 2e-3)),
    "sphere": lambda: make_sphere_probe(3e-3),
}


# case: (sensor, probe name in PROBES or "half-space", draw(count, probe, rng)); each
# case's poses are seeded by its name (case_rng).
CASES = {
    "pad5x5 + 2 mm cylinder": ("pad5x5", "cylinder", lambda n, probe, r: _pad_poses(n, probe, np.zeros(3), r)),
    "pad5x5 + tilted 2 mm cylinder": ("pad5x5", "tilted", lambda n, probe, r: _pad_poses(n, probe, TILTED, r)),
    "pad5x5 + edge-first box": ("pad5x5", "box", lambda n, probe, r: _pad_poses(n, probe, EDGE_FIRST, r)),
    "pad5x5 + corner-first box": ("pad5x5", "box", lambda n, probe, r: _pad_poses(n, probe, CORNER_FIRST, r)),
    "sphere8 + 6 mm sphere (generator)": ("sphere8", "sphere", lambda n, probe, r: _curved_poses("sphere8", n, r)),
    "ellipsoid8 + 6 mm sphere (generator)": ("ellipsoid8", "sphere", lambda n, probe, r: _curved_poses("ellipsoid8", n, r)),
    "sphere8 + half-space": ("sphere8", "half-space", lambda n, probe, r: _half_space_poses(n, r)),
}


def case_rng(seed, case):
    """The random generator of `case`'s poses."""
    return np.random.default_rng([seed, sum(map(ord, case))])


def _pad_poses(count, probe, rotation_vector, rng):
    """(count, 6): translations and rotation vectors of `probe` turned by
    `rotation_vector`, at x, y uniform within 4.4 mm of the pad's centre and its lowest
    point 0.1-0.5 mm below the top."""
    xy = rng.uniform(-4.4e-3, 4.4e-3, (count, 2))
    z = PAD_TOP - rng.uniform(*PAD_DEPTHS, count) - lowest_vertex(probe, rotation_vector)[2]
    return np.column_stack([xy, z, np.tile(rotation_vector, (count, 1))])


def _curved_poses(sensor, count, rng):
    """(count, 6): the generator's presses of its sphere probe on a curved sensor."""
    from hydrotact.datasets._events import _tilt, find_touchable_skin, pressing_rotation_vectors, sample_skin_points
    from hydrotact.mesh import load_tet_mesh
    from hydrotact.sensors import load_sensor

    skin = find_touchable_skin(load_sensor(sensor), load_tet_mesh(sensor))
    points, normals, _ = sample_skin_points(skin, count, rng)
    directions, _ = _tilt(-normals, np.radians(MAX_TILT), rng)
    tips = points + rng.uniform(*CURVED_DEPTHS, count)[:, None] * directions
    return np.column_stack([tips, pressing_rotation_vectors(directions)])


def _half_space_poses(count, rng):
    """(count, 6): the half-space's plane at random heights 0.3-1.5 mm into sphere8's
    dome (its top at 14 mm), shifted sideways (a plane does not care), unturned."""
    xy = rng.uniform(-3e-3, 3e-3, (count, 2))
    return np.column_stack([xy, 14.0e-3 - rng.uniform(0.3e-3, 1.5e-3, count), np.zeros((count, 3))])


def _matrix(row):
    X = np.eye(4)
    X[:3, :3] = Rotation.from_rotvec(row[3:]).as_matrix()
    X[:3, 3] = row[:3]
    return X


def _drake_timer(vtk_path, other, poses):
    """A function timing one pass of Drake's queries over `poses` (seconds a query).
    The other body is fixed in the world (the half-space turned upside down: Drake's is
    solid below z = 0, ours above) and the sensor moves to the pose that gives the same
    relative pose as ours."""
    flip = np.diag([1.0, -1.0, -1.0, 1.0]) if type(other).__name__ == "HalfSpace" else np.eye(4)
    scene = DrakeScene(vtk_path, MODULUS, other, X_WO=flip)
    # Drake's other body in ours is X_OO' = flip, so X_WS = X_WO' X_O'S = flip flip⁻¹ X_SO⁻¹ = X_SO⁻¹.
    sensor_poses = [np.linalg.inv(_matrix(row)) for row in poses]
    assert all(len(scene.query(X_WS)) == 1 for X_WS in sensor_poses), "every benchmark pose must be in contact"

    def time_once():
        start = time.perf_counter()
        for X_WS in sensor_poses:
            scene.query(X_WS)
        return (time.perf_counter() - start) / len(poses)

    return time_once


def _wrench(field, clusters, other, capacity):
    """hydrotact's timed work for one pose row: the surface's force, torque, area and
    whether its buffers overflowed."""

    def wrench(row):
        surface = calc_contact_surface(field, other, make_pose(row[:3], row[3:]), capacity, clusters)
        force, torque = surface.calc_wrench()
        return force, torque, surface.total_area, surface.did_overflow

    return wrench


def _ours_timer(field, clusters, other, poses, capacity, chunk):
    """A function timing one jitted call of hydrotact's surfaces and wrenches over
    `poses` (seconds a batch), compiled and checked for overflow first."""
    time_once, result = batched_over_poses(_wrench(field, clusters, other, capacity), poses, chunk)
    assert not bool(np.any(result[3])), "capacity too small for the benchmark poses"
    return time_once


def time_by_buffer(wrench, poses, capacity, chunk):
    """XLA's own per-fusion times (`jax.profiler.trace`) of one jitted batch of
    `wrench(row)` over `poses`, chunks of `chunk`, summed by the buffer each fusion's
    output is sized by, so that the stage that costs shows by its buffer (polygons,
    pairs, ...).

    **Returns:** ({buffer: microseconds a pose}, [(microseconds a pose, fusion, its
    output's shape)] of the five costliest fusions).
    """
    batch = jnp.asarray(poses).reshape(-1, chunk, poses.shape[1])
    run = jax.jit(lambda batch: jax.lax.map(jax.vmap(wrench), batch))
    jax.block_until_ready(run(batch))
    names = {capacity.polygons: "polygons", capacity.pairs: "candidate pairs", capacity.others: "near triangles", capacity.tets: "near tets"}
    shapes, buffers = {}, {}
    for line in run.lower(batch).compile().as_text().splitlines():
        match = re.match(r"\s*(?:ROOT )?%?([\w.\-]+) = \(?(\w+\[([\d,]*)\])", line)
        if match:
            sizes = [int(d) for d in match.group(3).split(",") if d]
            shapes[match.group(1)] = match.group(2)
            buffers[match.group(1)] = next((names[d] for d in sizes if d in names), "other")
    fusions = collections.Counter()
    repeats = 3
    with tempfile.TemporaryDirectory() as trace_dir:
        with jax.profiler.trace(trace_dir, create_perfetto_trace=True):
            for _ in range(repeats):
                jax.block_until_ready(run(batch))
        (trace,) = Path(trace_dir).rglob("*.trace.json.gz")
        events = json.load(gzip.open(trace))
    for event in events["traceEvents"] if isinstance(events, dict) else events:
        if event.get("ph") == "X" and event["name"] in shapes:
            fusions[event["name"]] += event.get("dur", 0) / repeats / len(poses)
    totals = collections.Counter()
    for name, microseconds in fusions.items():
        totals[buffers[name]] += microseconds
    return dict(totals.most_common()), [(microseconds, name, shapes[name]) for name, microseconds in fusions.most_common(5)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 64, 1024])
    parser.add_argument("--chunk", type=int, help="poses per vmapped chunk (lax.map over chunks); default: CPU_POSE_GROUP on a CPU, the batch elsewhere")
    parser.add_argument("--cases", nargs="+", help="run only the cases whose names contain one of these words")
    parser.add_argument("--drake-poses", type=int, default=256, help="poses Drake is timed over (each case's first ones)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rounds", type=int, default=5, help="rounds of Drake's pass and hydrotact's batches timed in turn")
    parser.add_argument("--no-profile", action="store_true", help="skip XLA's profile of the case furthest under Drake")
    args = parser.parse_args()
    from pydrake.geometry import HalfSpace as DrakeHalfSpace

    machine = describe_machine()
    print(f"machine: {machine}")
    print("| case | batch | hydrotact surfaces/s (rounds' range) | Drake surfaces/s (rounds' range) | ratio of medians (rounds' range) |\n|---|---:|---:|---:|---:|")
    rows, profiled = [], {}
    chunks = {batch: min(args.chunk or (CPU_POSE_GROUP if jax.default_backend() == "cpu" else batch), batch) for batch in args.batches}
    largest = max(args.batches)
    with tempfile.TemporaryDirectory() as scratch:
        probes = {name: make() for name, make in PROBES.items()}
        paths = {}
        for name, probe in probes.items():
            paths[name] = str(Path(scratch) / f"{name}.obj")
            probe.write_obj(paths[name])
        cases = {case: CASES[case] for case in CASES if not args.cases or any(word in case for word in args.cases)}
        fields = {}
        for case, (sensor, probe_name, draw) in cases.items():
            if sensor not in fields:
                vtk = write_mesh(make_seed_mesh(sensor), Path(scratch) / f"{sensor}.vtk")
                mesh, _ = read_mesh(vtk)
                field = make_pressure_field(mesh, calc_distance_field(mesh), MODULUS)
                fields[sensor] = (vtk, field, make_tet_clusters(field.vertices, field.tets))
            vtk, field, clusters = fields[sensor]
            ours_other = HalfSpace() if probe_name == "half-space" else probes[probe_name]
            drake_other = DrakeHalfSpace() if probe_name == "half-space" else paths[probe_name]
            poses = draw(largest, probes.get(probe_name), case_rng(args.seed, case))
            drake = _drake_timer(vtk, drake_other, poses[: args.drake_poses])
            # Start small and let compute_contact_surface grow the buffers to every pose of the case.
            X_SO = jax.vmap(make_pose)(jnp.asarray(poses[:, :3]), jnp.asarray(poses[:, 3:]))
            _, capacity = compute_contact_surface(field, ours_other, X_SO, Capacity(64, 64, 64, 256))
            ours = {batch: _ours_timer(field, clusters, ours_other, poses[:batch], capacity, chunks[batch]) for batch in args.batches}
            profiled[case] = (field, clusters, ours_other, poses, capacity)
            # Timed in turn, so that both see the same moments of the machine (hydrotact's
            # rate, on two threads, moves more between moments than Drake's on one).
            drake_rates, our_rates = [], {batch: [] for batch in args.batches}
            for _ in range(args.rounds):
                drake_rates.append(1.0 / drake())
                for batch in args.batches:
                    our_rates[batch].append(batch / ours[batch]())
            for batch in args.batches:
                mine, theirs = statistics.median(our_rates[batch]), statistics.median(drake_rates)
                ratios = [a / b for a, b in zip(our_rates[batch], drake_rates, strict=True)]
                row = {
                    "case": case,
                    "batch": batch,
                    "capacity": list(capacity.sizes),
                    "chunk": chunks[batch],
                    "ours_surfaces_per_s": mine,
                    "drake_surfaces_per_s": theirs,
                    "ratio": mine / theirs,
                    "ours_rounds": our_rates[batch],
                    "drake_rounds": drake_rates,
                }
                rows.append(row)
                print(
                    f"| {case} | {batch} | {mine:,.0f} ({min(our_rates[batch]):,.0f}-{max(our_rates[batch]):,.0f}) "
                    f"| {theirs:,.0f} ({min(drake_rates):,.0f}-{max(drake_rates):,.0f}) | {row['ratio']:.2f} ({min(ratios):.2f}-{max(ratios):.2f}) |",
                    flush=True,
                )
    if not args.no_profile:
        # The case furthest under Drake at the smallest batch of 64 or more: where its time goes.
        batch = min((b for b in args.batches if b >= 64), default=min(args.batches))
        slowest = min((row for row in rows if row["batch"] == batch), key=lambda row: row["ratio"])
        field, clusters, other, poses, capacity = profiled[slowest["case"]]
        chunk = slowest["chunk"]
        by_buffer, fusions = time_by_buffer(_wrench(field, clusters, other, capacity), poses[: batch - batch % chunk], capacity, chunk)
        print(f"profile of the case furthest under Drake, {slowest['case']} (batch {batch}, buffers {capacity.sizes}), XLA's fusion times:")
        print("  us a pose by the buffer a fusion's output is sized by: " + ", ".join(f"{k} {v:.0f}" for k, v in by_buffer.items()))
        print("  costliest fusions: " + "; ".join(f"{name} {shape} {us:.0f} us" for us, name, shape in fusions))
    print(f"written: {write_results('contact', machine, rows)}")


if __name__ == "__main__":
    main()
