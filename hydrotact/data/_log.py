"""Barometer logs: a table of samples (time, one column per barometer, optional probe,
wrench and label columns) with a metadata document, in Parquet.

The contract is `data_schemas/barometer_log.schema.json`: the metadata is validated
against it and stored in the Parquet file's key-value metadata under `hydrotact`; the
known optional columns and their units are listed in its `$defs/columns`. Every number
is SI. Reading checks what a fit would trip over and names the file, column and row:
missing columns, non-finite values, times that do not strictly increase.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._errors import HydrotactError
from .._files import atomic_path
from .._schemas import load_schema, parse_json, validate

METADATA_KEY = b"hydrotact"


def known_columns() -> dict:
    """The optional columns a log may carry: name -> {unit, description, ...}."""
    return load_schema("barometer_log")["$defs"]["columns"]["default"]


@dataclass(frozen=True)
class BarometerLog:
    """A log in memory: `metadata` (the schema's document) and `columns` (name ->
    1-D NumPy array, all of one length), SI units."""

    metadata: dict
    columns: dict

    @property
    def times(self) -> np.ndarray:
        return self.columns["time"]

    @property
    def channels(self) -> np.ndarray:
        """(num_samples, num_channels) barometer columns in channel order."""
        return np.column_stack([self.columns[name] for name in self.metadata["channels"]])

    @property
    def num_samples(self) -> int:
        return len(self.columns["time"])


def check_log(log: BarometerLog, source: str) -> None:
    """Validate metadata and columns; one HydrotactError naming file, column and row."""
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
            raise HydrotactError(f"{source}: column {name!r} is not numeric ({values.dtype})")
        bad = ~np.isfinite(values.astype(np.float64))
        if known.get(name, {}).get("nan_allowed"):
            bad &= ~np.isnan(values.astype(np.float64))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise HydrotactError(f"{source}: column {name!r}, row {row + 1}: {values[row]} is not a finite number")
    steps = np.diff(np.asarray(log.columns["time"], dtype=np.float64))
    if np.any(steps <= 0.0):
        row = int(np.flatnonzero(steps <= 0.0)[0]) + 1
        kind = "repeats" if steps[row - 1] == 0.0 else "goes back"
        raise HydrotactError(f"{source}: column 'time', row {row + 1}: time {kind} ({log.columns['time'][row]:g} s after {log.columns['time'][row - 1]:g} s)")


def write_log(path, log: BarometerLog) -> Path:
    """Check `log` and write it as Parquet, atomically (an interrupted write leaves
    any old file as it was)."""
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    check_log(log, str(path))
    table = pa.table({name: np.asarray(values) for name, values in log.columns.items()})
    table = table.replace_schema_metadata({METADATA_KEY: json.dumps(log.metadata).encode()})
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return path


def read_log(path) -> BarometerLog:
    """Read and check a Parquet log written by hydrotact (or to its schema)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise HydrotactError(f"{source}: no such log file")
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as error:
        raise HydrotactError(f"{source}: not a readable Parquet file ({str(error).splitlines()[0]})") from None
    raw = (table.schema.metadata or {}).get(METADATA_KEY)
    if raw is None:
        raise HydrotactError(f"{source}: no hydrotact metadata (key 'hydrotact'); was it written by hydrotact?")
    metadata = parse_json(raw.decode("utf-8", errors="replace"), f"{source}: metadata")
    columns = {name: table.column(name).to_numpy(zero_copy_only=False) for name in table.column_names}
    log = BarometerLog(metadata=metadata, columns=columns)
    check_log(log, source)
    return log
