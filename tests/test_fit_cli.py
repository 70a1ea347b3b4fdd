"""`hydrotact fit` from the command line: lumped fits of synthetic logs (Parquet, and a
user CSV through a column mapping), a full-mode fit of a log made by `hydrotact
simulate --material --barometer`, bad inputs (one error line, exit 2, nothing
written) and log warnings.

Fits and simulations run in this process through `hydrotact.cli.main` (each
subprocess pays the JAX import, and jitted code compiles once per process); two bad
inputs also go through a real subprocess to see the exact stderr of the command.
"""

import json
import warnings

import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli, run_main
from sysid_synthetic import make_lumped_log

from hydrotact.cli import main
from hydrotact.data import BarometerLog, make_material_document, read_log, read_material, write_log, write_material
from hydrotact.visco import make_prony

# --- lumped mode -------------------------------------------------------------------

LUMPED_TRUTH = {"long_term_modulus": 6e5, "moduli": [2.5e5, 1.5e5], "taus": [0.5, 8.0]}
AMPLITUDES = np.array([800.0, 1500.0, 400.0, 1000.0])  # Pa at the deepest indentation
EXPONENTS = np.array([1.5, 2.0, 1.7, 2.2])  # Hertz and steeper: the lumped law sums powers 1.5-3
FIT_FILES = ["material.json", "relaxation.png", "report.json", "residuals.png", "traces.png"]
LUMPED_FILES = sorted([*FIT_FILES, "channel_law_covariance.npz"])  # the channel law's covariance, for compare's band
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def lumped_log():
    """90 s at 50 Hz, four channels, the relative kernel of LUMPED_TRUTH (E∞ ≡ 1)."""
    relative = make_prony(1.0, np.asarray(LUMPED_TRUTH["moduli"]) / LUMPED_TRUTH["long_term_modulus"], LUMPED_TRUTH["taus"])
    return make_lumped_log(relative, AMPLITUDES, EXPONENTS, duration=90.0, rate_hz=50.0, seed=5, holds=(2.0, 25.0))


@pytest.fixture(scope="module")
def lumped_parquet(lumped_log, tmp_path_factory):
    path = tmp_path_factory.mktemp("lumped") / "lumped.parquet"
    write_log(path, lumped_log)
    return path


def _run(capsys, *args):
    """main(args) -> (exit status, stdout, stderr); argparse's exit becomes a status."""
    result = run_main(capsys, *args)
    return result.returncode, result.stdout, result.stderr


def _relative_taus(report):
    return sorted(term["tau_s"]["value"] for term in report["prony_terms"])


def _check_lumped_outputs(folder, report):
    assert sorted(p.name for p in folder.iterdir()) == LUMPED_FILES, "missing outputs or temporaries left behind"
    material = read_material(folder / "material.json")
    assert material["modulus_scale"] == "relative"
    assert material["long_term_modulus_Pa"]["value"] == 1.0
    assert len(material["prony_terms"]) == 2
    assert material["provenance"]["method"] == "fit" and material["provenance"]["mode"] == "lumped"
    on_disk = json.loads((folder / "report.json").read_text())
    assert on_disk["mode"] == "lumped" and on_disk["num_terms"] == 2 and on_disk["modulus_scale"] == "relative"
    assert on_disk["converged"]
    for name in ("traces.png", "residuals.png", "relaxation.png"):
        assert (folder / name).read_bytes()[:8] == PNG and (folder / name).stat().st_size > 10_000, name
    np.testing.assert_allclose(_relative_taus(on_disk), LUMPED_TRUTH["taus"], rtol=0.05)
    # The relative moduli E_i / E∞.
    moduli = [term["ratio"]["value"] for term in sorted(on_disk["prony_terms"], key=lambda t: t["tau_s"]["value"])]
    np.testing.assert_allclose(moduli, np.asarray(LUMPED_TRUTH["moduli"]) / LUMPED_TRUTH["long_term_modulus"], rtol=0.05)
    if report is not None:
        assert report["prony_terms"] == on_disk["prony_terms"]
    return on_disk


def test_lumped_fit_of_a_parquet_log(tmp_path, capsys, lumped_parquet):
    output = tmp_path / "fit"
    code, out, err = _run(capsys, "fit", lumped_parquet, "--lumped", "--terms", "2", "-o", output)
    assert code == 0, err
    assert "Traceback" not in err and "error" not in err
    report = _check_lumped_outputs(output, None)
    # The printed table: every parameter with its value.
    for label in ("E1/E∞", "τ1", "E2/E∞", "τ2"):
        assert label in out, (label, out)
    for term in report["prony_terms"]:
        assert f"{term['tau_s']['value']:.6g}" in out, out
    assert f"hydrotact fit: results in {output}/" in out
    for name in LUMPED_FILES:
        assert str(output / name) in out


USER_MAPPING = {
    "format": "hydrotact.column_mapping",
    "version": 1,
    "sensor": "rig4",
    "pressure": "absolute",
    "rate_hz": 50.0,
    "time": {"column": "t", "unit": "s"},
    "channels": [{"column": f"Sensor_{k}", "unit": "Pa"} for k in range(4)],
    # The stage's z in mm, the skin at z = 4 mm: indentation = 4 mm - z.
    "columns": {"indentation": {"column": "z", "unit": "mm", "offset": -4.0, "scale": -1.0}},
}


def _write_user_csv(path, log):
    """The lumped log in a user's layout: Sensor_0..3 in Pa, the stage z in mm, time in s."""
    z_mm = 4.0 - 1e3 * np.asarray(log.columns["indentation"])
    rows = zip(*(log.columns[f"b{k}"] for k in range(4)), z_mm, log.times, strict=True)
    lines = ["Sensor_0,Sensor_1,Sensor_2,Sensor_3,z,t"] + [",".join(repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_lumped_fit_of_a_user_csv_with_a_mapping(tmp_path, capsys, lumped_log, lumped_parquet):
    data = _write_user_csv(tmp_path / "rig.csv", lumped_log)
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps(USER_MAPPING))
    output = tmp_path / "fit"
    code, out, err = _run(capsys, "fit", data, "--mapping", mapping, "--lumped", "--terms", "2", "-o", output, "--json")
    assert code == 0, err
    report = json.loads(out)  # --json: stdout is the report and nothing else
    assert report["mode"] == "lumped" and report["num_terms"] == 2 and len(report["prony_terms"]) == 2
    assert report["channel_law"]["channels"] == [f"Sensor_{k}" for k in range(4)]
    assert report["files"]["material"] == str(output / "material.json")
    _check_lumped_outputs(output, report)
    assert read_material(output / "material.json")["channel_law"]["channels"] == [f"Sensor_{k}" for k in range(4)]

    # The same numbers as the Parquet log (the mm round trip costs ~1e-16 relative).
    code, out, err = _run(capsys, "fit", lumped_parquet, "--lumped", "--terms", "2", "-o", tmp_path / "parquet", "--json")
    assert code == 0, err
    np.testing.assert_allclose(_relative_taus(json.loads(out)), _relative_taus(report), rtol=1e-6)


def test_jittery_log_warns_and_fits(tmp_path, capsys, lumped_log):
    rng = np.random.default_rng(7)
    step = 1.0 / 50.0
    times = np.arange(lumped_log.num_samples) * step + rng.uniform(-0.3, 0.3, lumped_log.num_samples) * step
    log = BarometerLog(metadata=dict(lumped_log.metadata), columns={**lumped_log.columns, "time": times})
    path = tmp_path / "jittery.parquet"
    write_log(path, log)
    output = tmp_path / "fit"
    code, out, err = _run(capsys, "fit", path, "--lumped", "--terms", "2", "-o", output, "--json")
    assert code == 0, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines and all(line.startswith("hydrotact: warning: ") for line in lines), err
    assert any("jittery.parquet" in line and "uneven sampling" in line for line in lines), err
    assert "Traceback" not in err
    json.loads(out)
    assert sorted(p.name for p in output.iterdir()) == LUMPED_FILES


def test_lumped_fit_follows_a_drifting_baseline(tmp_path, capsys, lumped_log):
    """An aged sensor: each channel drifts linearly (0.5-2 Pa/s, hundreds of noise σ
    over the log). A constant baseline (--drift none) cannot follow it; the default
    B-spline baseline can. --tare belongs to full-mode fits."""
    drift = np.array([0.5, -1.0, 2.0, 1.5])
    times = lumped_log.times
    columns = dict(lumped_log.columns)
    for k, name in enumerate(lumped_log.metadata["channels"]):
        columns[name] = columns[name] + drift[k] * times
    path = tmp_path / "aged.parquet"
    write_log(path, BarometerLog(metadata=dict(lumped_log.metadata), columns=columns))
    reports = {}
    for flags in (["--drift", "none"], []):
        output = tmp_path / ("constant" if flags else "spline")
        code, out, err = _run(capsys, "fit", path, "--lumped", "--terms", "2", *flags, "-o", output, "--json")
        assert code == 0, err
        reports[bool(flags)] = json.loads(out)
    assert reports[True]["reduced_chi_square"] > 10.0
    assert reports[False]["reduced_chi_square"] < 1.5
    np.testing.assert_allclose(_relative_taus(reports[False]), LUMPED_TRUTH["taus"], rtol=0.05)
    code, _, err = _run(capsys, "fit", path, "--lumped", "--tare", "-o", tmp_path / "tared")
    assert code == 2 and "--tare" in err and "--drift" in err


# --- full mode: simulate, then fit ---------------------------------------------------

FULL_TRUTH = {"long_term_modulus": 1.5e5, "moduli": [5e4], "taus": [1.0]}  # a soft skin: its presses stay inside the BMP388's range
LSB = 0.016  # Pa, BMP388
# time (s), x, y, z (mm): two presses 0.4 mm deep with 5 s and 4 s holds, on taxels
# b22 (0, 0) and b23 (2.2 mm, 0); the skin is at z = 4 mm.
PRESSES_MM = [
    (0.0, 0.0, 0.0, 4.3),
    (1.0, 0.0, 0.0, 4.3),
    (1.3, 0.0, 0.0, 3.6),
    (6.3, 0.0, 0.0, 3.6),
    (6.6, 0.0, 0.0, 4.3),
    (7.0, 2.2, 0.0, 4.3),
    (8.0, 2.2, 0.0, 4.3),
    (8.3, 2.2, 0.0, 3.6),
    (12.3, 2.2, 0.0, 3.6),
    (12.6, 2.2, 0.0, 4.3),
    (14.0, 2.2, 0.0, 4.3),
]


def _write_trajectory(path, rows=PRESSES_MM):
    path.write_text("time,x,y,z\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in rows))
    return path


def _write_truth_material(path):
    return write_material(path, make_material_document(FULL_TRUTH["long_term_modulus"], FULL_TRUTH["moduli"], FULL_TRUTH["taus"], name="truth"))


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """`hydrotact simulate --material --barometer` once: (folder, log path, stdout)."""
    folder = tmp_path_factory.mktemp("full")
    trajectory = _write_trajectory(folder / "traj.csv")
    material = _write_truth_material(folder / "truth.json")
    log_path = folder / "log.parquet"
    code = main([
        "simulate", "--sensor", "pad5x5", "--probe", "cylinder:d=2mm", "--trajectory", str(trajectory), "--units", "mm",
        "--material", str(material), "--barometer", "--noise", "0.5", "--gain-spread", "0.05", "--offset-spread", "30",
        "--force-noise", "0.005", "--rays", "16", "-o", str(log_path), "--json",
    ])
    assert code == 0
    return folder, log_path


@pytest.fixture(scope="module")
def full_fit(simulated):
    """`hydrotact fit LOG --terms 1 -o fit/` once: (output folder, printed report)."""
    import contextlib
    import io

    folder, log_path = simulated
    output = folder / "fit"
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["fit", str(log_path), "--terms", "1", "-o", str(output), "--json"])
    assert code == 0, err.getvalue()
    assert "warning" not in err.getvalue(), err.getvalue()
    return output, json.loads(out.getvalue())


def test_simulated_barometer_log(simulated):
    folder, log_path = simulated
    assert sorted(p.name for p in folder.iterdir() if p.name != "fit") == ["log.parquet", "traj.csv", "truth.json"], "partial files left behind"
    log = read_log(log_path)
    meta = log.metadata
    assert meta["pressure"] == "absolute" and meta["sensor"] == "pad5x5" and meta["probe"] == "cylinder:d=2mm"
    assert meta["material"] == {
        "modulus_Pa": FULL_TRUTH["long_term_modulus"] + sum(FULL_TRUTH["moduli"]),
        "long_term_modulus_Pa": FULL_TRUTH["long_term_modulus"],
        "prony_terms": [{"modulus_Pa": FULL_TRUTH["moduli"][0], "tau_s": FULL_TRUTH["taus"][0]}],
    }
    barometer = meta["barometer"]
    assert barometer["part"] == "BMP388" and barometer["seed"] == 0
    assert barometer["noise_rms_Pa"] == 0.5 and barometer["force_noise_N"] == 0.005
    assert len(barometer["gains"]) == len(barometer["offsets_Pa"]) == 25
    gains, offsets = np.asarray(barometer["gains"]), np.asarray(barometer["offsets_Pa"])
    assert 0.01 < np.std(gains) < 0.1 and np.all(gains != 1.0)
    assert 10.0 < np.std(offsets) < 60.0
    assert barometer["range_Pa"] == [30000.0, 125000.0] and barometer["saturated_samples"] == [0] * 25  # a soft skin: nothing clipped

    # 100 Hz: the part's rate.
    assert meta["rate_hz"] == 100.0
    np.testing.assert_allclose(np.diff(log.times), 0.01, atol=1e-9)
    np.testing.assert_allclose(log.times[[0, -1]], [0.0, 14.0], atol=1e-9)
    assert log.num_samples == 1401

    readings = log.channels
    counts = readings / LSB
    np.testing.assert_allclose(counts, np.round(counts), rtol=0, atol=1e-6, err_msg="readings not whole LSBs")
    # Before the first press: ambient + the channel's offset + noise.
    quiet = readings[log.times < 0.9]
    np.testing.assert_allclose(quiet.mean(axis=0), 101325.0 + offsets, atol=0.5)
    np.testing.assert_allclose(quiet.std(axis=0), 0.5, rtol=0.3)
    # The pressed taxels rise by over 10 kPa (E0 = 0.2 MPa, 0.4 mm deep); the rest stay quiet.
    rise = readings.max(axis=0) - readings.min(axis=0)
    pressed = [meta["channels"].index(name) for name in ("b22", "b23")]
    assert np.all(rise[pressed] > 1e4), rise
    assert np.all(np.delete(rise, pressed) < 10.0), rise
    # Load-cell noise on the forces: before the press they read noise of 5 mN.
    np.testing.assert_allclose(log.columns["fz"][log.times < 0.9].std(), 0.005, rtol=0.3)
    assert log.columns["fz"].min() < -0.05  # the press: about 0.07 N into E0 = 0.2 MPa (force is linear in E), 10 noise stds


def test_full_fit_recovers_the_material_and_gains(simulated, full_fit):
    folder, log_path = simulated
    output, report = full_fit
    assert sorted(p.name for p in output.iterdir()) == FIT_FILES
    assert report["mode"] == "full" and report["num_terms"] == 1 and report["converged"]
    assert 0.8 < report["reduced_chi_square"] < 1.2
    np.testing.assert_allclose(report["long_term_modulus_Pa"]["value"], FULL_TRUTH["long_term_modulus"], rtol=0.01)
    [term] = report["prony_terms"]
    np.testing.assert_allclose(term["tau_s"]["value"], FULL_TRUTH["taus"][0], rtol=0.05)
    np.testing.assert_allclose(term["modulus_Pa"]["value"], FULL_TRUTH["moduli"][0], rtol=0.05)
    np.testing.assert_allclose(report["instantaneous_modulus_Pa"]["value"], FULL_TRUTH["long_term_modulus"] + sum(FULL_TRUTH["moduli"]), rtol=0.01)

    meta = read_log(log_path).metadata
    truth_gains = dict(zip(meta["channels"], meta["barometer"]["gains"], strict=True))
    truth_offsets = dict(zip(meta["channels"], meta["barometer"]["offsets_Pa"], strict=True))
    assert set(report["gains"]) >= {"pad5x5/b22", "pad5x5/b23"}, report["gains"]
    for name, gain in report["gains"].items():
        channel = name.split("/", 1)[1]
        np.testing.assert_allclose(gain["value"], truth_gains[channel], rtol=0.01, err_msg=name)
        assert abs(gain["value"] - truth_gains[channel]) < 5.0 * gain["std"], (name, gain, truth_gains[channel])
    [offsets] = report["offsets_Pa"]
    for channel, offset in offsets["channels"].items():
        np.testing.assert_allclose(offset["value"], 101325.0 + truth_offsets[channel], atol=1.0, err_msg=channel)

    material = read_material(output / "material.json")
    assert "modulus_scale" not in material
    np.testing.assert_allclose(material["long_term_modulus_Pa"]["value"], report["long_term_modulus_Pa"]["value"], rtol=1e-12)
    assert material["provenance"]["mode"] == "full" and material["provenance"]["sensor"] == "pad5x5"
    # The fitted material drives a simulation in turn (absolute moduli, not relative).
    from hydrotact.data import material_prony

    prony = material_prony(material, "material.json")
    np.testing.assert_allclose(float(prony.long_term_modulus), report["long_term_modulus_Pa"]["value"])


# --- bad input ------------------------------------------------------------------------


def _simple_log(num=60):
    """A hydrotact log (no probe pose): four channels near 1 atm and an indentation."""
    times = np.arange(num) * 0.02
    depth = np.clip(np.sin(np.pi * times / times[-1]), 0.0, None) * 0.5e-3
    columns = {"time": times, **{f"b{k}": 101325.0 + 1e3 * k + 2e6 * depth for k in range(4)}, "indentation": depth}
    metadata = {"format": "hydrotact.barometer_log", "version": 1, "sensor": "synthetic", "source": "recorded", "pressure": "absolute", "channels": [f"b{k}" for k in range(4)], "rate_hz": 50.0}
    return BarometerLog(metadata=metadata, columns=columns)


def _csv_with(tmp_path, edit):
    """The simple log as hydrotact CSV (+ its JSON) with `edit(lines)` applied to the CSV's lines."""
    path = tmp_path / "log.csv"
    write_log(path, _simple_log())
    lines = path.read_text().splitlines()
    edit(lines)
    path.write_text("\n".join(lines) + "\n")
    return path


def _blank_cells(lines, column, rows):
    header = lines[0].split(",")
    for row in rows:
        cells = lines[row].split(",")
        cells[header.index(column)] = ""
        lines[row] = ",".join(cells)


def _swap_times(lines, row):
    """Row `row` (1-based) gets a time before row `row - 1`'s."""
    cells = lines[row].split(",")
    cells[0] = repr(float(lines[row - 1].split(",")[0]) - 0.005)
    lines[row] = ",".join(cells)


def _case_missing_log(tmp_path, lumped_parquet):
    return ["fit", tmp_path / "absent.parquet", "-o", "{out}"], ["absent.parquet", "no such log file"]


def _case_full_without_pose(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--terms", "1", "-o", "{out}"], ["lumped.parquet", "probe pose", "'probe_x'", "--lumped"]


def _case_lumped_missing_column(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--lumped", "--indentation", "depth", "-o", "{out}"], ["lumped.parquet", "no indentation column 'depth'"]


def _case_terms_text(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--lumped", "--terms", "abc", "-o", "{out}"], ["--terms", "'abc'"]


def _case_terms_negative(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--lumped", "--terms", "-1", "-o", "{out}"], ["--terms", "-1"]


def _case_terms_many(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--lumped", "--terms", "9", "-o", "{out}"], ["--terms", "9"]


def _case_csv_without_metadata(tmp_path, lumped_parquet):
    data = tmp_path / "rig.csv"
    data.write_text("t,Sensor_0\n0,101325\n0.02,101326\n")
    return ["fit", data, "--lumped", "-o", "{out}"], ["rig.csv", "no metadata document rig.json", "--mapping"]


def _case_mapping_wrong_unit(tmp_path, lumped_parquet):
    data = tmp_path / "rig.csv"
    data.write_text("Sensor_0,Sensor_1,Sensor_2,Sensor_3,z,t\n" + "".join(f"101325,101325,101325,101325,4,{k / 50}\n" for k in range(20)))
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps({**USER_MAPPING, "channels": [{"column": "Sensor_0", "unit": "mm"}]}))
    return ["fit", data, "--mapping", mapping, "--lumped", "-o", "{out}"], ["map.json", "channels[0].unit", "'mm' is a length unit"]


def _case_mapping_missing(tmp_path, lumped_parquet):
    data = tmp_path / "rig.csv"
    data.write_text("t,Sensor_0\n0,101325\n")
    return ["fit", data, "--mapping", tmp_path / "nomap.json", "--lumped", "-o", "{out}"], ["nomap.json", "no such file"]


def _case_nan_run(tmp_path, lumped_parquet):
    data = _csv_with(tmp_path, lambda lines: _blank_cells(lines, "b2", range(3, 7)))
    return ["fit", data, "--lumped", "-o", "{out}"], ["log.csv", "column 'b2'", "rows 3-6: 4 missing values"]


def _case_time_goes_back(tmp_path, lumped_parquet):
    data = _csv_with(tmp_path, lambda lines: _swap_times(lines, 10))
    return ["fit", data, "--lumped", "-o", "{out}"], ["log.csv", "column 'time'", "row 10", "goes back"]


def _case_one_bad_log_of_two(tmp_path, lumped_parquet):
    """A good log first, then a bad one: still nothing written."""
    data = _csv_with(tmp_path, lambda lines: _blank_cells(lines, "b1", [5]))
    return ["fit", lumped_parquet, data, "--lumped", "-o", "{out}"], ["log.csv", "column 'b1'", "row 5"]


def _case_bad_sensor(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--sensor", "pad6x6", "-o", "{out}"], ["pad6x6"]


def _case_never_indented(tmp_path, lumped_parquet):
    data = tmp_path / "flat.parquet"
    log = _simple_log()
    write_log(data, BarometerLog(log.metadata, {**log.columns, "indentation": np.zeros(log.num_samples)}))
    return ["fit", data, "--lumped", "-o", "{out}"], ["flat.parquet", "never moves above its rest level"]


def _case_too_short(tmp_path, lumped_parquet):
    data = tmp_path / "short.parquet"
    write_log(data, _simple_log(num=5))
    return ["fit", data, "--lumped", "-o", "{out}"], ["short.parquet", "5 samples", "at least 8"]


def _case_not_parquet(tmp_path, lumped_parquet):
    data = tmp_path / "broken.parquet"
    data.write_bytes(b"PAR1 not really")
    return ["fit", data, "--lumped", "-o", "{out}"], ["broken.parquet", "not a readable Parquet file"]


def _case_starts_zero(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--lumped", "--starts", "0", "-o", "{out}"], ["--starts", "auto or 1 to 3", "'0'"]


def _case_starts_text(tmp_path, lumped_parquet):
    return ["fit", lumped_parquet, "--lumped", "--starts", "many", "-o", "{out}"], ["--starts", "'many'"]


FIT_CASES = {
    "missing-log": _case_missing_log,
    "full-mode-without-pose": _case_full_without_pose,
    "lumped-missing-indentation": _case_lumped_missing_column,
    "terms-abc": _case_terms_text,
    "terms-negative": _case_terms_negative,
    "terms-too-many": _case_terms_many,
    "csv-without-metadata": _case_csv_without_metadata,
    "mapping-wrong-kind-unit": _case_mapping_wrong_unit,
    "mapping-missing": _case_mapping_missing,
    "nan-run": _case_nan_run,
    "time-goes-back": _case_time_goes_back,
    "second-log-bad": _case_one_bad_log_of_two,
    "unknown-sensor": _case_bad_sensor,
    "never-indented": _case_never_indented,
    "too-short": _case_too_short,
    "not-parquet": _case_not_parquet,
    "starts-zero": _case_starts_zero,
    "starts-text": _case_starts_text,
}


def _snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None for p in sorted(folder.rglob("*"))}


def _assert_error_and_nothing_written(capsys, tmp_path, args, fragments):
    before = _snapshot(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code, out, err = _run(capsys, *args)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (code, out, err)
    assert len(lines) == 1 and lines[0].startswith("hydrotact: error: "), err
    assert "Traceback" not in err and out == ""
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert not [str(w.message) for w in caught], "warnings besides the error line"
    assert _snapshot(tmp_path) == before, "wrote something"


@pytest.mark.parametrize("existing", [False, True], ids=["new-folder", "existing-folder"])
@pytest.mark.parametrize("case", list(FIT_CASES))
def test_fit_bad_input(tmp_path, capsys, lumped_parquet, case, existing):
    args, fragments = FIT_CASES[case](tmp_path, lumped_parquet)
    output = tmp_path / "fit"
    if existing:
        output.mkdir()
        (output / "material.json").write_text("an earlier fit\n")
    args = [str(a).format(out=output) for a in args]
    _assert_error_and_nothing_written(capsys, tmp_path, args, fragments)
    assert output.exists() == existing


def test_fit_output_is_an_existing_file(tmp_path, capsys, lumped_parquet):
    output = tmp_path / "results.txt"
    output.write_text("keep me\n")
    _assert_error_and_nothing_written(capsys, tmp_path, ["fit", lumped_parquet, "--lumped", "-o", output], ["results.txt", "not a folder"])
    assert output.read_text() == "keep me\n"


def test_fit_unknown_solver(tmp_path, capsys, lumped_parquet):
    """argparse refuses it: exit 2, one line naming the command, the option and its --help, no traceback."""
    output = tmp_path / "fit"
    code, out, err = _run(capsys, "fit", lumped_parquet, "--lumped", "--solver", "newton", "-o", output)
    assert code == 2
    assert "--solver" in err and "invalid choice: 'newton'" in err and "Traceback" not in err
    assert err.splitlines() == [err.strip()] and err.startswith("hydrotact: error: fit: argument --solver") and "hydrotact fit --help" in err
    assert not output.exists()


@pytest.mark.parametrize("rays", ["-3", "0"])
def test_fit_refuses_a_bad_ray_count(simulated, tmp_path, capsys, rays):
    _, log_path = simulated
    output = tmp_path / "fit"
    _assert_error_and_nothing_written(capsys, tmp_path, ["fit", log_path, "--terms", "1", "--rays", rays, "-o", output], ["rays", rays])
    assert not output.exists()


def _simulate_args(trajectory, material, output):
    return ["simulate", "--sensor", "pad5x5", "--probe", "cylinder:d=2mm", "--trajectory", trajectory, "--units", "mm", "--material", material, "--barometer", "--rays", "16", "-o", output]


def test_simulate_refuses_a_relative_material(tmp_path, capsys):
    trajectory = _write_trajectory(tmp_path / "traj.csv")
    document = make_material_document(1.0, [0.4], [0.5])
    document["modulus_scale"] = "relative"
    material = tmp_path / "lumped_material.json"
    material.write_text(json.dumps(document))
    output = tmp_path / "out" / "log.parquet"
    _assert_error_and_nothing_written(capsys, tmp_path, _simulate_args(trajectory, material, output), ["lumped_material.json", "modulus_scale", "relative"])


@pytest.mark.parametrize(
    ("document", "fragments"),
    [
        ({"long_term_modulus_Pa": {"value": -1.0}}, ["long_term_modulus_Pa.value", "> 0"]),
        ('{"format": "hydrotact.material",', ["not valid JSON"]),
        (None, ["no such file"]),
    ],
    ids=["negative-modulus", "malformed-json", "missing-file"],
)
def test_simulate_refuses_an_invalid_material(tmp_path, capsys, document, fragments):
    trajectory = _write_trajectory(tmp_path / "traj.csv")
    material = tmp_path / "mat.json"
    if document is not None:
        if isinstance(document, dict):  # a valid document with these fields changed
            document = json.dumps({**make_material_document(6e5, [2e5], [1.0]), "instantaneous_modulus_Pa": {"value": 8e5}, **document})
        material.write_text(document)
    output = tmp_path / "out" / "log.parquet"
    _assert_error_and_nothing_written(capsys, tmp_path, _simulate_args(trajectory, material, output), ["mat.json", *fragments])


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["fit", "{tmp}/absent.parquet", "-o", "{tmp}/fit"], ["absent.parquet", "no such log file"]),
        (["fit", "{tmp}/absent.parquet", "--terms", "abc", "-o", "{tmp}/fit"], ["--terms", "'abc'"]),
    ],
    ids=["missing-log", "terms-abc"],
)
def test_bad_input_from_a_subprocess(tmp_path, args, fragments):
    result = run_cli(*[a.format(tmp=tmp_path) for a in args])
    assert_one_line_error(result, *fragments)
    assert result.stdout == ""
    assert not (tmp_path / "fit").exists()


@pytest.mark.parametrize("flag", [["--noise", "1"], ["--gain-spread", "0.1"], ["--offset-spread", "5"], ["--force-noise", "0.01"]])
def test_simulate_barometer_options_need_barometer(tmp_path, capsys, flag):
    trajectory = _write_trajectory(tmp_path / "traj.csv")
    output = tmp_path / "log.parquet"
    args = ["simulate", "--sensor", "pad5x5", "--probe", "cylinder:d=2mm", "--trajectory", trajectory, "--units", "mm", *flag, "-o", output]
    _assert_error_and_nothing_written(capsys, tmp_path, args, [flag[0], "--barometer"])


def test_fit_logs_takes_its_method_as_a_settings_object(lumped_parquet, tmp_path):
    """fit_logs(method=SimulatorFit(...) | LumpedFit(...)): the lumped fit through its
    method object writes what `fit --lumped` does; anything else is refused before a
    file is written; the methods hold settings only (frozen)."""
    import dataclasses

    from hydrotact import HydrotactError
    from hydrotact.sysid import LumpedFit, SimulatorFit, fit_logs

    with pytest.raises(HydrotactError, match=r"method: expected SimulatorFit\(...\) or LumpedFit\(...\), got 'lumped'"):
        fit_logs([lumped_parquet], tmp_path / "refused", method="lumped")
    assert not (tmp_path / "refused").exists()
    for method in (SimulatorFit(), LumpedFit()):
        with pytest.raises(dataclasses.FrozenInstanceError):
            method.sensor = "pad5x5"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = fit_logs([lumped_parquet], tmp_path / "fit", method=LumpedFit(estimate_lag=True), terms=1)
    assert report["mode"] == "lumped" and report["num_terms"] == 1 and (tmp_path / "fit" / "material.json").is_file()
    assert report["logs"][0]["lag_s"]["std"] > 0.0  # estimated (LumpedFit's estimate_lag reached the fit); a given lag has none
