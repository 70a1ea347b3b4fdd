"""Barometer logs: Parquet round trip, the metadata schema, and one clear error per
bad log naming the file, the column and the (1-based) row."""

import json

import numpy as np
import pytest

from hydrotact import HydrotactError
from hydrotact._schemas import load_schema
from hydrotact.data import BarometerLog, check_log, known_columns, read_log, write_log

CHANNELS = ["b00", "b01", "b02"]
NUM = 5


def _metadata(**changes):
    metadata = {
        "format": "hydrotact.barometer_log",
        "version": 1,
        "sensor": "bench3",  # names no spec: no channel-count check (tests/test_log_formats.py has those)
        "source": "simulated",
        "pressure": "elastic",
        "channels": list(CHANNELS),
        "rate_hz": 100.0,
        "probe": "cylinder:d=2mm",
        "material": {"modulus_Pa": 1e6},
        "field": "laplace",
        "num_rays": 16,
        "generator": "hydrotact test",
    }
    metadata.update(changes)
    return metadata


def _columns():
    rng = np.random.default_rng(7)
    columns = {"time": np.arange(NUM) * 0.01}
    for name in CHANNELS:
        columns[name] = rng.uniform(0.0, 1e4, NUM)
    for name in ("probe_x", "probe_y", "probe_z", "fx", "fy", "fz", "fn"):
        columns[name] = rng.normal(size=NUM)
    columns["theta"] = np.array([np.nan, 0.1, 0.2, np.nan, -0.3])
    columns["phi"] = np.array([np.nan, 0.0, 1.0, np.nan, 2.0])
    columns["contact"] = np.array([0, 1, 1, 0, 1], dtype=np.int8)
    return columns


def _log(metadata=None, **column_changes):
    columns = _columns()
    for name, values in column_changes.items():
        if values is None:
            del columns[name]
        else:
            columns[name] = values
    return BarometerLog(metadata=metadata or _metadata(), columns=columns)


def _with(column, row, value):
    values = _columns()[column].astype(np.float64)
    values[row] = value
    return values


def test_round_trip(tmp_path):
    path = tmp_path / "log.parquet"
    log = _log()
    assert write_log(path, log) == path
    back = read_log(path)
    assert back.metadata == log.metadata
    assert list(back.columns) == list(log.columns)
    for name, values in log.columns.items():
        np.testing.assert_array_equal(back.columns[name], values, err_msg=name)
    assert back.columns["contact"].dtype == np.int8
    assert back.columns["time"].dtype == np.float64
    assert back.num_samples == NUM
    np.testing.assert_array_equal(back.times, log.columns["time"])
    assert back.channels.shape == (NUM, len(CHANNELS))
    np.testing.assert_array_equal(back.channels[:, 1], log.columns["b01"])
    assert not list(tmp_path.glob(".log.parquet*")), "a temporary file was left behind"


def test_minimal_log_and_recorded_metadata(tmp_path):
    """Only the required metadata and columns: time and the channels."""
    metadata = {k: v for k, v in _metadata(source="recorded", pressure="absolute").items() if k in ("format", "version", "sensor", "source", "pressure", "channels")}
    columns = {"time": np.array([0.0, 0.5, 1.0]), **{name: np.array([1e5, 1e5 + 1, 1e5 + 2]) for name in CHANNELS}}
    path = tmp_path / "minimal.parquet"
    write_log(path, BarometerLog(metadata=metadata, columns=columns))
    back = read_log(path)
    assert back.metadata == metadata and set(back.columns) == set(columns)


def test_known_columns_have_units_and_descriptions():
    columns = known_columns()
    for name in ("time", "probe_x", "fx", "fn", "theta", "phi", "contact"):
        assert name in columns
    for name, info in columns.items():
        assert info.get("unit") and info.get("description"), name
    # The angles, as labels and as an estimator's estimates, are NaN off contact.
    assert {name for name, info in columns.items() if info.get("nan_allowed")} == {"theta", "phi", "est_theta", "est_phi", "contact_x", "contact_y", "depth"}


@pytest.mark.parametrize(
    ("change", "fragments"),
    [
        ({"time": None}, ["missing column 'time'"]),
        ({"b01": None}, ["missing column 'b01'"]),
        ({"b02": _with("b02", 2, np.nan)}, ["'b02'", "row 3", "missing value (NaN or blank)"]),
        ({"fx": _with("fx", 0, np.nan)}, ["'fx'", "row 1", "missing value"]),
        ({"b00": _with("b00", 4, np.inf)}, ["'b00'", "row 5", "not a finite number"]),
        ({"theta": _with("theta", 1, -np.inf)}, ["'theta'", "row 2", "not a finite number"]),
        ({"time": _with("time", 3, np.nan)}, ["'time'", "row 4", "missing value"]),
        ({"time": np.array([0.0, 0.01, 0.02, 0.015, 0.04])}, ["'time'", "row 4", "goes back"]),
        ({"time": np.array([0.0, 0.01, 0.01, 0.03, 0.04])}, ["'time'", "row 3", "repeats"]),
        ({"pressure_b00": np.zeros(NUM)}, ["unknown column 'pressure_b00'"]),
        ({"b01": np.zeros(NUM - 1)}, ["'b01'", f"expected {NUM}"]),
        ({"fz": np.zeros(NUM + 2)}, ["'fz'", f"expected {NUM}"]),
        ({"b00": np.zeros((NUM, 2))}, ["'b00'", f"expected {NUM}"]),
        ({"b00": np.array(["1", "2", "3", "4", "5"])}, ["'b00'", "not numeric"]),
        ({"fn": np.array([1.0, None, 2.0, 3.0, 4.0], dtype=object)}, ["'fn'", "not numeric"]),
        ({"fy": np.array([1j, 0, 0, 0, 0])}, ["'fy'", "not numeric"]),
    ],
    ids=[
        "no-time", "no-channel", "nan-channel", "nan-fx", "inf-channel", "inf-theta", "nan-time", "time-goes-back",
        "time-repeats", "unknown-column", "short-column", "long-column", "2d-column", "string-column",
        "object-column", "complex-column",
    ],
)
def test_bad_columns(tmp_path, change, fragments):
    log = _log(**change)
    _assert_refused(tmp_path, log, fragments)


@pytest.mark.parametrize(
    ("metadata", "fragments"),
    [
        (_metadata(format="hydrotact.log"), ["format", "hydrotact.barometer_log"]),
        (_metadata(version=2), ["version"]),
        (_metadata(pressure="gauge"), ["pressure", "gauge", "elastic"]),
        (_metadata(source="dreamt"), ["source", "dreamt"]),
        (_metadata(channels=[]), ["channels", "must not be empty"]),
        (_metadata(channels=["b00", "b00"]), ["channels"]),
        (_metadata(channels=["b 0"]), ["channels[0]"]),
        (_metadata(channels=["b00", "fx"]), ["'fx'", "reserved"]),
        (_metadata(channels=["time"]), ["'time'", "reserved"]),
        (_metadata(colour="red"), ["colour", "unknown field"]),
        (_metadata(material={"modulus_Pa": -1.0}), ["material.modulus_Pa"]),
        (_metadata(material={"modulus_Pa": 1e6, "nu": 0.5}), ["material.nu", "unknown field"]),
        (_metadata(rate_hz=0.0), ["rate_hz"]),
        (_metadata(num_rays=1.5), ["num_rays"]),
        (_metadata(rate_hz=float("nan")), ["rate_hz", "finite"]),
        ({k: v for k, v in _metadata().items() if k != "sensor"}, ["sensor", "is missing"]),
    ],
    ids=[
        "format", "version", "pressure-enum", "source-enum", "no-channels", "duplicate-channels", "bad-channel-name",
        "channel-reserved", "channel-time", "unknown-key", "negative-modulus", "unknown-material-key", "zero-rate",
        "fractional-rays", "nan-rate", "no-sensor",
    ],
)
def test_bad_metadata(tmp_path, metadata, fragments):
    columns = _columns()
    for name in metadata.get("channels", []):
        if name not in columns:
            columns[name] = np.ones(NUM)
    log = BarometerLog(metadata=metadata, columns=columns)
    _assert_refused(tmp_path, log, fragments)


def _assert_refused(tmp_path, log, fragments):
    """check_log says what is wrong in one line naming the file and `fragments`, and
    write_log refuses the log."""
    with pytest.raises(HydrotactError) as error:
        check_log(log, "mylog.parquet")
    message = str(error.value)
    assert message.startswith("mylog.parquet: ") and "\n" not in message
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    _assert_write_refused(tmp_path, log, fragments)


def _assert_write_refused(tmp_path, log, fragments):
    """write_log refuses the bad log: no new file, an existing good file untouched, no
    temporary file left."""
    fresh = tmp_path / "fresh.parquet"
    with pytest.raises(HydrotactError) as error:
        write_log(fresh, log)
    assert str(fresh) in str(error.value)
    for fragment in fragments:
        assert fragment in str(error.value)
    assert not fresh.exists()

    good = tmp_path / "good.parquet"
    write_log(good, _log())
    before = good.read_bytes()
    with pytest.raises(HydrotactError):
        write_log(good, log)
    assert good.read_bytes() == before
    assert read_log(good).metadata == _metadata()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.parquet"]


def _write_raw(path, columns, metadata):
    """A Parquet file written without our checks."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table(columns)
    if metadata is not None:
        table = table.replace_schema_metadata({b"hydrotact": metadata if isinstance(metadata, bytes) else json.dumps(metadata).encode()})
    pq.write_table(table, path)


def test_read_checks_the_file(tmp_path):
    """read_log applies the same checks to what it reads, naming the file."""
    path = tmp_path / "bad.parquet"
    columns = _columns()
    columns["b01"] = _with("b01", 3, np.nan)
    _write_raw(path, columns, _metadata())
    with pytest.raises(HydrotactError, match=r"bad\.parquet: column 'b01', row 4: missing value \(NaN or blank\)"):
        read_log(path)

    columns = _columns()
    columns["time"] = np.array([0.0, 0.01, 0.005, 0.03, 0.04])
    _write_raw(path, columns, _metadata())
    with pytest.raises(HydrotactError, match=r"bad\.parquet: column 'time', row 3: time goes back"):
        read_log(path)

    columns = _columns()
    del columns["b02"]
    _write_raw(path, columns, _metadata())
    with pytest.raises(HydrotactError, match=r"bad\.parquet: missing column 'b02'"):
        read_log(path)

    _write_raw(path, {**_columns(), "label": np.zeros(NUM)}, _metadata())
    with pytest.raises(HydrotactError, match=r"bad\.parquet: unknown column 'label'"):
        read_log(path)

    _write_raw(path, {**_columns(), "b00": np.array(["a", "b", "c", "d", "e"])}, _metadata())
    with pytest.raises(HydrotactError, match=r"bad\.parquet: column 'b00' is not numeric"):
        read_log(path)

    _write_raw(path, _columns(), _metadata(pressure="gauge"))
    with pytest.raises(HydrotactError, match=r"bad\.parquet: pressure: must be one of"):
        read_log(path)


def test_read_refuses_files_that_are_not_logs(tmp_path):
    plain = tmp_path / "plain.parquet"
    _write_raw(plain, _columns(), None)
    with pytest.raises(HydrotactError, match=r"plain\.parquet: no hydrotact metadata"):
        read_log(plain)

    garbled = tmp_path / "garbled.parquet"
    _write_raw(garbled, _columns(), b"{not json")
    with pytest.raises(HydrotactError, match=r"garbled\.parquet: metadata: not valid JSON"):
        read_log(garbled)

    listed = tmp_path / "listed.parquet"
    _write_raw(listed, _columns(), [1, 2])
    with pytest.raises(HydrotactError, match=r"listed\.parquet: \(document\): must be an object"):
        read_log(listed)

    text = tmp_path / "notes.parquet"
    text.write_text("time,b00\n0,1\n")
    with pytest.raises(HydrotactError, match=r"notes\.parquet: not a readable Parquet file") as error:
        read_log(text)
    assert "\n" not in str(error.value)

    empty = tmp_path / "empty.parquet"
    empty.write_bytes(b"")
    with pytest.raises(HydrotactError, match=r"empty\.parquet: not a readable Parquet file"):
        read_log(empty)

    with pytest.raises(HydrotactError, match=r"missing\.parquet: no such log file"):
        read_log(tmp_path / "missing.parquet")
    with pytest.raises(HydrotactError, match="no such log file"):
        read_log(tmp_path)


def test_schema_document():
    """The log schema's own contract (every schema's titles and descriptions are
    checked in test_log_formats.test_schema_documents)."""
    schema = load_schema("barometer_log")
    assert set(schema["required"]) <= set(schema["properties"])
    for name, definition in schema["$defs"].items():
        assert definition.get("title") and definition.get("description"), name
    assert schema["properties"]["pressure"]["enum"] == ["elastic", "tared", "absolute"]


VISCOELASTIC = {"modulus_Pa": 1.5e6, "long_term_modulus_Pa": 1e6, "prony_terms": [{"modulus_Pa": 5e5, "tau_s": 0.5}]}
UNDERSHOOT = np.array([0.0, 8e3, 6e3, -1.2e3, -0.4e3])  # a press, a fast release: the linear model dips below zero


@pytest.mark.parametrize("material", [VISCOELASTIC, None], ids=["viscoelastic", "material-not-said"])
def test_a_viscoelastic_release_may_read_below_zero(material):
    """The linear viscoelastic model reads below zero after a fast release (less than
    the load it follows): a simulated log of it is read, as `simulate` writes it."""
    metadata = _metadata(material=material) if material else {k: v for k, v in _metadata().items() if k != "material"}
    check_log(_log(metadata, b01=UNDERSHOOT), "log.parquet")


@pytest.mark.parametrize(
    ("material", "values", "fragments"),
    [
        ({"modulus_Pa": 1e6}, UNDERSHOOT, ["'b01'", "row 4", "-1200 Pa is negative", "an elastic material pushes"]),
        (VISCOELASTIC, -UNDERSHOOT, ["'b01'", "row 2", "-8000 Pa is negative", "outweighs its peak, 1200 Pa", "sign flipped"]),
        ({"modulus_Pa": 1e6}, -UNDERSHOOT, ["'b01'", "row 2", "-8000 Pa is negative"]),
    ],
    ids=["elastic-undershoot", "viscoelastic-flipped", "elastic-flipped"],
)
def test_elastic_pressures_of_the_wrong_sign_are_refused(tmp_path, material, values, fragments):
    _assert_refused(tmp_path, _log(_metadata(material=material), b01=values), fragments)


def test_a_barometer_reading_the_elastomers_stress_may_read_tension(tmp_path):
    """A channel named in `stress_channels` (an elastic barometer: its port's stress,
    which a press bending a pocket's ceiling puts in tension) may read below zero
    under an elastic material; the log's other channels are still checked, and a
    stress channel that is not a channel is refused."""
    elastic = {"modulus_Pa": 1e6}
    tension = -UNDERSHOOT
    check_log(_log(_metadata(material=elastic, stress_channels=["b01"]), b01=tension), "log.parquet")
    _assert_refused(tmp_path, _log(_metadata(material=elastic, stress_channels=["b01"]), b00=tension), ["'b00'", "-8000 Pa is negative"])
    _assert_refused(tmp_path, _log(_metadata(material=elastic, stress_channels=["b99"])), ["stress_channels", "'b99' is not one of the log's channels"])
    path = tmp_path / "stress.parquet"
    write_log(path, _log(_metadata(material=elastic, stress_channels=["b01"]), b01=tension))
    np.testing.assert_array_equal(read_log(path).columns["b01"], tension)
