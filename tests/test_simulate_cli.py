"""`hydrotact simulate`: a trajectory file -> a barometer log (and plot), its bad
inputs, and resuming an interrupted run from its partial file.

Compiling the simulation dominates the cost (tens of seconds per shape), so every
simulation here runs in this process with blocks (and so jitted chunks) of the same
size, BLOCK_SAMPLES; only a failing run goes through a subprocess.
"""

import json

import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

import hydrotact.cli.simulate as job
import hydrotact.sim._host as host
from hydrotact import HydrotactError
from hydrotact.cli import main
from hydrotact.data import read_log
from hydrotact.sim import CONTACT_THRESHOLD_N

BLOCK_SAMPLES = 3
REAL_BLOCK = host.BLOCK  # what a run in another process uses (this one's is patched to BLOCK_SAMPLES)
PROBE = "cylinder:d=2mm"
RAYS = 16
# time (s), x, y, z (mm): the pad's skin is at z = 4 mm; the taxels are on a 2.2 mm grid.
TRAJECTORY_MM = np.array(
    [
        [0.00, 0.0, 0.0, 4.5],
        [0.01, 0.0, 0.0, 3.9],
        [0.02, 0.0, 0.0, 3.7],
        [0.03, 1.1, 0.0, 3.6],
        [0.04, 2.2, 2.2, 3.6],
        [0.05, 2.2, 2.2, 3.7],
        [0.06, -2.2, 0.0, 3.7],
        [0.07, -2.2, 0.0, 3.95],
        [0.08, 0.0, 0.0, 4.5],
    ]
)
CHANNELS = [f"b{row}{col}" for row in range(5) for col in range(5)]


def _write_trajectory(path, rows, header="time,x,y,z"):
    lines = [header] + [",".join(f"{value!r}" if isinstance(value, float) else str(value) for value in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _in_metres(rows):
    rows = np.array(rows, dtype=np.float64)
    rows[:, 1:4] *= 1e-3
    return rows


@pytest.fixture(autouse=True)
def _small_blocks_own_cache(monkeypatch, tmp_path_factory):
    """Blocks of BLOCK_SAMPLES poses, and a cache of unit responses of this test's own
    (else a run would find the reference's responses there and compute nothing)."""
    monkeypatch.setattr(host, "BLOCK", BLOCK_SAMPLES)
    monkeypatch.setenv("HYDROTACT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run along TRAJECTORY_MM (in metres), E = 1 MPa: the log."""
    folder = tmp_path_factory.mktemp("reference")
    trajectory = _write_trajectory(folder / "traj.csv", _in_metres(TRAJECTORY_MM).tolist())
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(host, "BLOCK", BLOCK_SAMPLES)
        patch.setenv("HYDROTACT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        job.run_simulate("pad5x5", PROBE, trajectory, folder / "log.parquet", modulus=1e6, num_rays=RAYS, progress=False)
    return read_log(folder / "log.parquet")


class _Counting:
    """Stands in for compute_unit_responses: counts calls, raises KeyboardInterrupt on
    call `fail_on` (1-based)."""

    def __init__(self, fail_on=None):
        self.calls = 0
        self.fail_on = fail_on
        self.real = host.compute_unit_responses

    def __call__(self, *args, **kwargs):
        self.calls += 1
        if self.calls == self.fail_on:
            raise KeyboardInterrupt
        return self.real(*args, **kwargs)


def test_simulate_command_writes_a_log(tmp_path, capsys, reference):
    trajectory = _write_trajectory(tmp_path / "traj.csv", TRAJECTORY_MM.tolist())
    output, png = tmp_path / "out" / "log.parquet", tmp_path / "log.png"
    code = main(["simulate", "--sensor", "pad5x5", "--probe", PROBE, "--trajectory", str(trajectory), "--units", "mm",
                 "--rays", str(RAYS), "-o", str(output), "--png", str(png), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    report = json.loads(captured.out)
    assert set(report) == {"sensor", "probe", "num_samples", "num_taxels", "samples_in_contact", "max_normal_force_N",
                           "max_taxel_pressure_Pa", "log", "png"}
    assert report["sensor"] == "pad5x5" and report["probe"] == PROBE
    assert report["num_samples"] == len(TRAJECTORY_MM) and report["num_taxels"] == 25
    assert report["log"] == str(output) and report["png"] == str(png)

    log = read_log(output)
    meta = log.metadata
    assert meta["channels"] == CHANNELS
    assert meta["sensor"] == "pad5x5" and meta["probe"] == PROBE and meta["source"] == "simulated"
    assert meta["pressure"] == "elastic" and meta["material"] == {"modulus_Pa": 1e6}
    assert meta["field"] == "laplace" and meta["num_rays"] == RAYS
    np.testing.assert_allclose(meta["rate_hz"], 100.0, rtol=1e-9)
    assert meta["generator"].startswith("hydrotact ")

    metres = _in_metres(TRAJECTORY_MM)
    np.testing.assert_allclose(log.times, metres[:, 0], rtol=0, atol=0)
    for k, axis in enumerate("xyz"):
        np.testing.assert_allclose(log.columns[f"probe_{axis}"], metres[:, 1 + k], rtol=1e-15, atol=1e-18)
        np.testing.assert_array_equal(log.columns[f"probe_r{axis}"], 0.0)

    force = np.column_stack([log.columns[f"f{axis}"] for axis in "xyz"])
    magnitude = np.linalg.norm(force, axis=1)
    contact = log.columns["contact"]
    assert contact.dtype == np.int8
    np.testing.assert_array_equal(contact, (magnitude > CONTACT_THRESHOLD_N).astype(np.int8))
    assert report["samples_in_contact"] == int(contact.sum())
    assert 3 <= contact.sum() < len(TRAJECTORY_MM), contact
    in_contact = contact == 1
    assert np.all(log.columns["fn"][in_contact] > 0.0)
    assert np.all(force[in_contact, 2] < 0.0), "the probe pushes the sensor down (-z)"
    np.testing.assert_allclose(report["max_normal_force_N"], log.columns["fn"].max(), rtol=1e-12)

    # Above the skin nothing is touched: no force, no pressure.
    for row in (0, len(TRAJECTORY_MM) - 1):
        np.testing.assert_array_equal(log.channels[row], 0.0)
        np.testing.assert_array_equal(force[row], 0.0)
    assert np.all(log.channels >= 0.0)
    np.testing.assert_allclose(report["max_taxel_pressure_Pa"], log.channels.max(), rtol=1e-12)
    # The taxel under the probe reads the most (channel b{row}{col} at x = -4.4 + 2.2 col mm, y = -4.4 + 2.2 row mm).
    for row, name in ((2, "b22"), (5, "b33"), (6, "b21")):
        assert CHANNELS[int(np.argmax(log.channels[row]))] == name, (row, log.channels[row])

    # Millimetres in, the same log as the reference run given in metres.
    np.testing.assert_allclose(log.channels, reference.channels, rtol=1e-9, atol=1e-6)

    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5_000
    assert sorted(p.name for p in output.parent.iterdir()) == ["log.parquet"], "partial or temporary files left behind"


def test_pressures_scale_with_the_modulus(tmp_path, reference):
    trajectory = _write_trajectory(tmp_path / "traj.csv", _in_metres(TRAJECTORY_MM).tolist())
    output = tmp_path / "stiff.parquet"
    job.run_simulate("pad5x5", PROBE, trajectory, output, modulus=2e6, num_rays=RAYS, progress=False)
    stiff = read_log(output)
    assert stiff.metadata["material"] == {"modulus_Pa": 2e6}
    assert reference.channels.max() > 1e3
    np.testing.assert_allclose(stiff.channels, 2.0 * reference.channels, rtol=1e-9, atol=1e-9)
    for name in ("fx", "fy", "fz", "tx", "ty", "tz", "fn"):
        np.testing.assert_allclose(stiff.columns[name], 2.0 * reference.columns[name], rtol=1e-9, atol=1e-15, err_msg=name)
    for name in ("probe_x", "probe_y", "probe_z", "time"):
        np.testing.assert_array_equal(stiff.columns[name], reference.columns[name])
    # Stiffer: at least as many samples over the force threshold.
    assert np.all(stiff.columns["contact"] >= reference.columns["contact"])


# (name, trajectory file text or None for none, extra arguments, fragments the message names)
BAD_INPUTS = [
    ("no-z", "time,x,y\n0,0,0\n0.01,0,0\n", [], ["traj.csv", "missing column", "z"]),
    ("not-a-number", "time,x,y,z\n0,0,0,4.5\n0.01,0,zero,4\n", [], ["traj.csv", "row 2", "column y", "'zero'"]),
    ("empty-cell", "time,x,y,z\n0,0,0,4.5\n0.01,0,0,\n", [], ["traj.csv", "row 2", "column z"]),
    ("time-goes-back", "time,x,y,z\n0,0,0,4.5\n0.02,0,0,4\n0.01,0,0,4\n", [], ["traj.csv", "row 3", "time", "does not increase"]),
    ("time-repeats", "time,x,y,z\n0,0,0,4.5\n0,0,0,4\n", [], ["traj.csv", "row 2", "time", "does not increase"]),
    ("nan-position", "time,x,y,z\n0,0,0,4.5\n0.01,nan,0,4\n", [], ["traj.csv", "row 2", "not a finite number"]),
    ("inf-time", "time,x,y,z\n0,0,0,4.5\ninf,0,0,4\n", [], ["traj.csv", "row 2", "not a finite number"]),
    ("short-row", "time,x,y,z\n0,0,0,4.5\n0.01,0,0\n", [], ["traj.csv", "row 2", "3 fields"]),
    ("no-rows", "time,x,y,z\n", [], ["traj.csv", "at least one sample"]),
    ("empty-file", "", [], ["traj.csv", "missing column"]),
    ("rx-only", "time,x,y,z,rx\n0,0,0,4.5,0\n", [], ["traj.csv", "rx, ry, rz"]),
    ("missing-file", None, [], ["traj.csv", "no such trajectory file"]),
    ("binary-file", b"\x89PNG\r\n\x1a\n\x00\xff\xfe", [], ["traj.csv"]),
    ("output-not-parquet", "time,x,y,z\n0,0,0,4.5\n", ["-o", "{tmp}/log.csv"], ["log.csv", "*.parquet"]),
    ("png-not-png", "time,x,y,z\n0,0,0,4.5\n", ["--png", "{tmp}/plot.xyz"], ["plot.xyz", "*.png"]),
    ("unknown-sensor", "time,x,y,z\n0,0,0,4.5\n", ["--sensor", "pad6x6"], ["pad6x6"]),
    ("bad-probe", "time,x,y,z\n0,0,0,4.5\n", ["--probe", "cone:r=2mm"], ["--probe", "cone:r=2mm"]),
    ("probe-length", "time,x,y,z\n0,0,0,4.5\n", ["--probe", "cylinder:d=two"], ["--probe"]),
    ("zero-modulus", "time,x,y,z\n0,0,0,4.5\n", ["--modulus", "0"], ["modulus"]),
]


@pytest.mark.parametrize(("text", "extra", "fragments"), [case[1:] for case in BAD_INPUTS], ids=[case[0] for case in BAD_INPUTS])
def test_bad_inputs(tmp_path, capsys, monkeypatch, text, extra, fragments):
    counting = _Counting()
    monkeypatch.setattr(host, "compute_unit_responses", counting)
    trajectory = tmp_path / "traj.csv"
    if isinstance(text, bytes):
        trajectory.write_bytes(text)
    elif text is not None:
        trajectory.write_text(text)
    output = tmp_path / "log.parquet"
    output.write_bytes(b"an earlier log")
    arguments = {"--sensor": "pad5x5", "--probe": PROBE, "--trajectory": str(trajectory), "--units": "mm", "--rays": str(RAYS), "-o": str(output)}
    arguments.update(dict(zip(extra[::2], [value.format(tmp=tmp_path) for value in extra[1::2]])))
    code = main(["simulate", *[item for pair in arguments.items() for item in pair]])
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert code == 2, captured.err
    assert len(lines) == 1 and lines[0].startswith("hydrotact: error: "), captured.err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert captured.out == ""
    assert counting.calls == 0, "simulated before checking the inputs"
    assert output.read_bytes() == b"an earlier log"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["log.parquet"] + (["traj.csv"] if text is not None else []))


def test_bad_input_from_a_subprocess(tmp_path):
    trajectory = _write_trajectory(tmp_path / "traj.csv", [[0.0, 0, 0, 4.5], [0.01, 0, "x", 4.0]])
    output = tmp_path / "log.parquet"
    result = run_cli("simulate", "--sensor", "pad5x5", "--probe", PROBE, "--trajectory", trajectory, "-o", output)
    assert_one_line_error(result, "traj.csv", "row 2", "column y", "'x'")
    assert not output.exists()


def test_trajectory_file_details(tmp_path):
    """Column order is free, extra spaces and a byte-order mark are fine, blank lines
    are skipped (rows keep their numbers), and rotation vectors come through."""
    from hydrotact.sim import read_trajectory

    path = tmp_path / "traj.csv"
    path.write_text("\ufeff z , time,x ,y,rz,ry,rx\n4.0, 0, 1, 2, 0.3, 0.2, 0.1\n\n4.5, 0.5, 1, 2, 0, 0, 0\n\n", encoding="utf-8")
    trajectory = read_trajectory(path, units="mm")
    np.testing.assert_array_equal(np.asarray(trajectory.times), [0.0, 0.5])
    np.testing.assert_allclose(np.asarray(trajectory.X_SR.translation), [[1e-3, 2e-3, 4e-3], [1e-3, 2e-3, 4.5e-3]], rtol=1e-15)
    np.testing.assert_array_equal(np.asarray(trajectory.rotation_vectors), [[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]])

    path.write_text("time,x,y,z\n0,0,0,4\n\n0.5,0,nan,4\n")
    with pytest.raises(HydrotactError, match=r"traj\.csv: row 3, column y: .*not a finite number"):
        read_trajectory(path)
    path.write_text("time,x,y,z\n0,0,0,4\n\n\n0.5,0,0,4\n0.5,0,0,4\n")
    with pytest.raises(HydrotactError, match=r"traj\.csv: row 5, column time: time 0\.5 s does not increase"):
        read_trajectory(path)
    path.write_bytes(b"time,x,y,z\n0,0,0\x00,4\n")
    with pytest.raises(HydrotactError, match=r"traj\.csv: "):
        read_trajectory(path)
    with pytest.raises(HydrotactError, match=r"traj\.csv: unknown length unit 'furlong'"):
        read_trajectory(path, units="furlong")


def _partial(output):
    return output.with_name(f".{output.name}.partial.npz")


def _run(trajectory, output, monkeypatch, counting):
    monkeypatch.setattr(host, "compute_unit_responses", counting)
    return job.run_simulate("pad5x5", PROBE, trajectory, output, modulus=1e6, num_rays=RAYS, progress=False)


def _assert_same_log(log, reference):
    assert log.metadata == reference.metadata
    assert list(log.columns) == list(reference.columns)
    np.testing.assert_allclose(log.channels, reference.channels, rtol=1e-12, atol=1e-12)
    for name in reference.columns:
        np.testing.assert_allclose(log.columns[name], reference.columns[name], rtol=1e-12, atol=1e-15, err_msg=name)


def test_interrupted_run_resumes(tmp_path, monkeypatch, reference):
    trajectory = _write_trajectory(tmp_path / "traj.csv", _in_metres(TRAJECTORY_MM).tolist())
    output = tmp_path / "log.parquet"
    blocks = len(TRAJECTORY_MM) // BLOCK_SAMPLES
    assert blocks == 3

    interrupted = _Counting(fail_on=2)
    with pytest.raises(KeyboardInterrupt):
        _run(trajectory, output, monkeypatch, interrupted)
    assert interrupted.calls == 2
    assert not output.exists()
    assert _partial(output).is_file()
    with np.load(_partial(output)) as saved:
        assert int(saved["num_blocks"]) == 1

    resumed = _Counting()
    report = _run(trajectory, output, monkeypatch, resumed)
    assert resumed.calls == blocks - 1, "recomputed a saved block"
    assert report["num_samples"] == len(TRAJECTORY_MM)
    _assert_same_log(read_log(output), reference)
    assert not _partial(output).exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.parquet", "traj.csv"]

    # The finished run's unit responses are cached: the same run again computes none.
    output.unlink()
    cached = _Counting()
    _run(trajectory, output, monkeypatch, cached)
    assert cached.calls == 0
    _assert_same_log(read_log(output), reference)

    # Interrupted again on the last block (an empty cache): two blocks saved, one left.
    monkeypatch.setenv("HYDROTACT_CACHE_DIR", str(tmp_path.parent / f"{tmp_path.name}-second-cache"))
    output.unlink()
    late = _Counting(fail_on=3)
    with pytest.raises(KeyboardInterrupt):
        _run(trajectory, output, monkeypatch, late)
    again = _Counting()
    _run(trajectory, output, monkeypatch, again)
    assert again.calls == 1
    _assert_same_log(read_log(output), reference)


def test_partial_file_of_other_inputs_is_ignored(tmp_path, monkeypatch, reference):
    trajectory = _write_trajectory(tmp_path / "traj.csv", _in_metres(TRAJECTORY_MM).tolist())
    output = tmp_path / "log.parquet"

    # Interrupted along another trajectory (the same length, shifted by 1 mm in x).
    other = _in_metres(TRAJECTORY_MM)
    other[:, 1] += 1e-3
    other_path = _write_trajectory(tmp_path / "other.csv", other.tolist())
    interrupted = _Counting(fail_on=3)
    with pytest.raises(KeyboardInterrupt):
        _run(other_path, output, monkeypatch, interrupted)
    assert _partial(output).is_file()

    fresh = _Counting()
    _run(trajectory, output, monkeypatch, fresh)
    assert fresh.calls == len(TRAJECTORY_MM) // BLOCK_SAMPLES, "mixed in blocks of another run"
    _assert_same_log(read_log(output), reference)
    assert not _partial(output).exists()


@pytest.mark.parametrize("content", [b"not a zip file", b"PK\x03\x04 truncated"], ids=["text", "truncated-zip"])
def test_unreadable_partial_file_is_ignored(tmp_path, monkeypatch, reference, content):
    trajectory = _write_trajectory(tmp_path / "traj.csv", _in_metres(TRAJECTORY_MM).tolist())
    output = tmp_path / "log.parquet"
    _partial(output).write_bytes(content)
    fresh = _Counting()
    _run(trajectory, output, monkeypatch, fresh)
    assert fresh.calls == len(TRAJECTORY_MM) // BLOCK_SAMPLES
    _assert_same_log(read_log(output), reference)
    assert not _partial(output).exists()


def test_partial_file_of_another_block_size_is_used_correctly(tmp_path, monkeypatch, reference):
    """Blocks saved with one block size and resumed with another still line up."""
    trajectory = _write_trajectory(tmp_path / "traj.csv", _in_metres(TRAJECTORY_MM).tolist())
    output = tmp_path / "log.parquet"
    interrupted = _Counting(fail_on=3)
    with pytest.raises(KeyboardInterrupt):
        _run(trajectory, output, monkeypatch, interrupted)  # blocks 0-2 and 3-5 saved
    monkeypatch.setattr(host, "BLOCK", 2 * BLOCK_SAMPLES)
    resumed = _Counting()
    _run(trajectory, output, monkeypatch, resumed)
    _assert_same_log(read_log(output), reference)


def test_interrupted_fit_of_many_logs_resumes(tmp_path, monkeypatch):
    """A full fit of three logs interrupted inside the second log's unit responses
    resumes there: the first log's come from the cache, the second's finished blocks
    from its partial file beside the cache entry; the fit equals an uninterrupted one."""
    from hydrotact.sysid import SimulatorFit, fit_logs

    paths = []
    for k, shift in enumerate((0.0, 1.1e-3, -1.1e-3)):
        rows = _in_metres(TRAJECTORY_MM)
        rows[:, 1] += shift
        paths.append(tmp_path / f"log{k}.parquet")
        job.run_simulate("pad5x5", PROBE, _write_trajectory(tmp_path / f"traj{k}.csv", rows.tolist()), paths[-1], modulus=1e6, num_rays=RAYS, progress=False)
    blocks_per_log = len(TRAJECTORY_MM) // BLOCK_SAMPLES

    def fit(folder, cache, counting):
        monkeypatch.setenv("HYDROTACT_CACHE_DIR", str(tmp_path / cache))
        monkeypatch.setattr(host, "compute_unit_responses", counting)
        return fit_logs(paths, tmp_path / folder, method=SimulatorFit(progress=False), terms=0)

    interrupted = _Counting(fail_on=blocks_per_log + 2)  # the first log done, one block of the second saved
    with pytest.raises(KeyboardInterrupt):
        fit("fit", "cache", interrupted)
    assert not (tmp_path / "fit").exists()
    partial = list((tmp_path / "cache" / "unit_responses").glob("*.partial.npz"))
    assert len(partial) == 1
    resumed = _Counting()
    report = fit("fit", "cache", resumed)
    assert resumed.calls == 3 * blocks_per_log - (blocks_per_log + 1), "recomputed a cached log or a saved block"
    assert not list((tmp_path / "cache" / "unit_responses").glob("*.partial.npz"))

    whole = _Counting()
    uninterrupted = fit("fit-whole", "fresh-cache", whole)
    assert whole.calls == 3 * blocks_per_log
    for key in ("long_term_modulus_Pa", "gains", "offsets_Pa", "reduced_chi_square"):
        assert json.dumps(report[key]) == json.dumps(uninterrupted[key]).replace("fit-whole", "fit"), key


def test_simulate_killed_with_sigkill_resumes_to_the_same_log(tmp_path):
    """A real kill: `hydrotact simulate` in its own process, SIGKILLed once its first
    block of poses is saved, then run again: it starts from the saved poses (its
    progress begins there), removes its partial file and writes the same bytes as an
    uninterrupted run (each run with a cache of its own, so nothing comes from there)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    count = 3 * REAL_BLOCK
    x = 1e-3 * np.linspace(-4.4, 4.4, count)
    rows = [[k / 100.0, float(x[k]), float(1.1e-3 * np.sin(k / 9.0)), 3.7e-3] for k in range(count)]
    trajectory = _write_trajectory(tmp_path / "traj.csv", rows)

    def start(name, cache):
        command = [sys.executable, "-m", "hydrotact.cli", "simulate", "--sensor", "pad5x5", "--probe", PROBE, "--trajectory", str(trajectory), "--rays", "8", "-o", str(tmp_path / name)]
        env = {**os.environ, "HYDROTACT_CACHE_DIR": str(tmp_path / cache)}
        return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)

    killed = start("log.parquet", "cache")
    partial = job.checkpoint_path(tmp_path / "log.parquet")
    deadline = time.monotonic() + 500
    while not partial.exists() and killed.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert killed.poll() is None, "the run ended before its first block was saved: " + killed.stderr.read()[-2000:]
    killed.send_signal(signal.SIGKILL)
    killed.communicate(timeout=60)
    assert killed.returncode == -signal.SIGKILL
    assert partial.is_file() and not (tmp_path / "log.parquet").exists()
    with np.load(partial) as saved:
        done = sum(len(saved[f"{b}/area"]) for b in range(int(saved["num_blocks"])))
    assert 0 < done < count
    resumed = start("log.parquet", "cache")
    reference = start("reference.parquet", "reference-cache")
    errors = []
    for run in (resumed, reference):
        _, err = run.communicate(timeout=600)
        assert run.returncode == 0, err[-3000:]
        errors.append(err)
    assert f"| {done}/{count} [" in errors[0] and f"| 0/{count} [" not in errors[0], errors[0][-2000:]
    assert f"| 0/{count} [" in errors[1]
    assert not partial.exists()
    assert (tmp_path / "log.parquet").read_bytes() == (tmp_path / "reference.parquet").read_bytes()
