"""Record `tests/data/regression_logs.npz`: the two logs that
`tests/test_forward_model.py` compares every later simulation with (to 1e-12).

Run only when a change to the simulation is meant to change these logs, and say in
`tests/data/README.md` which change and why:
`.venv/bin/python tests/data/record_regression_logs.py`.
"""

import json
import sys
from pathlib import Path

import jax
import numpy as np

# As the tests run (tests/conftest.py).
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))

from test_forward_model import simulate_regression_log  # noqa: E402

from hydrotact._files import atomic_path  # noqa: E402


def main():
    arrays = {}
    for name in ("demo", "sphere"):
        log = simulate_regression_log(name)
        arrays.update({f"{name}/{column}": np.asarray(values) for column, values in log.columns.items()})
        arrays[f"{name}/metadata"] = np.array(json.dumps(log.metadata, sort_keys=True))
        print(f"{name}: {len(log.columns)} columns, {len(next(iter(log.columns.values())))} samples", flush=True)
    path = HERE / "regression_logs.npz"
    with atomic_path(path) as tmp:
        np.savez_compressed(tmp, **arrays)
    print(f"written: {path}")


if __name__ == "__main__":
    main()
