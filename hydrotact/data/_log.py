"""Barometer logs: a table of samples (time, one column per barometer, optional probe,
wrench and label columns) with a metadata document, in Parquet or CSV.

The contract is `data_schemas/barometer_log.schema.json`: the metadata is validated
against it and stored in the Parquet file's key-value metadata under `hydrotact`, or,
for a CSV log `NAME.csv`, in the JSON document `NAME.json` beside it. The known optional
columns and their units are listed in its `$defs/columns`. Every number is SI. A table
of the user's own layout is read through a column mapping (see `_mapping.py`).

Reading checks what a fit would trip over and names the file, column and (1-based) row:
missing columns, runs of missing values, non-finite values, times that do not strictly
increase, a channel count other than the sensor's, pressures no barometer reads. Uneven
sampling (jitter, gaps, a rate other than the declared one) is a :class:`LogWarning`
with the figures.
"""

import json
import re
import warnings
from pathlib import Path

import numpy as np

from .._errors import HydrotactError, HydrotactWarning
from .._files import atomic_path
from .._schemas import parse_json, read_json, validate
from ._mapping import ColumnMapping, apply_mapping, load_mapping
from ._table import BarometerLog, known_columns, sensor_spec

METADATA_KEY = b"hydrotact"
SUFFIXES = (".parquet", ".csv")
# Sampling figures that draw a warning: relative std of the steps, gap size in median
# steps, relative difference between the declared and the measured rate.
JITTER_LIMIT = 0.05
GAP_STEPS = 3.0
RATE_LIMIT = 0.02
# Tared or elastic pressures beyond this many pascals are no barometer reading (10 MPa).
PRESSURE_LIMIT_PA = 1e7
# Absolute readings of a sensor whose part we do not know: a barometer in air, from
# high altitude to a hard press (the BMP388 reads 30-125 kPa; others a little wider).
ABSOLUTE_RANGE_PA = (2e4, 3e5)
# An elastic pressure below -this x the channel's peak is negative, not round-off (a
# viscoelastic simulation relaxes to -1e-13 Pa after a 1e5 Pa press).
NEGATIVE_ROUND_OFF = 1e-9


class LogWarning(HydrotactWarning):
    """A log that reads but may mislead a fit: uneven sampling, gaps, a rate other
    than the declared one. The message gives the figures."""


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where `mask` is true."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True))


def _check_values(log: BarometerLog, name: str, values: np.ndarray, source: str, known: dict) -> None:
    label = log.describe_column(name)
    floats = values.astype(np.float64)
    missing = np.isnan(floats)
    if not known.get(name, {}).get("nan_allowed") and missing.any():
        runs = _runs(missing)
        start, stop = runs[0]
        where = f"row {start + 1}: missing value" if stop - start == 1 else f"rows {start + 1}-{stop}: {stop - start} missing values"
        more = f"; {len(runs)} runs, {int(missing.sum())} missing values in all" if len(runs) > 1 else ""
        raise HydrotactError(f"{source}: column {label}, {where} (NaN or blank){more}")
    infinite = np.isinf(floats)
    if infinite.any():
        row = int(np.flatnonzero(infinite)[0])
        raise HydrotactError(f"{source}: column {label}, row {row + 1}: {values[row]} is not a finite number")


def _unit_hint(value: float, low: float, high: float) -> str:
    """The pressure unit a reading outside [low, high] Pa was most likely in."""
    for unit, size in (("hPa or mbar", 100.0), ("kPa", 1e3), ("bar", 1e5), ("psi", 6894.757293168361)):
        if low <= value * size <= high:
            return f" (in {unit}? the mapping's unit, or the channel's scale, converts it)"
    return " (is the unit, the scale or the pressure reference right?)"


def _check_pressures(log: BarometerLog, source: str, spec=None) -> None:
    """Readings a barometer can give: absolute ones positive and within the part's
    range (or, for a sensor we do not know, near the atmosphere), elastic ones
    (simulated elastomer pressure) of the right sign, none beyond 10 MPa. A barometer
    that reads the elastomer's stress at its port (an `elastic` receptive field: the
    log's `stress_channels`) reads tension too (a port on a free face that the press
    bends, as a pocket's ceiling): its sign is not checked."""
    reference = log.metadata["pressure"]
    low, high = (float(v) for v in spec.part.range_pa) if spec is not None else ABSOLUTE_RANGE_PA
    part = f"the {spec.part.name}'s range" if spec is not None else "the range of a barometer in air"
    stressed = set(log.metadata.get("stress_channels", ()))
    unknown = sorted(stressed - set(log.metadata["channels"]))
    if unknown:
        raise HydrotactError(f"{source}: stress_channels: {unknown[0]!r} is not one of the log's channels")
    for name in log.metadata["channels"]:
        values = np.asarray(log.columns[name], dtype=np.float64)
        label = log.describe_column(name)
        if reference == "absolute" and np.any(values <= 0.0):
            row = int(np.flatnonzero(values <= 0.0)[0])
            raise HydrotactError(f"{source}: column {label}, row {row + 1}: absolute pressure {values[row]:g} Pa is not positive (is the unit or the pressure reference right?)")
        if np.any(np.abs(values) > PRESSURE_LIMIT_PA):
            row = int(np.flatnonzero(np.abs(values) > PRESSURE_LIMIT_PA)[0])
            raise HydrotactError(f"{source}: column {label}, row {row + 1}: {values[row]:g} Pa is beyond the {PRESSURE_LIMIT_PA:g} Pa no barometer reads (is the unit right?)")
        if reference == "absolute":  # a part clips at its limits (the fit masks those); beyond them is a unit slip
            outside = (values < low) | (values > high)
            if np.any(outside):
                row = int(np.flatnonzero(outside)[0])
                raise HydrotactError(
                    f"{source}: column {label}, row {row + 1}: {values[row]:.6g} Pa is outside {part}, {low:g}-{high:g} Pa{_unit_hint(values[row], low, high)}"
                )
        if reference == "elastic" and name not in stressed:
            _check_elastic_sign(log, values, label, source)


def _check_elastic_sign(log: BarometerLog, values: np.ndarray, label: str, source: str) -> None:
    """Refuse elastomer pressures of the wrong sign. Under a purely elastic material the
    elastomer only pushes: any pressure below round-off is wrong. Under a viscoelastic
    one (the log's material has Prony terms, or is not said) the linear model reads
    below zero for a few τ after a fast release, by at most (E(0) - E∞) / E(0) of the
    load it remembers, so less than the channel's peak: a channel whose deepest dip
    outweighs its peak has its sign flipped."""
    peak, dip = float(np.max(values, initial=0.0)), float(-np.min(values, initial=0.0))
    material = log.metadata.get("material")
    elastic = isinstance(material, dict) and not material.get("prony_terms")
    negative = dip > NEGATIVE_ROUND_OFF * max(peak, dip, 1.0) if elastic else dip > peak
    if negative:
        row = int(np.argmin(values))
        why = (
            "the elastomer of an elastic material pushes, never pulls"
            if elastic
            else f"its deepest dip outweighs its peak, {peak:g} Pa: a viscoelastic release reads below zero by less than the load it follows"
        )
        raise HydrotactError(
            f"{source}: column {label}, row {row + 1}: elastic pressure {values[row]:g} Pa is negative ({why}); "
            "is the channel's sign flipped? A barometer reading minus its baseline is pressure: tared"
        )


def _check_time_unit(log: BarometerLog, source: str, spec=None) -> None:
    """Refuse a time column whose steps are 100x or more off the rate the log
    declares (or its part's): time in ms (or us) read as seconds."""
    times = np.asarray(log.columns["time"], dtype=np.float64)
    if len(times) < 3:
        return
    declared = log.metadata.get("rate_hz") or (spec.part.rate_hz if spec is not None and log.metadata.get("pressure") == "absolute" else None)
    if not declared:
        return
    measured = 1.0 / float(np.median(np.diff(times)))
    ratio = declared / measured
    if ratio >= 100.0 or ratio <= 0.01:
        what = "rate_hz" if log.metadata.get("rate_hz") else f"its {spec.part.name}'s rate"
        hint = "time in ms? (a mapping's time unit ms converts it)" if 300 <= ratio <= 3000 else "is the time column in seconds?"
        raise HydrotactError(
            f"{source}: column {log.describe_column('time')}: the median step is {1.0 / measured:.4g} s ({measured:.4g} Hz) but {what} is {declared:g} Hz "
            f"({ratio:.3g}x): {hint}"
        )


def _warn_sampling(log: BarometerLog, source: str) -> None:
    """LogWarnings for jitter, gaps and a declared rate the steps do not show."""
    times = np.asarray(log.columns["time"], dtype=np.float64)
    if len(times) < 3:
        return
    steps = np.diff(times)
    median = float(np.median(steps))
    label = log.describe_column("time")
    regular = steps[steps <= GAP_STEPS * median]
    jitter = float(np.std(regular) / median)
    if jitter > JITTER_LIMIT:
        warnings.warn(LogWarning(f"{source}: column {label}: uneven sampling: median step {median:.4g} s, relative std of the steps {jitter:.1%} (over {JITTER_LIMIT:.0%})"), stacklevel=3)
    gaps = np.flatnonzero(steps > GAP_STEPS * median)
    if len(gaps):
        longest = int(gaps[np.argmax(steps[gaps])])
        warnings.warn(
            LogWarning(
                f"{source}: column {label}: {len(gaps)} gap{'s' if len(gaps) > 1 else ''} over {GAP_STEPS:g}x the median step ({median:.4g} s), "
                f"{float(steps[gaps].sum()):.4g} s in all; the longest {float(steps[longest]):.4g} s ({float(steps[longest]) / median:.1f} steps), "
                f"row {longest + 1} to row {longest + 2} (t = {times[longest]:g} s to {times[longest + 1]:g} s)"
            ),
            stacklevel=3,
        )
    declared = log.metadata.get("rate_hz")
    measured = 1.0 / median
    if declared is not None and abs(measured - declared) > RATE_LIMIT * declared:
        warnings.warn(
            LogWarning(f"{source}: rate_hz: declared {declared:g} Hz, measured {measured:.4g} Hz from the median step {median:.4g} s ({(measured - declared) / declared:+.1%})"),
            stacklevel=3,
        )


def check_log(log: BarometerLog, source: str, *, warn: bool = True) -> None:
    """Validate metadata and columns; one HydrotactError naming file, column and row.

    Checks, in order: the metadata against the schema; that the channel names are not
    reserved; the columns present (time and every channel; no unknown ones); one length,
    numeric; no missing values (NaN or blank; reported as the first run of them, rows
    1-based) except where the schema allows NaN; finite values; strictly increasing
    time; as many channels as the sensor has taxels (when `sensor` names a built-in
    sensor or an existing sensor file); absolute pressures above 0 and no channel beyond
    1e7 Pa. With `warn`, uneven sampling is a :class:`LogWarning` with its figures:
    the relative std of the steps over 5 %, gaps over 3 median steps, a declared
    `rate_hz` more than 2 % off the measured one.

    **Arguments:**

    - `log`: the :class:`BarometerLog`.
    - `source`: the file name messages start with.
    - `warn`: whether to warn about the sampling (write_log does not).
    """
    validate(log.metadata, "barometer_log", source)
    known = known_columns()
    channels = log.metadata["channels"]
    clash = sorted(set(channels) & set(known))
    if clash:
        raise HydrotactError(f"{source}: channels: {clash[0]!r} is a reserved column name")
    for name in ["time", *channels]:
        if name not in log.columns:
            raise HydrotactError(f"{source}: missing column {name!r} (has {', '.join(log.columns)})")
    allowed = set(known) | set(channels)
    extra = sorted(set(log.columns) - allowed)
    if extra:
        raise HydrotactError(f"{source}: unknown column {extra[0]!r}; the known ones are {', '.join(known)} and the channels")
    length = len(log.columns["time"])
    for name, values in log.columns.items():
        values = np.asarray(values)
        if values.ndim != 1 or len(values) != length:
            raise HydrotactError(f"{source}: column {name!r} has {values.shape} values, expected {length}")
        if not (np.issubdtype(values.dtype, np.integer) or np.issubdtype(values.dtype, np.floating) or values.dtype == bool):
            raise HydrotactError(f"{source}: column {log.describe_column(name)} is not numeric ({values.dtype})")
        _check_values(log, name, values, source, known)
    times = np.asarray(log.columns["time"], dtype=np.float64)
    steps = np.diff(times)
    if np.any(steps <= 0.0):
        row = int(np.flatnonzero(steps <= 0.0)[0]) + 1
        kind = "repeats" if steps[row - 1] == 0.0 else "goes back"
        raise HydrotactError(f"{source}: column {log.describe_column('time')}, row {row + 1}: time {kind} ({times[row]:g} s after {times[row - 1]:g} s in row {row})")
    spec = sensor_spec(log.metadata["sensor"], source)
    if spec is not None and spec.num_taxels != len(channels):
        raise HydrotactError(f"{source}: channels: {len(channels)} channel columns, but sensor {log.metadata['sensor']!r} has {spec.num_taxels} taxels")
    _check_pressures(log, source, spec)
    _check_time_unit(log, source, spec)
    if warn:
        _warn_sampling(log, source)


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise HydrotactError(f"{path}: a log is a Parquet or CSV file; name it *.parquet or *.csv")
    return suffix


def metadata_path(path) -> Path:
    """The metadata document beside a CSV log: `NAME.json` for `NAME.csv`."""
    return Path(path).with_suffix(".json")


def write_log(path, log: BarometerLog) -> Path:
    """Check `log` and write it, atomically: Parquet (metadata inside) for `*.parquet`,
    or for `*.csv` the table with a header of the column names and the metadata as
    `NAME.json` beside it. An interrupted or refused write leaves old files as they were.

    **Arguments:**

    - `path`: the file to write, `*.parquet` or `*.csv`.
    - `log`: the :class:`BarometerLog` (checked first, without sampling warnings).

    **Returns:** `path`.
    """
    import pyarrow as pa
    import pyarrow.csv as pa_csv
    import pyarrow.parquet as pq

    path = Path(path)
    suffix = _suffix(path)
    check_log(log, str(path), warn=False)
    table = pa.table({name: np.asarray(values) for name, values in log.columns.items()})
    if suffix == ".parquet":
        table = table.replace_schema_metadata({METADATA_KEY: json.dumps(log.metadata).encode()})
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp)
        return path
    with atomic_path(metadata_path(path)) as tmp_metadata, atomic_path(path) as tmp:
        tmp_metadata.write_text(json.dumps(log.metadata, indent=2) + "\n", encoding="utf-8")
        with open(tmp, "wb") as handle:  # the header unquoted: column names are identifiers
            handle.write((",".join(table.column_names) + "\n").encode())
            pa_csv.write_csv(table, handle, pa_csv.WriteOptions(include_header=False, quoting_style="none"))
    return path


def _to_numpy(column, name: str, source: str) -> np.ndarray:
    """A pyarrow column as a NumPy array: nulls (blank cells) become NaN; a text
    column is an error naming the first cell that is no number."""
    import pyarrow as pa

    if pa.types.is_null(column.type):
        return np.full(len(column), np.nan)
    if pa.types.is_string(column.type) or pa.types.is_large_string(column.type):
        for row, text in enumerate(column.to_pylist()):
            if text is None:
                continue
            try:
                float(text)
            except ValueError:
                comma = " (a decimal comma? write 0.5, not 0,5)" if re.fullmatch(r"\s*[-+]?\d+,\d+\s*", text) else ""
                raise HydrotactError(f"{source}: column {name!r}, row {row + 1}: {text.strip()!r} is not a number{comma}") from None
        return np.array([np.nan if text is None else float(text) for text in column.to_pylist()])
    if column.null_count and (pa.types.is_integer(column.type) or pa.types.is_boolean(column.type)):
        column = column.cast(pa.float64())
    return column.to_numpy(zero_copy_only=False)


def _check_delimiter(path: Path, source: str, delimiter: str, skip_rows: int) -> None:
    """Refuse a CSV whose header holds no `delimiter` but another separator (';' as
    spreadsheets in decimal-comma locales write, a tab, '|'), naming it."""
    try:
        with path.open("r", encoding="utf-8-sig", errors="strict") as handle:
            for _ in range(skip_rows):
                handle.readline()
            header = handle.readline()
    except UnicodeDecodeError:
        raise HydrotactError(f"{source}: not a CSV text file (it is not UTF-8 text; a binary file?)") from None
    if delimiter in header:
        return
    for mark in (";", "\t", "|", ","):
        if mark != delimiter and mark in header:
            comma = " (with decimal commas, too: write 0.5, not 0,5)" if mark == ";" else ""
            raise HydrotactError(
                f"{source}: the header {header.strip()[:40]!r} has no {delimiter!r}: the file separates fields by {mark!r}{comma}; "
                "export it comma-separated, or give a column mapping whose csv.delimiter says so"
            )


def read_table(path, source: str | None = None, *, delimiter: str = ",", skip_rows: int = 0) -> dict:
    """The columns of a CSV or Parquet file as NumPy arrays (name -> array), read with
    pyarrow; blank cells are NaN. A CSV needs a header row; names are stripped of
    surrounding blanks. Errors name the file and the line or column."""
    import pyarrow as pa
    import pyarrow.csv as pa_csv
    import pyarrow.parquet as pq

    path = Path(path)
    source = source or str(path)
    if not path.is_file():
        raise HydrotactError(f"{source}: no such log file")
    if _suffix(path) == ".parquet":
        try:
            table = pq.read_table(path)
        except (pa.ArrowException, OSError) as error:
            raise HydrotactError(f"{source}: not a readable Parquet file ({str(error).splitlines()[0]})") from None
    else:
        _check_delimiter(path, source, delimiter, skip_rows)
        invalid = []

        def on_invalid(row):
            invalid.append(row)
            return "skip"

        try:
            table = pa_csv.read_csv(
                path,
                read_options=pa_csv.ReadOptions(use_threads=False, skip_rows=skip_rows),
                parse_options=pa_csv.ParseOptions(delimiter=delimiter, invalid_row_handler=on_invalid),
            )
        except (pa.ArrowException, OSError) as error:
            message = str(error).splitlines()[0].replace("CSV parse error: ", "")
            raise HydrotactError(f"{source}: not a readable CSV file ({message})") from None
        if invalid:
            row = invalid[0]
            line = f"line {row.number}: " if row.number is not None else ""
            raise HydrotactError(f"{source}: {line}{row.actual_columns} fields, expected {row.expected_columns} ({row.text[:40]!r})")
        table = table.rename_columns([name.strip() for name in table.column_names])
    names = table.column_names
    for index, name in enumerate(names):
        if name in names[:index]:
            raise HydrotactError(f"{source}: column {name!r} appears twice in the header")
    return {name: _to_numpy(table.column(name), name, source) for name in names}


def read_log(path, mapping=None, *, sensor: str | None = None, require_sensor: bool = True) -> BarometerLog:
    """Read and check a barometer log.

    Without `mapping`, the file is a hydrotact log: Parquet with its metadata inside,
    or a CSV whose header holds our column names with the metadata document `NAME.json`
    beside it. With `mapping` (a column-mapping file or :class:`ColumnMapping`), the
    file, CSV or Parquet, is of the user's own layout: the mapping picks and converts
    its columns to SI. The log is then checked (:func:`check_log`): every problem is one
    :class:`HydrotactError` naming the file, the column and the row (rows count samples
    from 1; a CSV's header and blank lines are not counted, a parse error names the
    file's line instead); uneven sampling is a :class:`LogWarning`.

    **Arguments:**

    - `path`: `*.parquet` or `*.csv`.
    - `mapping`: a column mapping for a file of the user's own layout, or None.
    - `sensor`: the sensor spec (built-in name or JSON path); with a mapping it
      overrides the mapping's `sensor`; without one it must agree with the log's.
    - `require_sensor`: with a mapping, refuse a log whose sensor neither the mapping
      nor `sensor` names (False: label it `unnamed`, for a lumped fit).

    **Returns:** the :class:`BarometerLog`, SI units.
    """

    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise HydrotactError(f"{source}: no such log file")
    suffix = _suffix(path)
    if mapping is not None:
        mapping = mapping if isinstance(mapping, ColumnMapping) else load_mapping(mapping)
        columns = read_table(path, source, **mapping.csv_options) if suffix == ".csv" else read_table(path, source)
        log = apply_mapping(columns, mapping, source, sensor=sensor, require_sensor=require_sensor)
    elif suffix == ".csv":
        beside = metadata_path(path)
        if not beside.is_file():
            raise HydrotactError(
                f"{source}: no metadata document {beside.name} beside it; a CSV of your own layout needs a column mapping (--mapping MAPPING.json)"
            )
        metadata = read_json(beside)
        validate(metadata, "barometer_log", str(beside))
        log = BarometerLog(metadata=metadata, columns=read_table(path, source))
    else:
        log = _read_parquet_log(path, source)
    if mapping is None and sensor is not None and str(sensor) != log.metadata.get("sensor"):
        raise HydrotactError(f"{source}: sensor: the log is from {log.metadata.get('sensor')!r}, not {str(sensor)!r}")
    check_log(log, source)
    return log


def _read_parquet_log(path: Path, source: str) -> BarometerLog:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as error:
        raise HydrotactError(f"{source}: not a readable Parquet file ({str(error).splitlines()[0]})") from None
    raw = (table.schema.metadata or {}).get(METADATA_KEY)
    if raw is None:
        raise HydrotactError(f"{source}: no hydrotact metadata (key 'hydrotact'); was it written by hydrotact? For your own layout pass a column mapping (--mapping MAPPING.json)")
    metadata = parse_json(raw.decode("utf-8", errors="replace"), f"{source}: metadata")
    columns = {name: table.column(name).to_numpy(zero_copy_only=False) for name in table.column_names}
    return BarometerLog(metadata=metadata, columns=columns)
