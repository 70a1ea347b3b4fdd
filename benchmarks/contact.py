"""Benchmark: contact surfaces per second, against Drake's query in the same run.

Cases: pad5x5 (27k tets) pressed by the 2 mm cylinder probe (6 mm long), upright;
by the default 2 mm cylinder (10 mm long) tilted 15 degrees about x, then 10 about y;
by a 4 x 4 x 2 mm box turned 45 degrees about x, an edge pressing first; and sphere8
(28k tets) pressed by a rigid half-space; the distance field throughout, so Drake
computes the same surfaces from the same meshes (tests/test_contact_drake.py checks
they agree). Poses sweep the probe across the sensor, its lowest point at a fixed
depth.

- Drake: `QueryObject.ComputeContactSurfaces` (polygons), one pose at a time, after
  updating the free body's pose; mean seconds per query.
- hydrotact: the contact surface and its wrench for a batch of poses in one jitted
  call (vmap over chunks of poses, lax.map over chunks: by default chunks of
  hydrotact's CPU_POSE_GROUP on a CPU, the whole batch on an accelerator), float64,
  with the clustered tet search; timed after compilation, median of repeats.

Run: `.venv/bin/python benchmarks/contact.py [--batches 1 64 4096] [--cases box tilted]`.
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
    make_tet_clusters,
)
from hydrotact.field import calc_distance_field, make_pressure_field  # noqa: E402
from hydrotact.mesh import make_seed_mesh, read_mesh, write_mesh  # noqa: E402

MODULUS = 2e5
PAD_TOP = 4e-3  # pad5x5's top face
DEPTH = 0.4e-3  # of the probe's lowest point below it
TILTED = Rotation.from_euler("xy", [15.0, 10.0], degrees=True).as_rotvec()  # 15 degrees about x, then 10 about (fixed) y
EDGE_FIRST = np.array([np.pi / 4, 0.0, 0.0])


def _poses(case, count, probe, rotation_vector):
    """Translations of the probe across the sensor (count, 3)."""
    if case.startswith("pad5x5"):
        x = np.linspace(-4.4e-3, 4.4e-3, count)
        lowest = np.min(np.asarray(probe.vertices_R) @ np.asarray(make_pose((0, 0, 0), rotation_vector).rotation).T, axis=0)[2]
        return np.column_stack([x, 0.3 * x, np.full(count, PAD_TOP - DEPTH - lowest)])
    x = np.linspace(-3e-3, 3e-3, count)
    return np.column_stack([x, -0.5 * x, np.full(count, 14.0e-3 - 1e-3)])


def _drake_seconds_per_query(vtk_path, other, translations, rotation_vector, repeats=3):
    """Drake's seconds per query. The probe is fixed (turned by `rotation_vector`) and
    the sensor moves by the opposite translation: the same relative poses as ours."""
    flip = type(other).__name__ == "HalfSpace"
    X_WO = np.eye(4)
    X_WO[:3, :3] = np.asarray(make_pose((0, 0, 0), rotation_vector).rotation)
    if flip:  # Drake's half-space is solid below z = 0; ours above
        X_WO[:3, :3] = np.diag([1.0, -1.0, -1.0])
    scene = DrakeScene(vtk_path, MODULUS, other, X_WO=X_WO)
    counts = []
    timings = []
    for _ in range(repeats):
        start = time.perf_counter()
        for translation in translations:
            X_WS = np.eye(4)
            X_WS[:3, 3] = -np.asarray(translation)
            counts.append(len(scene.query(X_WS)))
        timings.append((time.perf_counter() - start) / len(translations))
    assert min(counts) == 1, "every benchmark pose must be in contact"
    return statistics.median(timings)


def _ours_seconds_per_batch(field, other, translations, rotation_vector, capacity, chunk, repeats=3):
    clusters = make_tet_clusters(field.vertices, field.tets)

    def wrench(translation):
        surface = calc_contact_surface(field, other, make_pose(translation, rotation_vector), capacity, clusters)
        force, torque = surface.calc_wrench()
        return force, torque, surface.total_area, surface.did_overflow

    seconds, result = time_over_poses(wrench, translations, chunk, repeats)
    assert not bool(np.any(result[3])), "capacity too small for the benchmark poses"
    return seconds, result[0]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 64, 4096])
    parser.add_argument(
        "--chunk", type=int, help="poses per vmapped chunk (lax.map over chunks); default: CPU_POSE_GROUP on a CPU, the batch elsewhere"
    )
    parser.add_argument("--cases", nargs="+", help="run only the cases whose names contain one of these words")
    args = parser.parse_args()
    from pydrake.geometry import HalfSpace as DrakeHalfSpace

    machine = describe_machine()
    print(f"machine: {machine}")
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        probes = {
            "cylinder": make_cylinder_probe(2e-3, length=6e-3),
            "tilted": make_cylinder_probe(2e-3),
            "box": make_box_probe((4e-3, 4e-3, 2e-3)),
        }
        paths = {}
        for name, probe in probes.items():
            paths[name] = str(Path(scratch) / f"{name}.obj")
            probe.write_obj(paths[name])
        no_turn = np.zeros(3)
        cases = {
            "pad5x5 + 2 mm cylinder": ("pad5x5", probes["cylinder"], paths["cylinder"], no_turn),
            "pad5x5 + tilted 2 mm cylinder": ("pad5x5", probes["tilted"], paths["tilted"], TILTED),
            "pad5x5 + edge-first box": ("pad5x5", probes["box"], paths["box"], EDGE_FIRST),
            "sphere8 + half-space": ("sphere8", HalfSpace(), DrakeHalfSpace(), no_turn),
        }
        if args.cases:
            cases = {case: cases[case] for case in cases if any(word in case for word in args.cases)}
        for case, (sensor, ours_other, drake_other, turn) in cases.items():
            vtk = write_mesh(make_seed_mesh(sensor), Path(scratch) / f"{sensor}.vtk")
            mesh, _ = read_mesh(vtk)
            field = make_pressure_field(mesh, calc_distance_field(mesh), MODULUS)
            drake_translations = _poses(case, 64, ours_other, turn)
            drake_seconds = _drake_seconds_per_query(vtk, drake_other, drake_translations, turn)
            # Start small and let compute_contact_surface grow the buffers to these poses.
            X_SO = jax.vmap(make_pose)(jnp.asarray(drake_translations), jnp.broadcast_to(jnp.asarray(turn), (64, 3)))
            _, capacity = compute_contact_surface(field, ours_other, X_SO, Capacity(64, 64, 64, 256))
            for batch in args.batches:
                chunk = args.chunk or (CPU_POSE_GROUP if jax.default_backend() == "cpu" else batch)
                translations = _poses(case, batch, ours_other, turn)
                seconds, _ = _ours_seconds_per_batch(field, ours_other, translations, turn, capacity, chunk)
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
