"""Name the machine a benchmark ran on."""

import os
import platform
from pathlib import Path


def describe_machine() -> dict:
    import jax

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    device = jax.devices()[0]
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "cores_usable": len(os.sched_getaffinity(0)),  # fewer under taskset
        "jax": jax.__version__,
        "jax_backend": jax.default_backend(),
        "device": getattr(device, "device_kind", str(device)),
        "python": platform.python_version(),
    }


def write_results(name: str, machine: dict, rows: list) -> Path:
    """Write benchmarks/results/NAME-BACKEND.json ({machine, rows}) and return its path."""
    import json
    from pathlib import Path

    out = Path(__file__).parent / "results" / f"{name}-{machine['jax_backend']}.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
    return out


def batched_over_poses(per_pose, translations, chunk: int):
    """Compile `per_pose(row)` over a batch of rows (count, 3 or more) as one jitted
    call: vmap over chunks of `chunk` poses, lax.map over the chunks (the last chunk
    padded with repeats of the last pose). Compiles and runs once.

    **Returns:** (time_once, the outputs with the padding removed): `time_once()` runs
    the batch once more and returns its seconds.
    """
    import time

    import jax
    import jax.numpy as jnp
    import numpy as np

    count = len(translations)
    chunk = min(chunk, count)
    padded = int(np.ceil(count / chunk)) * chunk
    batch = jnp.asarray(np.concatenate([translations, np.repeat(translations[-1:], padded - count, axis=0)]))
    width = batch.shape[1]  # 3 (a translation) or more (a translation and a rotation vector)

    @jax.jit
    def run(batch):
        return jax.lax.map(jax.vmap(per_pose), batch.reshape(-1, chunk, width))

    result = jax.block_until_ready(run(batch))

    def time_once():
        start = time.perf_counter()
        jax.block_until_ready(run(batch))
        return time.perf_counter() - start

    return time_once, jax.tree_util.tree_map(lambda a: np.asarray(a).reshape(padded, *a.shape[2:])[:count], result)


def time_over_poses(per_pose, translations, chunk: int, repeats: int):
    """`batched_over_poses`, timed `repeats` times.

    **Returns:** (median seconds per batch, the outputs with the padding removed).
    """
    import statistics

    time_once, outputs = batched_over_poses(per_pose, translations, chunk)
    return statistics.median(time_once() for _ in range(repeats)), outputs
