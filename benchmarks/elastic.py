"""Benchmark: elastic barometers against the ray-cast cones, on a built-in curved sensor.

In one run, for the sensor's built-in layout (every barometer made `elastic`, nu 0.49,
0.5 mm ports):

- the receptive fields' one-off cost, cold (no cache): the multigrid hierarchy's
  set-up, the CG solves (steps, seconds) and the process's peak memory; beside it one
  barometer solved with the block-Jacobi preconditioner alone (the baseline);
- the per-frame cost of a press: the contact surface and the elastic readings against
  the contact surface and the ray-cast cones (64 rays), the same poses in one jitted,
  vmapped call each (medians of repeats after compilation);
- coverage: the 3 mm sphere (the dataset generator's probe) pressed along the inward
  normal at skin points uniform over the touchable skin, each reading scaled to a
  0.5 N press; a channel "moves" when it changes by more than 3 noise stds of the
  part (BMP388: 0.03 Pa RMS); the fraction of points that move no channel, one, two or
  more; the points no channel sees by more than 1 % of its own largest response;
  each channel's largest response.

Run: `.venv/bin/python benchmarks/elastic.py [--sensor sphere8] [--points 400]`.
Writes benchmarks/results/elastic_SENSOR-cpu.json and elastic_SENSOR_coverage.png.
"""

import argparse
import resource
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _machine import describe_machine, write_results  # noqa: E402

from hydrotact.contact import make_pose, make_sphere_probe  # noqa: E402
from hydrotact.datasets import find_touchable_skin, pressing_rotation_vectors  # noqa: E402
from hydrotact.elastic import (  # noqa: E402
    calc_receptive_fields,
    make_barometer_ports,
    make_elastic_problem,
    make_multigrid_preconditioner,
    make_receptive_fields,
)
from hydrotact.sensors import load_sensor, with_receptive_fields  # noqa: E402
from hydrotact.sim import SimCapacity, calc_unit_response, make_sensor_model  # noqa: E402

NOISE_RMS_PA = 0.03  # BMP388
PRESS_N = 0.5
DEPTH = 0.3e-3


def elastic_spec(name: str):
    return with_receptive_fields(load_sensor(name), {"kind": "elastic"})


def _peak_rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def time_fields(spec, mesh) -> dict:
    problem = make_elastic_problem(mesh, spec.poisson_ratio)
    start = time.perf_counter()
    make_multigrid_preconditioner(problem)
    setup = time.perf_counter() - start
    start = time.perf_counter()
    fields = make_receptive_fields(
        mesh, spec.taxel_positions_S, spec.taxel_axes_S, spec.taxel_field_sizes, spec.taxel_elastic_readings, spec.poisson_ratio, cache=False, progress=True
    )
    total = time.perf_counter() - start
    ports = make_barometer_ports(spec.taxel_positions_S[:1], spec.taxel_axes_S[:1], spec.taxel_field_sizes[:1])
    start = time.perf_counter()
    baseline = calc_receptive_fields(problem, ports, rtol=1e-10, max_steps=20 * problem.num_nodes + 1000, throw=False)
    baseline.responses.block_until_ready()
    baseline_seconds = time.perf_counter() - start
    return {
        "unknowns": problem.num_unknowns,
        "barometers": spec.num_taxels,
        "multigrid_setup_s": setup,
        "fields_s": total,
        "fields_s_per_barometer": total / spec.num_taxels,
        "max_cg_steps": int(fields.num_steps),
        "block_jacobi_one_barometer_s": baseline_seconds,
        "block_jacobi_cg_steps": int(baseline.num_steps),
        "speedup_per_barometer": baseline_seconds / (total / spec.num_taxels),
        "peak_rss_gib": _peak_rss_gib(),
    }


def press_poses(spec, mesh, count: int, seed: int = 0):
    from hydrotact.datasets._events import sample_skin_points

    skin = find_touchable_skin(spec, mesh)
    points, normals, _ = sample_skin_points(skin, count, np.random.default_rng(seed))
    rotations = pressing_rotation_vectors(-normals)
    tips = points - DEPTH * normals
    return points, tips, rotations


CHUNK = 16  # poses per vmapped chunk (lax.map over the chunks), as the library's CPU pose group


def unit_batch(probe, capacity):
    @jax.jit
    def run(model, tips, rotations):
        def chunk(args):
            return jax.vmap(lambda p, r: calc_unit_response(model, probe, make_pose(p, r), capacity))(*args)

        out = jax.lax.map(chunk, (tips.reshape(-1, CHUNK, 3), rotations.reshape(-1, CHUNK, 3)))
        return jax.tree_util.tree_map(lambda a: a.reshape(-1, *a.shape[2:]), out)

    return run


def timed(run, *args, repeats: int = 3):
    result = jax.block_until_ready(run(*args))
    timings = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run(*args))
        timings.append(time.perf_counter() - start)
    return float(np.median(timings)), result


def coverage(unit, modulus: float) -> dict:
    force = np.linalg.norm(np.asarray(unit.force_S), axis=1) * modulus
    touching = force > 1e-6
    readings = np.abs(np.asarray(unit.taxel_pressures)) * modulus * (PRESS_N / np.where(touching, force, 1.0))[:, None]
    readings = readings[touching]
    moving = readings > 3.0 * NOISE_RMS_PA
    counts = moving.sum(axis=1)
    largest = readings.max(axis=0)
    seen = readings > 0.01 * np.where(largest > 0, largest, np.inf)[None]
    return {
        "points": int(touching.sum()),
        "fraction_moving_0": float(np.mean(counts == 0)),
        "fraction_moving_1": float(np.mean(counts == 1)),
        "fraction_moving_2_or_more": float(np.mean(counts >= 2)),
        "fraction_seen_by_none_over_1pct": float(np.mean(seen.sum(axis=1) == 0)),
        "fraction_seen_by_2_or_more_over_1pct": float(np.mean(seen.sum(axis=1) >= 2)),
        "largest_response_pa_at_0p5N": [float(v) for v in largest],
        "channels_never_moving": [int(k) for k in np.flatnonzero(~moving.any(axis=0))],
    }, counts, touching


def plot(path, points, results):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(results), figsize=(5 * len(results), 4.4), constrained_layout=True)
    for axis, (name, (counts, touching)) in zip(np.atleast_1d(axes), results.items(), strict=True):
        shown = points[touching]
        scatter = axis.scatter(shown[:, 0] * 1e3, shown[:, 1] * 1e3, c=counts, cmap="viridis", vmin=0, vmax=8, s=14)
        axis.set_title(f"{name}: channels moved by a 0.5 N press")
        axis.set_xlabel("x (mm)")
        axis.set_ylabel("y (mm)")
        axis.set_aspect("equal")
        figure.colorbar(scatter, ax=axis, label="channels > 3 noise std")
    figure.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sensor", default="sphere8", choices=["sphere8", "ellipsoid8"])
    parser.add_argument("--points", type=int, default=400)
    parser.add_argument("--skip-fields", action="store_true", help="read the fields from the cache instead of timing them cold (keeps the JSON's earlier timing)")
    args = parser.parse_args()
    machine = describe_machine()
    spec_elastic, spec_cone = elastic_spec(args.sensor), load_sensor(args.sensor)
    mesh = spec_cone.make_mesh()
    row = {"sensor": args.sensor, "poisson_ratio": spec_elastic.poisson_ratio, "port_radius_m": float(spec_elastic.taxel_field_sizes[0])}
    if not args.skip_fields:
        row["fields"] = time_fields(spec_elastic, mesh)
        print(row["fields"], flush=True)
    else:
        import json

        earlier = Path(__file__).parent / "results" / f"elastic_{args.sensor}-{machine['jax_backend']}.json"
        if earlier.is_file():
            row["fields"] = json.loads(earlier.read_text())["rows"][0].get("fields")
    models = {"elastic": make_sensor_model(spec_elastic, num_rays=64), "cone": make_sensor_model(spec_cone, num_rays=64)}
    probe = make_sphere_probe(3e-3)
    points, tips, rotations = press_poses(spec_cone, mesh, -(-args.points // CHUNK) * CHUNK)
    capacity = SimCapacity(tets=1024, others=1536, pairs=8192, polygons=8192, taxel_pairs=8192, taxel_pieces=16384)
    modulus = 1e7
    row["per_frame"], results = {}, {}
    for name, model in models.items():
        seconds, unit = timed(unit_batch(probe, capacity), model, jnp.asarray(tips), jnp.asarray(rotations))
        assert not np.any(np.asarray(unit.did_overflow)), name
        row["per_frame"][name] = {"frames": len(tips), "seconds": seconds, "frames_per_s": len(tips) / seconds}
        row[f"coverage_{name}"], counts, touching = coverage(unit, modulus)
        results[name] = (counts, touching)
        print(name, row["per_frame"][name], row[f"coverage_{name}"], flush=True)
    row["per_frame_ratio_elastic_over_cone_speed"] = row["per_frame"]["elastic"]["frames_per_s"] / row["per_frame"]["cone"]["frames_per_s"]
    out = write_results(f"elastic_{args.sensor}", machine, [row])
    figure = Path(__file__).parent / "results" / f"elastic_{args.sensor}_coverage.png"
    plot(figure, points, results)
    print(f"wrote {out} and {figure}")


if __name__ == "__main__":
    main()
