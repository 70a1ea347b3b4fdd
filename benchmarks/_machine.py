"""Name the machine a benchmark ran on."""

import os
import platform


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
        "jax": jax.__version__,
        "jax_backend": jax.default_backend(),
        "device": getattr(device, "device_kind", str(device)),
        "python": platform.python_version(),
    }


def write_results(name: str, machine: dict, rows: list) -> "Path":
    """Write benchmarks/results/NAME-BACKEND.json ({machine, rows}) and return its path."""
    import json
    from pathlib import Path

    out = Path(__file__).parent / "results" / f"{name}-{machine['jax_backend']}.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"machine": machine, "rows": rows}, indent=2) + "\n")
    return out
