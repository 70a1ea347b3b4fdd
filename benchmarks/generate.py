"""Dataset generation speed: distinct poses/s and samples/s of `hydrotact generate`.

Engines, each in a fresh process on the same poses (the approach samples of the
seed-scale regime's first events, sphere8, a 3 mm sphere):

- `loop`: the baseline a user would write without the generator: one
  `hydrotact.sim.simulate` call per event (its own trajectory of approach poses), in a
  Python loop;
- `local-N`: `hydrotact.datasets.PoseEngine` on N host devices
  (`XLA_FLAGS=--xla_force_host_platform_device_count=N`; on a GPU machine, its devices);
- `ray-2`: the same engine sending its slices to a local Ray cluster of 2 worker CPUs.

Each engine's first batch (compilation) is timed apart from the rest. Then, with
`--full`, the seed-scale dataset itself (2500 events, about 3 h at 100 Hz, sphere8)
is generated once in process: wall time, peak memory, size on disk.

    .venv/bin/python benchmarks/generate.py [--poses 2048] [--engines loop,local-1,local-2,local-4,ray-2] [--full] [--output DIR]

Writes generate.json in DIR and prints a table.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _machine import describe_machine

RAYS = 64
RAY = str(Path(sys.executable).parent / "ray")  # the environment's own Ray command


def _rows(count: int):
    """Approach poses of the default regime's first events: (rows (n, 6), events' slices)."""
    import numpy as np

    from hydrotact.datasets import DatasetConfig, find_touchable_skin, sample_events
    from hydrotact.sensors import load_sensor

    spec = load_sensor("sphere8")
    config = DatasetConfig(events=max(8, count // 8))
    plan = sample_events(find_touchable_skin(spec, spec.make_mesh(check=False)), config, np.random.default_rng(0))
    rows, slices = [], []
    for event in range(plan.num_events):
        steps = np.arange(0.0, 1.5e-3 + config.clearance, plan.speeds[event] / config.rate_hz) - config.clearance
        tips = plan.points[event] + steps[:, None] * plan.directions[event]
        start = sum(len(r) for r in rows)
        rows.append(np.column_stack([tips, np.repeat(plan.rotation_vectors[event][None], len(steps), axis=0)]))
        slices.append((start, start + len(steps)))
        if slices[-1][1] >= count:
            break
    return np.vstack(rows)[:count], [(a, min(b, count)) for a, b in slices if a < count]


def _engine_run(name: str, count: int) -> dict:
    """In the child process: time one engine on `count` poses."""
    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from hydrotact.contact import parse_probe
    from hydrotact.datasets import PoseEngine
    from hydrotact.sensors import load_sensor
    from hydrotact.sim import make_sensor_model, make_trajectory, simulate
    from hydrotact.visco import make_prony

    rows, events = _rows(count)
    spec = load_sensor("sphere8")
    model = make_sensor_model(spec, num_rays=RAYS)
    probe = parse_probe("sphere:r=3mm")
    warm, rest = rows[:256], rows[256:]
    if name == "loop":
        material = make_prony(1e6)

        def run(chosen):
            for a, b in chosen:
                trajectory = make_trajectory(np.arange(b - a) / 100.0, rows[a:b, :3], rows[a:b, 3:])
                simulate(model, material, probe, trajectory, cache=False)

        first_events = [e for e in events if e[1] <= 256]
        start = time.perf_counter()
        run(first_events)
        compile_s = time.perf_counter() - start
        later = [e for e in events if e[0] >= 256]
        start = time.perf_counter()
        run(later)
        poses = sum(b - a for a, b in later)
    else:
        engine = PoseEngine(model, probe, "auto" if name.startswith("ray") else None)
        start = time.perf_counter()
        engine.compute(warm)
        compile_s = time.perf_counter() - start
        start = time.perf_counter()
        engine.compute(rest)
        poses = len(rest)
    elapsed = time.perf_counter() - start
    return {"engine": name, "devices": len(jax.local_devices()), "first_batch_s": compile_s, "poses": poses, "seconds": elapsed, "poses_per_s": poses / elapsed}


def _child(name: str, count: int, folder: Path) -> dict:
    env = dict(os.environ)
    ray = None
    if name.startswith("local-"):
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={name.split('-')[1]}".strip()
    if name.startswith("ray-"):
        ray = Path(tempfile.mkdtemp(prefix="ray-", dir="/tmp"))  # Ray's socket paths must stay under 108 bytes
        subprocess.run([RAY, "start", "--head", "--num-cpus=2", "--port=0", "--include-dashboard=false", f"--temp-dir={ray}", "--disable-usage-stats"], check=True, capture_output=True, env=env)
    try:
        out = subprocess.run([sys.executable, __file__, "--child", name, "--poses", str(count)], capture_output=True, text=True, env=env, check=False)
    finally:
        if ray is not None:
            subprocess.run([RAY, "stop", "--force"], capture_output=True, env=env)
    if out.returncode != 0:
        raise SystemExit(f"{name} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _full(folder: Path) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    from hydrotact.data import make_material_document, write_material
    from hydrotact.datasets import generate_dataset

    material = write_material(folder / "material.json", make_material_document(6e6, [2.5e6, 1.5e6], [0.8, 12.0], name="benchmark silicone"))
    start = time.perf_counter()
    manifest = generate_dataset("sphere8", folder / "sphere8_seed_scale", material=material, progress=True)
    from hydrotact.datasets import load_dataset
    from hydrotact.viz import plot_dataset

    plot_dataset(load_dataset(folder / "sphere8_seed_scale"), folder / "sphere8_seed_scale")
    elapsed = time.perf_counter() - start
    size = sum(path.stat().st_size for path in (folder / "sphere8_seed_scale").iterdir())
    return {
        "events": manifest["num_events"], "rows": manifest["num_rows"], "hours": manifest["duration_s"] / 3600, "distinct_poses": manifest["num_distinct_poses"],
        "seconds": elapsed, "samples_per_s": manifest["num_rows"] / elapsed, "poses_per_s": manifest["num_distinct_poses"] / elapsed,
        "peak_rss_GiB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, "size_MiB": size / 2**20,
        "channel_std_kPa": [round(1e-3 * s, 2) for s in manifest["statistics"]["channel_std_Pa"]],
        "events_short_of_target": manifest["statistics"]["events_short_of_target"],
        "statistics": manifest["statistics"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=2048)
    parser.add_argument("--engines", default="loop,local-1,local-2,local-4,ray-2")
    parser.add_argument("--full", action="store_true")
    parser.add_argument("--output", type=Path)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_engine_run(args.child, args.poses)))
        return
    folder = args.output or Path(tempfile.mkdtemp(prefix="hydrotact-generate-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    results = {"machine": describe_machine(), "rays": RAYS, "engines": []}
    for name in filter(None, args.engines.split(",")):
        results["engines"].append(_child(name, args.poses, folder))
        print(json.dumps(results["engines"][-1]), flush=True)
    if results["engines"]:
        base = results["engines"][0]["poses_per_s"]
        print(f"\n| engine | devices | first batch s | poses | poses/s | x {results['engines'][0]['engine']} |\n|---|---:|---:|---:|---:|---:|")
        for row in results["engines"]:
            print(f"| {row['engine']} | {row['devices']} | {row['first_batch_s']:.1f} | {row['poses']} | {row['poses_per_s']:.1f} | {row['poses_per_s'] / base:.2f} |")
    if args.full:
        results["full"] = _full(folder)
        print(json.dumps(results["full"], indent=2))
    (folder / "generate.json").write_text(json.dumps(results, indent=2) + "\n")
    print(f"written {folder / 'generate.json'}")


if __name__ == "__main__":
    main()
