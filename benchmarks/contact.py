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
  updating the free body's pose; mean seconds per query.
- hydrotact: the contact surface and its wrench for a batch of poses in one jitted
  call (vmap over chunks of poses, lax.map over chunks: by default chunks of
  hydrotact's CPU_POSE_GROUP on a CPU, the whole batch on an accelerator), float64,
  with the clustered tet search, the buffers grown to the batch's poses; timed after
  compilation, median of repeats.

Run: `.venv/bin/python benchmarks/contact.py [--batches 1 64 1024] [--cases box sphere8]`.
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _machine import describe_machine, time_over_poses, write_results  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
from drake_reference import DrakeScene  # noqa: E402

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


def _pad_poses(count, probe, rotation_vector, rng):
    """(count, 6): translations and rotation vectors of `probe` turned by
    `rotation_vector`, at x, y uniform within 4.4 mm of the pad's centre and its lowest
    point 0.1-0.5 mm below the top."""
    lowest = np.min(np.asarray(probe.vertices_R) @ np.asarray(make_pose((0, 0, 0), rotation_vector).rotation).T, axis=0)[2]
    xy = rng.uniform(-4.4e-3, 4.4e-3, (count, 2))
    z = PAD_TOP - rng.uniform(*PAD_DEPTHS, count) - lowest
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


def _drake_seconds_per_query(vtk_path, other, poses, repeats=3):
    """Drake's seconds per query. The other body is fixed in the world (the
    half-space turned upside down: Drake's is solid below z = 0, ours above) and the
    sensor moves to the pose that gives the same relative pose as ours."""
    flip = np.diag([1.0, -1.0, -1.0, 1.0]) if type(other).__name__ == "HalfSpace" else np.eye(4)
    scene = DrakeScene(vtk_path, MODULUS, other, X_WO=flip)
    counts, timings = [], []
    # Drake's other body in ours is X_OO' = flip, so X_WS = X_WO' X_O'S = flip flip⁻¹ X_SO⁻¹ = X_SO⁻¹.
    sensor_poses = [np.linalg.inv(_matrix(row)) for row in poses]
    for _ in range(repeats):
        start = time.perf_counter()
        for X_WS in sensor_poses:
            counts.append(len(scene.query(X_WS)))
        timings.append((time.perf_counter() - start) / len(poses))
    assert min(counts) == 1, "every benchmark pose must be in contact"
    return statistics.median(timings)


def _ours_seconds_per_batch(field, other, poses, capacity, chunk, repeats=3):
    clusters = make_tet_clusters(field.vertices, field.tets)

    def wrench(row):
        surface = calc_contact_surface(field, other, make_pose(row[:3], row[3:]), capacity, clusters)
        force, torque = surface.calc_wrench()
        return force, torque, surface.total_area, surface.did_overflow

    seconds, result = time_over_poses(wrench, poses, chunk, repeats)
    assert not bool(np.any(result[3])), "capacity too small for the benchmark poses"
    return seconds, result[0]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 64, 1024])
    parser.add_argument(
        "--chunk", type=int, help="poses per vmapped chunk (lax.map over chunks); default: CPU_POSE_GROUP on a CPU, the batch elsewhere"
    )
    parser.add_argument("--cases", nargs="+", help="run only the cases whose names contain one of these words")
    parser.add_argument("--drake-poses", type=int, default=256, help="poses Drake is timed over (each case's first ones)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    from pydrake.geometry import HalfSpace as DrakeHalfSpace

    machine = describe_machine()
    print(f"machine: {machine}")
    print("| case | batch | hydrotact surfaces/s | Drake surfaces/s | ratio |\n|---|---:|---:|---:|---:|")
    rows = []
    largest = max(args.batches)
    with tempfile.TemporaryDirectory() as scratch:
        probes = {
            "cylinder": make_cylinder_probe(2e-3, length=6e-3),
            "tilted": make_cylinder_probe(2e-3),
            "box": make_box_probe((4e-3, 4e-3, 2e-3)),
            "sphere": make_sphere_probe(3e-3),
        }
        paths = {}
        for name, probe in probes.items():
            paths[name] = str(Path(scratch) / f"{name}.obj")
            probe.write_obj(paths[name])
        rng = lambda case: np.random.default_rng([args.seed, sum(map(ord, case))])
        cases = {
            "pad5x5 + 2 mm cylinder": ("pad5x5", "cylinder", lambda n, r: _pad_poses(n, probes["cylinder"], np.zeros(3), r)),
            "pad5x5 + tilted 2 mm cylinder": ("pad5x5", "tilted", lambda n, r: _pad_poses(n, probes["tilted"], TILTED, r)),
            "pad5x5 + edge-first box": ("pad5x5", "box", lambda n, r: _pad_poses(n, probes["box"], EDGE_FIRST, r)),
            "pad5x5 + corner-first box": ("pad5x5", "box", lambda n, r: _pad_poses(n, probes["box"], CORNER_FIRST, r)),
            "sphere8 + 6 mm sphere (generator)": ("sphere8", "sphere", lambda n, r: _curved_poses("sphere8", n, r)),
            "ellipsoid8 + 6 mm sphere (generator)": ("ellipsoid8", "sphere", lambda n, r: _curved_poses("ellipsoid8", n, r)),
            "sphere8 + half-space": ("sphere8", "half-space", lambda n, r: _half_space_poses(n, r)),
        }
        if args.cases:
            cases = {case: cases[case] for case in cases if any(word in case for word in args.cases)}
        fields = {}
        for case, (sensor, probe_name, draw) in cases.items():
            if sensor not in fields:
                vtk = write_mesh(make_seed_mesh(sensor), Path(scratch) / f"{sensor}.vtk")
                mesh, _ = read_mesh(vtk)
                fields[sensor] = (vtk, make_pressure_field(mesh, calc_distance_field(mesh), MODULUS))
            vtk, field = fields[sensor]
            ours_other = HalfSpace() if probe_name == "half-space" else probes[probe_name]
            drake_other = DrakeHalfSpace() if probe_name == "half-space" else paths[probe_name]
            poses = draw(largest, rng(case))
            drake_seconds = _drake_seconds_per_query(vtk, drake_other, poses[: args.drake_poses])
            # Start small and let compute_contact_surface grow the buffers to every pose of the case.
            X_SO = jax.vmap(make_pose)(jnp.asarray(poses[:, :3]), jnp.asarray(poses[:, 3:]))
            _, capacity = compute_contact_surface(field, ours_other, X_SO, Capacity(64, 64, 64, 256))
            for batch in args.batches:
                chunk = args.chunk or (CPU_POSE_GROUP if jax.default_backend() == "cpu" else batch)
                seconds, _ = _ours_seconds_per_batch(field, ours_other, poses[:batch], capacity, chunk)
                row = {
                    "case": case,
                    "batch": batch,
                    "capacity": list(capacity.sizes),
                    "chunk": min(chunk, batch),
                    "ours_surfaces_per_s": batch / seconds,
                    "drake_surfaces_per_s": 1.0 / drake_seconds,
                    "ratio": (batch / seconds) * drake_seconds,
                }
                rows.append(row)
                print(
                    f"| {case} | {batch} | {row['ours_surfaces_per_s']:,.0f} | {row['drake_surfaces_per_s']:,.0f} | {row['ratio']:.2f} |",
                    flush=True,
                )
    print(f"written: {write_results('contact', machine, rows)}")


if __name__ == "__main__":
    main()
