"""What a new user waits for: each command's wall time from a cold start.

Each command runs as a user would type it, in a fresh process, in a fresh folder, with
an empty cache of meshes and unit responses (so nothing comes from an earlier run),
and prints the seconds to its first output (a progress bar or a status line on stderr,
or the report) and to its end. The commands build on each other as in the README: the
simulated log is the one `fit` reads.

    .venv/bin/python benchmarks/first_contact.py [--full-demo] [--output DIR]

Writes first_contact.json in DIR (default: a temporary folder) and prints a table.
"""

import argparse
import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from _machine import describe_machine

TRAJECTORY_ROWS = 21  # a 2 s press, 0.6 mm deep, at 10 Hz waypoints


def _trajectory(path: Path) -> Path:
    lines = ["time,x,y,z"] + [f"{t / 10:g},0,0,{4.3e-3 - 0.6e-3 * min(t, 20 - t, 6) / 6:.6g}" for t in range(TRAJECTORY_ROWS)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _time(arguments: list[str], folder: Path, cache: Path) -> dict:
    """Seconds to the first byte of output and to the end of `hydrotact ARGUMENTS`."""
    import os

    env = {**os.environ, "HYDROTACT_CACHE_DIR": str(cache)}
    start = time.perf_counter()
    first = []
    process = subprocess.Popen([sys.executable, "-m", "hydrotact.cli", *arguments], cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def watch(stream, sink):
        for chunk in iter(lambda: stream.read1(65536), b""):
            if not first:
                first.append(time.perf_counter() - start)
            sink.append(chunk)

    out, err = [], []
    threads = [threading.Thread(target=watch, args=(process.stdout, out)), threading.Thread(target=watch, args=(process.stderr, err))]
    for thread in threads:
        thread.start()
    process.wait()
    for thread in threads:
        thread.join()
    total = time.perf_counter() - start
    if process.returncode != 0:
        raise SystemExit(f"hydrotact {' '.join(arguments)} failed ({process.returncode}):\n{b''.join(err).decode()[-2000:]}")
    return {"command": "hydrotact " + " ".join(arguments), "first_output_s": round(first[0] if first else total, 2), "total_s": round(total, 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full-demo", action="store_true", help="also time `hydrotact demo` at full size (minutes)")
    parser.add_argument("--output", type=Path, help="folder for first_contact.json and the commands' files (default: a temporary one)")
    args = parser.parse_args()
    folder = args.output or Path(tempfile.mkdtemp(prefix="first-contact-"))
    folder.mkdir(parents=True, exist_ok=True)
    _trajectory(folder / "press.csv")
    commands = [
        ["mesh", "sphere8", "--png", "mesh.png"],
        ["field", "sphere8", "--png", "field.png"],
        ["contact", "--sensor", "sphere8", "--probe", "sphere:r=3mm", "--at", "1mm,0,0.5mm", "--png", "contact.png"],
        ["simulate", "--sensor", "pad5x5", "--probe", "cylinder:d=2mm", "--trajectory", "press.csv", "--modulus", "2e5", "--barometer", "-o", "press.parquet"],
        ["fit", "press.parquet", "--terms", "auto", "-o", "fit"],
        ["demo", "--smoke", "-o", "demo-smoke"],
    ]
    if args.full_demo:
        commands.append(["demo", "-o", "demo"])
    rows = []
    for k, command in enumerate(commands):
        rows.append(_time(command, folder, folder / f"cache-{k}"))
        print(f"{rows[-1]['total_s']:8.1f} s  (first output {rows[-1]['first_output_s']:6.1f} s)  {rows[-1]['command']}", flush=True)
    report = {"machine": describe_machine(), "commands": rows}
    (folder / "first_contact.json").write_text(json.dumps(report, indent=2))
    print(f"machine: {report['machine']}\nwritten: {folder / 'first_contact.json'}")


if __name__ == "__main__":
    main()
