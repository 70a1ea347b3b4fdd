"""Record `tests/data/tiny_dataset/`: a two-event sphere8 dataset (875 rows, one
shard, 31 kB) that `tests/test_bad_input.py` copies and damages one way per case
(`train`, `evaluate` and `generate` on a dataset folder), so that the table needs no
generation of its own (~25 s on the 2-core machine).

Run when the dataset format changes (a manifest that no longer validates fails the
table's clear cases first): `.venv/bin/python tests/data/record_tiny_dataset.py`.
"""

import shutil
import sys
from pathlib import Path

HERE = Path(__file__).parent
ARGS = ["generate", "--sensor", "sphere8", "--events", "2", "--rays", "4", "--probe", "sphere:r=3mm,subdivisions=1", "--no-plots", "--shard-rows", "5000", "--seed", "1", "--json"]


def main():
    from hydrotact.cli import main as hydrotact

    target = HERE / "tiny_dataset"
    shutil.rmtree(target, ignore_errors=True)
    code = hydrotact([*ARGS, "-o", str(target)])
    print(f"{target}: exit {code}")
    return code


if __name__ == "__main__":
    sys.exit(main())
