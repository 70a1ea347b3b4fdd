"""Log formats: hydrotact CSV (+ metadata JSON), users' layouts through a column
mapping with units converted on reading, the checks that name file, column and row,
sampling warnings, tare calibration and material documents."""

import json
import math

import jsonschema
import numpy as np
import pytest

from hydrotact import HydrotactError
from hydrotact._schemas import load_schema
from hydrotact.data import (
    BarometerLog,
    LogWarning,
    apply_mapping,
    check_log,
    check_material,
    find_no_load_segments,
    load_mapping,
    make_material_document,
    read_log,
    read_material,
    tare_log,
    write_log,
    write_material,
)

CHANNELS = ["b00", "b01", "b02"]


def _metadata(**changes):
    metadata = {
        "format": "hydrotact.barometer_log",
        "version": 1,
        "sensor": "bench3",
        "source": "recorded",
        "pressure": "absolute",
        "channels": list(CHANNELS),
        "rate_hz": 100.0,
    }
    metadata.update(changes)
    return metadata


def _log(num=50, **changes):
    rng = np.random.default_rng(3)
    columns = {"time": np.arange(num) * 0.01}
    for name in CHANNELS:
        columns[name] = 1e5 + rng.normal(0.0, 1.0, num)
    columns["fz"] = rng.normal(size=num)
    columns["theta"] = np.where(np.arange(num) % 3 == 0, np.nan, 0.1)
    columns["contact"] = (np.arange(num) % 2).astype(np.int8)
    return BarometerLog(metadata=_metadata(**changes), columns=columns)


def _one_line(error, *fragments):
    message = str(error.value)
    assert "\n" not in message, message
    for fragment in fragments:
        assert fragment in message, (fragment, message)


# --- hydrotact CSV ------------------------------------------------------------------


def test_csv_round_trip(tmp_path):
    log = _log()
    path = tmp_path / "log.csv"
    assert write_log(path, log) == path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "log.json"]
    assert path.read_text().splitlines()[0] == "time,b00,b01,b02,fz,theta,contact"
    assert json.loads((tmp_path / "log.json").read_text()) == log.metadata
    back = read_log(path)
    assert back.metadata == log.metadata
    assert list(back.columns) == list(log.columns)
    for name, values in log.columns.items():
        np.testing.assert_array_equal(back.columns[name], values, err_msg=name)


def test_parquet_and_csv_hold_the_same_log(tmp_path):
    log = _log()
    write_log(tmp_path / "a.parquet", log)
    from_parquet = read_log(tmp_path / "a.parquet")
    write_log(tmp_path / "b.csv", from_parquet)
    from_csv = read_log(tmp_path / "b.csv")
    assert from_csv.metadata == from_parquet.metadata
    for name in log.columns:
        np.testing.assert_array_equal(from_csv.columns[name], from_parquet.columns[name], err_msg=name)
    assert from_parquet.columns["contact"].dtype == np.int8


def test_csv_write_is_atomic(tmp_path):
    """A refused write leaves the old CSV and its JSON as they were, and no temporaries."""
    path = tmp_path / "log.csv"
    write_log(path, _log())
    before = path.read_bytes(), (tmp_path / "log.json").read_bytes()
    bad = _log()
    bad.columns["b01"][4] = np.nan
    with pytest.raises(HydrotactError, match=r"log\.csv: column 'b01', row 5: missing value"):
        write_log(path, bad)
    assert (path.read_bytes(), (tmp_path / "log.json").read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "log.json"]


def test_log_suffix(tmp_path):
    with pytest.raises(HydrotactError, match=r"log\.txt: a log is a Parquet or CSV file"):
        write_log(tmp_path / "log.txt", _log())
    (tmp_path / "log.txt").write_text("time\n0\n")
    with pytest.raises(HydrotactError, match=r"log\.txt: a log is a Parquet or CSV file"):
        read_log(tmp_path / "log.txt")


# --- users' layouts through a column mapping -----------------------------------------

USER_CSV = """Sensor_0,Sensor_1,Sensor_2,Sensor_3,x,z,time
101325.0,101300.5,101290.0,101310.0,0,4.5,0.00
101325.5,101301.0,101290.5,101310.5,8,4.0,0.01
101400.0,101350.0,101320.0,101330.0,16,3.5,0.02
101380.0,101340.0,101310.0,101320.0,24,3.6,0.03
101326.0,101301.5,101291.0,101311.0,32,4.5,0.04
"""


def _mapping(**changes):
    mapping = {
        "format": "hydrotact.column_mapping",
        "version": 1,
        "sensor": "rig4",
        "pressure": "absolute",
        "rate_hz": 100.0,
        "time": {"column": "time", "unit": "s"},
        "channels": [{"column": f"Sensor_{k}", "unit": "Pa"} for k in range(4)],
        "columns": {
            "probe_x": {"column": "x", "unit": "step", "scale": 1.25e-6},
            "probe_z": {"column": "z", "unit": "mm"},
            "indentation": {"column": "z", "unit": "mm", "offset": -4.0, "scale": -1.0},
        },
    }
    mapping.update(changes)
    return mapping


def _write_user(tmp_path, mapping=None, text=USER_CSV, name="rig.csv"):
    data = tmp_path / name
    data.write_text(text)
    mapping_path = tmp_path / "map.json"
    mapping_path.write_text(mapping if isinstance(mapping, str) else json.dumps(mapping or _mapping()))
    return data, mapping_path


@pytest.fixture(scope="module")
def four_taxel_sensor(tmp_path_factory):
    """A sensor JSON with pad5x5's first four taxels, named t0..t3."""
    from hydrotact.sensors import load_sensor

    document = load_sensor("pad5x5").to_json()
    document["name"] = "pad4"
    document["taxels"] = document["taxels"][:4]
    for k, taxel in enumerate(document["taxels"]):
        taxel["name"] = f"t{k}"
    path = tmp_path_factory.mktemp("sensor") / "pad4.json"
    path.write_text(json.dumps(document))
    return path


def test_user_csv_read_into_si(tmp_path):
    data, mapping = _write_user(tmp_path)
    log = read_log(data, mapping)
    raw = np.loadtxt(data, delimiter=",", skiprows=1)
    assert log.metadata == {
        "format": "hydrotact.barometer_log",
        "version": 1,
        "sensor": "rig4",
        "source": "recorded",
        "pressure": "absolute",
        "channels": ["Sensor_0", "Sensor_1", "Sensor_2", "Sensor_3"],
        "rate_hz": 100.0,
    }
    np.testing.assert_array_equal(log.times, raw[:, 6])
    np.testing.assert_array_equal(log.channels, raw[:, :4])
    np.testing.assert_allclose(log.columns["probe_x"], raw[:, 4] * 1.25e-6, rtol=1e-15)
    np.testing.assert_allclose(log.columns["probe_z"], raw[:, 5] * 1e-3, rtol=1e-15)
    np.testing.assert_allclose(log.columns["indentation"], (4.0 - raw[:, 5]) * 1e-3, rtol=1e-12)
    # Written as a hydrotact log, it reads back without the mapping.
    write_log(tmp_path / "ours.parquet", log)
    assert read_log(tmp_path / "ours.parquet").metadata == log.metadata


def test_mapping_takes_the_sensors_taxel_names(tmp_path, four_taxel_sensor):
    data, mapping = _write_user(tmp_path)
    log = read_log(data, mapping, sensor=str(four_taxel_sensor))
    assert log.metadata["channels"] == ["t0", "t1", "t2", "t3"]
    assert log.metadata["sensor"] == str(four_taxel_sensor)
    named = _mapping(channels=[{"column": f"Sensor_{k}", "unit": "Pa", "name": f"p{k}"} for k in range(4)])
    data, mapping = _write_user(tmp_path, named)
    assert read_log(data, mapping, sensor=str(four_taxel_sensor)).metadata["channels"] == ["p0", "p1", "p2", "p3"]
    # Errors in a mapped log name the log's channel and the file's column.
    data, mapping = _write_user(tmp_path, text=USER_CSV.replace("101300.5", "0"))
    with pytest.raises(HydrotactError) as error:
        read_log(data, mapping, sensor=str(four_taxel_sensor))
    _one_line(error, "rig.csv: column 't1' (file column 'Sensor_1'), row 1: absolute pressure 0 Pa is not positive")


def test_mapped_contact_flag_drives_the_tare(tmp_path):
    text = "\n".join(["t_ms,p,touch", *(f"{10 * k},{1000.0 + (50.0 if 100 <= k < 200 else 0.0) + 0.01 * k},{int(100 <= k < 200)}" for k in range(300))]) + "\n"
    mapping = _mapping(
        time={"column": "t_ms", "unit": "ms"}, channels=[{"column": "p", "unit": "hPa"}], columns={"contact": {"column": "touch", "unit": "1"}}
    )
    data, path = _write_user(tmp_path, mapping, text)
    log = read_log(data, path)
    assert log.columns["contact"].dtype.kind == "i"
    tared, baselines = tare_log(log)
    assert tared.metadata["tare"]["segments_s"] == [[0.0, 0.99], [2.0, 2.99]]
    np.testing.assert_allclose(tared.columns["p"], np.where(log.columns["contact"] == 1, 5000.0, 0.0), atol=1e-6)


def test_mapping_channel_group_units_and_parquet(tmp_path):
    """One group in hPa with a gain, time in ms: converted; the same mapping reads a
    Parquet file of the user's layout."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    grouped = _mapping(
        channels={"columns": ["Sensor_0", "Sensor_1", "Sensor_2", "Sensor_3"], "unit": "hPa", "scale": 2.0, "names": ["a", "b", "c", "d"]},
        time={"column": "time", "unit": "ms"},
        columns={},
    )
    text = "\n".join(["time,Sensor_0,Sensor_1,Sensor_2,Sensor_3", *(f"{10 * k},{1013.25 + k},1000,999,998" for k in range(5))]) + "\n"
    data, mapping = _write_user(tmp_path, grouped, text)
    log = read_log(data, mapping)
    np.testing.assert_allclose(log.times, np.arange(5) * 0.01, rtol=1e-15)
    np.testing.assert_allclose(log.columns["a"], (1013.25 + np.arange(5)) * 100.0 * 2.0, rtol=1e-15)
    assert log.metadata["channels"] == ["a", "b", "c", "d"]

    table = pa.table({"time": np.arange(5) * 10.0, **{f"Sensor_{k}": np.full(5, 1000.0 + k) for k in range(4)}, "ignored": np.zeros(5)})
    pq.write_table(table, tmp_path / "rig.parquet")
    log = read_log(tmp_path / "rig.parquet", mapping)
    np.testing.assert_allclose(log.columns["d"], np.full(5, 1003.0 * 200.0))
    assert "ignored" not in log.columns


def test_mapping_psi_and_sanitised_names(tmp_path):
    mapping = _mapping(channels=[{"column": "port 1 (psi)", "unit": "psi"}, {"column": "2nd", "unit": "kPa"}], columns={}, rate_hz=100.0)
    text = "time,port 1 (psi),2nd\n0,14.7,101.3\n0.01,14.7,101.3\n0.02,14.8,101.4\n"
    data, path = _write_user(tmp_path, mapping, text)
    log = read_log(data, path)
    assert log.metadata["channels"] == ["port_1__psi_", "_2nd"]
    np.testing.assert_allclose(log.columns["port_1__psi_"][0], 14.7 * 6894.757293168361)
    np.testing.assert_allclose(log.columns["_2nd"][0], 101.3e3)
    assert log.describe_column("_2nd") == "'_2nd' (file column '2nd')"


def test_apply_mapping_in_memory():
    columns = {"t": np.array([0.0, 1.0, 2.0]), "p": np.array([1.0, 1.1, 1.2])}
    document = _mapping(time={"column": "t", "unit": "min"}, channels=[{"column": "p", "unit": "bar"}], columns={}, rate_hz=1 / 60)
    log = apply_mapping(columns, document, "memory")
    np.testing.assert_allclose(log.times, [0.0, 60.0, 120.0])
    np.testing.assert_allclose(log.columns["p"], [1e5, 1.1e5, 1.2e5])
    check_log(log, "memory")


# Each bad input: the CSV text (None: USER_CSV), mapping changes (None: no mapping file
# at all, a str: the mapping file's text), read_log keywords, and message fragments.
BAD_CSV = [
    ("missing-column", USER_CSV.replace("Sensor_3", "Sensor_9"), {}, {}, ["rig.csv", "missing column 'Sensor_3'", "channels[3].column", "Sensor_9"]),
    ("time-goes-back", USER_CSV.replace("0.03\n", "0.015\n"), {}, {}, ["rig.csv", "column 'time'", "row 4", "goes back", "0.015 s after 0.02 s"]),
    ("time-repeats", USER_CSV.replace("0.03\n", "0.02\n"), {}, {}, ["rig.csv", "column 'time'", "row 4", "repeats"]),
    (
        "nan-run",
        "\n".join(["Sensor_0,Sensor_1,Sensor_2,Sensor_3,x,z,time", *(f"1e5,1e5,{'' if 2 <= k <= 5 else '1e5'},1e5,0,4,{k / 100}" for k in range(10))]) + "\n",
        {},
        {},
        ["rig.csv", "column 'Sensor_2'", "rows 3-6: 4 missing values"],
    ),
    (
        "nan-runs",
        "\n".join(["Sensor_0,Sensor_1,Sensor_2,Sensor_3,x,z,time", *(f"1e5,1e5,1e5,{'nan' if k in (1, 5, 6) else '1e5'},0,4,{k / 100}" for k in range(10))]) + "\n",
        {},
        {},
        ["column 'Sensor_3'", "row 2: missing value", "2 runs, 3 missing values in all"],
    ),
    ("wrong-channel-count", None, {"sensor": "pad5x5"}, {}, ["rig.csv", "channels", "4 channel columns", "'pad5x5' has 25 taxels"]),
    ("unknown-unit", None, {"time": {"column": "time", "unit": "fortnight"}}, {}, ["map.json", "time.unit", "unknown unit 'fortnight'", "s, ms, us, min"]),
    ("wrong-kind-unit", None, {"channels": [{"column": "Sensor_0", "unit": "mm"}]}, {}, ["map.json", "channels[0].unit", "'mm' is a length unit", "pressure column takes Pa"]),
    ("wrong-kind-column", None, {"columns": {"probe_x": {"column": "x", "unit": "kPa"}}}, {}, ["map.json", "columns.probe_x.unit", "'kPa' is a pressure unit", "length"]),
    ("step-without-scale", None, {"columns": {"probe_x": {"column": "x", "unit": "step"}}}, {}, ["map.json", "columns.probe_x.scale", "needs a scale"]),
    ("unknown-target", None, {"columns": {"probe_w": {"column": "x", "unit": "m"}}}, {}, ["map.json", "columns.probe_w", "not a log column"]),
    ("time-in-columns", None, {"columns": {"time": {"column": "x", "unit": "s"}}}, {}, ["map.json", "columns.time"]),
    ("zero-scale", None, {"columns": {"probe_x": {"column": "x", "unit": "step", "scale": 0}}}, {}, ["map.json", "columns.probe_x.scale"]),
    ("malformed-mapping", None, '{"format": "hydrotact.column_mapping",', {}, ["map.json", "not valid JSON", "line 1"]),
    ("mapping-unknown-field", None, {"colour": "red"}, {}, ["map.json", "colour", "unknown field"]),
    ("mapping-no-channels", None, {"channels": []}, {}, ["map.json", "channels", "must not be empty"]),
    ("mapping-group-names", None, {"channels": {"columns": ["Sensor_0", "Sensor_1"], "unit": "Pa", "names": ["a"]}}, {}, ["map.json", "channels.names", "1 names for 2 columns"]),
    ("mapping-reserved-name", None, {"channels": [{"column": "Sensor_0", "unit": "Pa", "name": "fx"}]}, {}, ["map.json", "channels[0].name", "reserved"]),
    ("no-sensor", None, {"sensor": None}, {}, ["rig.csv", "which sensor", "--sensor"]),
    ("csv-without-metadata", None, None, {}, ["rig.csv", "no metadata document rig.json", "--mapping"]),
    ("absolute-not-positive", USER_CSV.replace("101380.0,", "-3.0,"), {}, {}, ["rig.csv", "column 'Sensor_0'", "row 4", "absolute pressure -3 Pa is not positive"]),
    ("pressure-in-wrong-unit", None, {"channels": [{"column": f"Sensor_{k}", "unit": "bar"} for k in range(4)]}, {}, ["rig.csv",
        "column 'Sensor_0'", "row 1", "1.01325e+10 Pa is beyond the 1e+07 Pa"]),
    ("text-cell", USER_CSV.replace("101400.0", "high"), {}, {}, ["rig.csv", "column 'Sensor_0'", "row 3", "'high' is not a number"]),
    ("ragged-row", USER_CSV.replace("32,4.5,0.04", "32,4.5"), {}, {}, ["rig.csv", "line 6", "6 fields, expected 7"]),
    ("empty-file", "", {}, {}, ["rig.csv", "not a readable CSV file"]),
    ("duplicate-header", USER_CSV.replace("x,z", "x,x"), {}, {}, ["rig.csv", "column 'x' appears twice"]),
    ("non-numeric-mapped", USER_CSV, {"columns": {"contact": {"column": "x", "unit": "1"}}, "channels": [{"column": "Sensor_0",
        "unit": "Pa"}]}, {"sensor": "pad5x5"}, ["rig.csv", "1 channel columns", "25 taxels"]),
]


@pytest.mark.parametrize(("text", "changes", "keywords", "fragments"), [case[1:] for case in BAD_CSV], ids=[case[0] for case in BAD_CSV])
def test_bad_user_csv(tmp_path, text, changes, keywords, fragments):
    text = USER_CSV if text is None else text
    if changes is None:
        data = tmp_path / "rig.csv"
        data.write_text(text)
        mapping = None
    else:
        mapping_document = changes if isinstance(changes, str) else {k: v for k, v in _mapping(**changes).items() if v is not None}
        data, mapping = _write_user(tmp_path, mapping_document, text)
    with pytest.raises(HydrotactError) as error:
        read_log(data, mapping, **keywords)
    _one_line(error, *fragments)


def test_load_mapping_errors_name_the_file(tmp_path):
    with pytest.raises(HydrotactError, match=r"nowhere\.json: no such file"):
        load_mapping(tmp_path / "nowhere.json")
    (tmp_path / "list.json").write_text("[1]")
    with pytest.raises(HydrotactError, match=r"list\.json: \(document\): must be an object"):
        load_mapping(tmp_path / "list.json")


def test_missing_log_and_wrong_sensor(tmp_path):
    with pytest.raises(HydrotactError, match=r"absent\.csv: no such log file"):
        read_log(tmp_path / "absent.csv")
    write_log(tmp_path / "log.csv", _log())
    with pytest.raises(HydrotactError, match=r"log\.csv: sensor: the log is from 'bench3', not 'pad5x5'"):
        read_log(tmp_path / "log.csv", sensor="pad5x5")
    (tmp_path / "log.json").write_text('{"format": "hydrotact.barometer_log"}')
    with pytest.raises(HydrotactError, match=r"log\.json: version: is missing"):
        read_log(tmp_path / "log.csv")


def test_wrong_channel_count_for_a_builtin_sensor():
    log = _log(sensor="pad5x5")
    with pytest.raises(HydrotactError) as error:
        check_log(log, "mylog.parquet")
    _one_line(error, "mylog.parquet: channels: 3 channel columns, but sensor 'pad5x5' has 25 taxels")


@pytest.mark.parametrize(
    ("pressure", "value", "fragments"),
    [("absolute", 0.0, ["row 7", "absolute pressure 0 Pa is not positive"]), ("tared", -2e7, ["row 7", "-2e+07 Pa is beyond"]), ("elastic", 1.5e7, ["row 7", "1.5e+07 Pa"])],
)
def test_impossible_pressures(pressure, value, fragments):
    log = _log(pressure=pressure)
    log.columns["b01"][6] = value
    with pytest.raises(HydrotactError) as error:
        check_log(log, "mylog.csv")
    _one_line(error, "mylog.csv: column 'b01'", *fragments)


# --- sampling warnings ----------------------------------------------------------------


def _timed(times, rate_hz=100.0):
    log = _log(num=len(times), rate_hz=rate_hz)
    if rate_hz is None:
        del log.metadata["rate_hz"]
    log.columns["time"] = np.asarray(times, dtype=np.float64)
    return log


def test_jitter_warning():
    rng = np.random.default_rng(0)
    times = np.cumsum(0.01 * (1.0 + 0.2 * rng.uniform(-1.0, 1.0, 200)))
    with pytest.warns(LogWarning, match=r"mylog\.csv: column 'time': uneven sampling: median step 0\.01\d* s, relative std of the steps 1\d\.\d% \(over 5%\)"):
        check_log(_timed(times, rate_hz=None), "mylog.csv")


def test_gap_warning():
    times = np.arange(100) * 0.01
    times[40:] += 0.5
    times[70:] += 0.03
    with pytest.warns(LogWarning) as record:
        check_log(_timed(times), "mylog.csv")
    messages = [str(w.message) for w in record]
    assert len(messages) == 1, messages
    assert "2 gaps over 3x the median step (0.01 s), 0.55 s in all; the longest 0.51 s (51.0 steps), row 40 to row 41 (t = 0.39 s to 0.9 s)" in messages[0]


def test_rate_warning_and_quiet_regular_log():
    with pytest.warns(LogWarning, match=r"rate_hz: declared 100 Hz, measured 50 Hz from the median step 0\.02 s \(-50\.0%\)"):
        check_log(_timed(np.arange(50) * 0.02), "mylog.csv")
    check_log(_timed(np.arange(50) * 0.0101), "mylog.csv")  # 1 % off: no warning
    check_log(_timed(np.arange(50) * 0.01), "mylog.csv", warn=True)


def test_read_warns_write_does_not(tmp_path):
    log = _timed(np.arange(50) * 0.02)
    write_log(tmp_path / "slow.csv", log)
    with pytest.warns(LogWarning, match="slow.csv: rate_hz"):
        read_log(tmp_path / "slow.csv")


# --- tare -------------------------------------------------------------------------------

RATE = 100.0
SIGMA = 0.5


def _loaded_log(with_contact=False, pulses=(5.0, 13.0, 20.0, 28.0, 35.0, 45.0, 52.0)):
    """60 s, four channels: per-channel baselines near 1 atm drifting 20 Pa over the
    log (plus a slow bend), white noise SIGMA, and 2 s load pulses (0.3 s ramps, a
    1.7 s hold: quiet stretches above the baseline) seen by each channel with its gain."""
    rng = np.random.default_rng(11)
    times = np.arange(0.0, 60.0, 1.0 / RATE)
    baselines = np.array([101000.0, 100500.0, 101200.0, 100900.0])
    drift = (20.0 * times / 60.0 + 2.0 * np.sin(2.0 * np.pi * times / 120.0))[:, None] * np.array([1.0, 0.5, -1.0, 2.0])
    load = np.zeros_like(times)
    for start in pulses:
        load += 300.0 * np.clip((times - start) / 0.3, 0.0, 1.0) * np.clip((start + 2.3 - times) / 0.3, 0.0, 1.0)
    gains = np.array([1.0, 0.6, 0.3, 0.05])
    readings = baselines + drift + load[:, None] * gains + rng.normal(0.0, SIGMA, (len(times), 4))
    names = ["c0", "c1", "c2", "c3"]
    columns = {"time": times, **{name: readings[:, k] for k, name in enumerate(names)}}
    if with_contact:
        columns["contact"] = (load > 0.0).astype(np.int8)
    metadata = _metadata(channels=names, rate_hz=RATE)
    return BarometerLog(metadata=metadata, columns=columns), baselines + drift, load


def test_tare_finds_no_load_from_the_signal():
    log, truth, load = _loaded_log()
    segments = find_no_load_segments(log)
    times = log.times
    assert len(segments) == 8
    for start, stop in segments:
        assert np.all(load[start:stop] == 0.0), (times[start], times[stop - 1])
        assert stop - start >= 50
    covered = sum(stop - start for start, stop in segments) / np.count_nonzero(load == 0.0)
    assert covered > 0.85
    tared, baselines = tare_log(log, source="rig.csv")
    error = (log.channels - tared.channels) - truth
    assert np.max(np.abs(error)) < SIGMA, np.max(np.abs(error), axis=0)
    no_load = load == 0.0
    assert np.all(np.abs(tared.channels[no_load].mean(axis=0)) < 3 * SIGMA / math.sqrt(no_load.sum()) + 0.05)
    np.testing.assert_allclose(baselines, truth[np.concatenate([np.arange(a, b) for a, b in segments])].mean(axis=0), atol=0.05)
    assert tared.metadata["pressure"] == "tared"
    tare = tared.metadata["tare"]
    assert tare["method"] == "signal" and len(tare["segments_s"]) == 8 and np.shape(tare["baselines_Pa"]) == (8, 4)
    assert tare["segments_s"][0][0] == 0.0
    check_log(tared, "rig.csv")
    assert log.metadata["pressure"] == "absolute", "the input log is untouched"


def test_tare_round_trips_through_a_file(tmp_path):
    log, _, _ = _loaded_log()
    tared, _ = tare_log(log)
    write_log(tmp_path / "tared.csv", tared)
    assert read_log(tmp_path / "tared.csv").metadata["tare"] == tared.metadata["tare"]


def test_tare_uses_the_contact_column_and_margin():
    log, truth, load = _loaded_log(with_contact=True)
    segments = find_no_load_segments(log)
    contact_free = _runs_of(load == 0.0)
    assert segments == contact_free
    trimmed = find_no_load_segments(log, margin=0.2)  # 20 samples off each end
    assert len(trimmed) == len(contact_free)
    for (start, stop), (free_start, free_stop) in zip(trimmed, contact_free, strict=True):
        assert free_start + 19 <= start <= free_start + 21 and free_stop - 21 <= stop <= free_stop - 19
    tared, _ = tare_log(log)
    assert tared.metadata["tare"]["method"] == "contact"
    assert np.max(np.abs((log.channels - tared.channels) - truth)) < SIGMA


def _runs_of(mask):
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True))


def test_tare_with_indentation_and_force_columns():
    log, truth, load = _loaded_log()
    log.columns["indentation"] = np.where(load > 0.0, 1e-4, -1e-3)
    assert find_no_load_segments(log) == _runs_of(load == 0.0)
    del log.columns["indentation"]
    log.columns["fz"] = load / 100.0
    assert find_no_load_segments(log) == _runs_of(load <= 10.0)
    assert find_no_load_segments(log, method="signal") != find_no_load_segments(log)


def test_tare_on_given_segments():
    log, truth, load = _loaded_log()
    tared, baselines = tare_log(log, [(0, 400), (5500, 6000)])
    assert tared.metadata["tare"]["method"] == "rows"
    assert tared.metadata["tare"]["segments_s"] == [[0.0, 3.99], [55.0, 59.99]]
    np.testing.assert_allclose(baselines, log.channels[np.r_[0:400, 5500:6000]].mean(axis=0))
    by_time, _ = tare_log(log, segment_times=[(0.0, 3.995), (55.0, 60.0)])
    assert by_time.metadata["tare"]["method"] == "times"
    np.testing.assert_array_equal(by_time.channels, tared.channels)
    single, single_baselines = tare_log(log, segment_times=[(0.0, 4.0)])
    np.testing.assert_allclose(log.channels - single.channels, np.broadcast_to(single_baselines, log.channels.shape))


@pytest.mark.parametrize(
    ("keywords", "fragments"),
    [
        ({"method": "contact"}, ["tare method 'contact' needs the log's contact column"]),
        ({"method": "psychic"}, ["unknown tare method 'psychic'"]),
        ({"segment_times": [(70.0, 80.0)]}, ["segment_times[0]", "holds no sample", "0 s to 59.99 s"]),
        ({"segment_times": [(3.0, 2.0)]}, ["segment_times[0]", "holds no sample"]),
        ({"segments": [(10, 5)]}, ["segments[0]", "(10, 5)"]),
        ({"segments": [(0, 10)], "segment_times": [(0.0, 1.0)]}, ["not both"]),
        ({"min_duration": 100.0}, ["no no-load segment found", "method 'signal'", "segment_times"]),
    ],
    ids=["missing-contact", "unknown-method", "times-outside", "times-reversed", "rows-reversed", "both", "none-found"],
)
def test_tare_errors(keywords, fragments):
    log, _, _ = _loaded_log()
    with pytest.raises(HydrotactError) as error:
        tare_log(log, source="rig.csv", **keywords)
    _one_line(error, "rig.csv: ", *fragments)


def test_tare_without_load_anywhere_and_with_load_throughout():
    log, _, _ = _loaded_log(pulses=())
    assert find_no_load_segments(log) == [(0, log.num_samples)]
    log.columns["contact"] = np.ones(log.num_samples, dtype=np.int8)
    with pytest.raises(HydrotactError, match=r"log: no no-load segment found \(method 'contact'"):
        tare_log(log)


def test_tare_refuses_an_elastic_log():
    log, _, _ = _loaded_log()
    elastic = BarometerLog(metadata={**log.metadata, "pressure": "elastic"}, columns=log.columns)
    with pytest.raises(HydrotactError, match=r"sim\.parquet: pressure: an 'elastic' \(simulated\) log has no barometer baseline"):
        tare_log(elastic, source="sim.parquet")


# --- materials ----------------------------------------------------------------------------


def _material(**changes):
    document = make_material_document(
        1.0e6,
        [2.0e5, 5.0e4],
        [0.5, 8.0],
        stds={"long_term_modulus": 5e3, "moduli": [1e3, 2e3], "taus": [0.01, 0.3]},
        covariance=np.diag([1e-4, 2e-4, 3e-4, 4e-4, 5e-4]),
        channels=[{"name": "b00", "gain": (1.0, 0.01), "offset_Pa": {"value": -2.0, "std": 1.0}}],
        provenance={"created": "2026-11-23T00:00:00Z", "method": "fit", "mode": "lumped", "solver": "lm", "sensor": "pad5x5",
            "logs": [{"path": "a.csv", "sha256": "ab" * 32}], "num_samples": 1000, "cost": 1.5, "criterion": {"name": "bic", "value": -12.0}},
        name="ecoflex",
        description="test",
    )
    document.update(changes)
    return document


def test_material_round_trip(tmp_path):
    document = _material()
    assert document["instantaneous_modulus_Pa"] == {"value": 1.25e6}
    assert document["covariance"]["parameters"] == ["log_long_term_modulus", "log_modulus_1", "log_modulus_2", "log_tau_1", "log_tau_2"]
    assert document["channels"][0] == {"name": "b00", "gain": {"value": 1.0, "std": 0.01}, "offset_Pa": {"value": -2.0, "std": 1.0}}
    path = tmp_path / "material.json"
    assert write_material(path, document) == path
    assert read_material(path) == document
    assert sorted(p.name for p in tmp_path.iterdir()) == ["material.json"]
    elastic = make_material_document(3e5, [], [])
    assert elastic["prony_terms"] == [] and elastic["provenance"]["method"] == "manual"
    assert elastic["provenance"]["generator"].startswith("hydrotact ")
    write_material(path, elastic)
    assert read_material(path) == elastic


def _term(modulus, tau):
    return {"modulus_Pa": {"value": modulus}, "tau_s": {"value": tau}}


BAD_MATERIALS = [
    ("format", {"format": "hydrotact.mat"}, ["format"]),
    ("no-long-term", {"long_term_modulus_Pa": None}, ["long_term_modulus_Pa", "is missing"]),
    ("negative-modulus", {"long_term_modulus_Pa": {"value": -1.0}}, ["long_term_modulus_Pa.value", "> 0"]),
    ("negative-std", {"long_term_modulus_Pa": {"value": 1e6, "std": -1.0}}, ["long_term_modulus_Pa.std", ">= 0"]),
    ("zero-tau", {"prony_terms": [_term(1e5, 0.0)], "instantaneous_modulus_Pa": None}, ["prony_terms[0].tau_s.value", "> 0"]),
    ("repeated-tau", {"prony_terms": [_term(1e5, 0.5), _term(2e5, 0.5)], "instantaneous_modulus_Pa": None, "covariance": None}, ["prony_terms[1].tau_s.value", "distinct"]),
    ("instantaneous-off", {"instantaneous_modulus_Pa": {"value": 1.3e6}}, ["instantaneous_modulus_Pa.value", "1250000 Pa"]),
    ("covariance-rows", {"covariance": {"parameters": ["a", "b"], "space": "log", "matrix": [[1.0, 0.0]]}}, ["covariance.matrix", "1 rows for 2 parameters"]),
    ("covariance-columns", {"covariance": {"parameters": ["a", "b"], "space": "log", "matrix": [[1.0, 0.0], [0.0]]}}, ["covariance.matrix[1]", "1 numbers, expected 2"]),
    ("covariance-asymmetric", {"covariance": {"parameters": ["a", "b"], "space": "log", "matrix": [[1.0, 0.5], [0.2, 1.0]]}}, ["covariance.matrix[0][1]", "symmetric"]),
    ("covariance-variance", {"covariance": {"parameters": ["a"], "space": "log", "matrix": [[-1.0]]}}, ["covariance.matrix[0][0]", "variance"]),
    ("covariance-space", {"covariance": {"parameters": ["a"], "space": "sqrt", "matrix": [[1.0]]}}, ["covariance.space"]),
    ("no-provenance", {"provenance": None}, ["provenance", "is missing"]),
    ("provenance-method", {"provenance": {"generator": "x", "created": "2026-11-23T00:00:00Z", "method": "guess"}}, ["provenance.method"]),
    ("provenance-created", {"provenance": {"generator": "x", "created": "yesterday", "method": "fit"}}, ["provenance.created"]),
    ("provenance-sha", {"provenance": {"generator": "x", "created": "2026-11-23T00:00:00Z", "method": "fit", "logs": [{"path": "a", "sha256": "xyz"}]}}, ["provenance.logs[0].sha256"]),
    ("channel-twice", {"channels": [{"name": "b00"}, {"name": "b00"}]}, ["channels[1].name", "twice"]),
    ("channel-gain", {"channels": [{"name": "b00", "gain": {"value": 0.0}}]}, ["channels[0].gain.value"]),
    ("unknown-field", {"nu": 0.5}, ["nu", "unknown field"]),
    ("nan", {"long_term_modulus_Pa": {"value": float("nan")}}, ["long_term_modulus_Pa.value", "finite"]),
]


@pytest.mark.parametrize(("changes", "fragments"), [case[1:] for case in BAD_MATERIALS], ids=[case[0] for case in BAD_MATERIALS])
def test_bad_material(tmp_path, changes, fragments):
    document = {key: value for key, value in _material(**changes).items() if value is not None}
    with pytest.raises(HydrotactError) as error:
        check_material(document, "mat.json")
    _one_line(error, "mat.json: ", *fragments)
    path = tmp_path / "mat.json"
    with pytest.raises(HydrotactError):
        write_material(path, document)
    assert not path.exists() and not list(tmp_path.iterdir())
    path.write_text(json.dumps(document))
    with pytest.raises(HydrotactError) as error:
        read_material(path)
    _one_line(error, str(path), *fragments)


def test_read_material_malformed(tmp_path):
    path = tmp_path / "mat.json"
    path.write_text('{"format": ')
    with pytest.raises(HydrotactError, match=r"mat\.json: not valid JSON"):
        read_material(path)
    with pytest.raises(HydrotactError, match="moduli but"):
        make_material_document(1e6, [1.0, 2.0], [1.0])


# --- schemas ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["barometer_log", "column_mapping", "material", "model"])
def test_schema_documents(name):
    schema = load_schema(name)
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["$id"] == f"urn:hydrotact:schema:{name}"
    assert schema.get("title") and schema.get("description")

    def walk(node, where):
        if isinstance(node, dict):
            for key, child in node.get("properties", {}).items():
                assert child.get("title") and child.get("description"), f"{where}.{key}"
            for key, child in node.items():
                walk(child, f"{where}.{key}")
        elif isinstance(node, list):
            for child in node:
                walk(child, where)

    walk(schema, name)
    for key, definition in schema.get("$defs", {}).items():
        assert definition.get("title") and definition.get("description"), key
