"""Column mappings: how a table of the user's own layout becomes a barometer log in SI.

A mapping (`data_schemas/column_mapping.schema.json`) names the file's time column,
its barometer channels and any probe, force or label columns, each with the unit it
is declared in. The unit must be of the kind the log column needs, which is read off
the column's SI unit in `barometer_log.schema.json` `$defs/columns` (channels are
pressures). Every value is converted on reading: SI = (raw + offset) x factor x scale.
"""

import re
from dataclasses import dataclass, field

import numpy as np

from .._errors import HydrotactError
from .._schemas import format_path, read_json, validate
from .._units import SI_UNITS, UNITS
from ._table import BarometerLog, known_columns, sensor_spec

STEP = "step"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class ColumnMapping:
    """A validated mapping: `document` (the JSON) and `source` (the file it came
    from, for messages)."""

    document: dict
    source: str = "column mapping"
    csv_options: dict = field(default_factory=dict)


def unit_kind(unit: str) -> str | None:
    """The quantity kind of a unit ('mm' -> 'length'), or None for an unknown unit."""
    for kind, units in UNITS.items():
        if unit in units:
            return kind
    return None


def _known_columns() -> dict:

    return known_columns()


def _factor(entry: dict, kind: str, source: str, path: list) -> float:
    """The factor from `entry`'s declared unit to SI, or an error naming the field."""
    unit, scale = entry["unit"], entry.get("scale")
    allowed = ", ".join(UNITS[kind])
    if unit == STEP:
        if scale is None:
            raise HydrotactError(f"{source}: {format_path([*path, 'scale'])}: the unit 'step' needs a scale (the SI amount of one step)")
        return float(scale)
    declared = unit_kind(unit)
    if declared is None:
        raise HydrotactError(f"{source}: {format_path([*path, 'unit'])}: unknown unit {unit!r}; a {kind} column takes {allowed} (or 'step' with a scale)")
    if declared != kind:
        raise HydrotactError(f"{source}: {format_path([*path, 'unit'])}: {unit!r} is a {declared} unit; a {kind} column takes {allowed}")
    return UNITS[kind][unit] * (1.0 if scale is None else float(scale))


def _entries(document: dict, source: str):
    """(log name or None, path in the document, entry, kind) for every mapped column;
    a `columns` key that is no log column is an error naming `source`."""
    known = _known_columns()
    yield "time", ["time"], document["time"], "time"
    channels = document["channels"]
    if isinstance(channels, list):
        for index, entry in enumerate(channels):
            yield entry.get("name"), ["channels", index], entry, "pressure"
    else:
        names = channels.get("names")
        for index, column in enumerate(channels["columns"]):
            entry = {key: value for key, value in channels.items() if key not in ("columns", "names")}
            entry["column"] = column
            yield (names[index] if names else None), ["channels"], entry, "pressure"
    for name, entry in document.get("columns", {}).items():
        if name == "time":
            raise HydrotactError(f"{source}: columns.time: the time column is mapped by the 'time' field")
        if name not in known:
            others = ", ".join(column for column in known if column != "time")
            raise HydrotactError(f"{source}: {format_path(['columns', name])}: not a log column; the known ones are {others}")
        yield name, ["columns", name], entry, SI_UNITS[known[name]["unit"]]


def check_mapping(document, source: str = "column mapping") -> ColumnMapping:
    """Validate a mapping document (schema, then units and names) and return it as a
    :class:`ColumnMapping`; one :class:`HydrotactError` naming `source` and the field."""
    validate(document, "column_mapping", source)
    channels = document["channels"]
    if isinstance(channels, dict) and "names" in channels and len(channels["names"]) != len(channels["columns"]):
        raise HydrotactError(f"{source}: channels.names: {len(channels['names'])} names for {len(channels['columns'])} columns")
    names = []
    for name, path, entry, kind in _entries(document, source):
        _factor(entry, kind, source, path)
        if kind == "pressure" and name is not None:
            if name in _known_columns():
                raise HydrotactError(f"{source}: {format_path([*path, 'name'])}: {name!r} is a reserved column name")
            if name in names:
                raise HydrotactError(f"{source}: {format_path([*path, 'name'])}: channel {name!r} is named twice")
            names.append(name)
    csv_options = dict(document.get("csv", {}))
    return ColumnMapping(document=document, source=source, csv_options=csv_options)


def load_mapping(path) -> ColumnMapping:
    """Read and check the column mapping JSON file at `path`.

    **Arguments:**

    - `path`: the mapping file (data_schemas/column_mapping.schema.json).

    **Returns:** a :class:`ColumnMapping`. A malformed file, a field the schema refuses,
    an unknown unit or a unit of the wrong kind (a length unit for a pressure channel)
    is one :class:`HydrotactError` naming the file and the field.
    """
    return check_mapping(read_json(path), str(path))


def sanitise_name(column: str) -> str:
    """A file's column name made into a channel name: characters outside [A-Za-z0-9_]
    become `_`, and a leading digit gets a `_` before it ('Sensor 0' -> 'Sensor_0')."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", column.strip())
    if not name or not _NAME.match(name):
        name = f"_{name}"
    return name


def _channel_names(mapping: ColumnMapping, columns: list[str], taxel_names, source: str) -> list[str]:
    """Channel names: those the mapping gives, else the sensor's taxel names when the
    count matches, else the file's column names as identifiers."""
    given = [name for name, _, _, kind in _entries(mapping.document, mapping.source) if kind == "pressure"]
    if all(name is not None for name in given):
        return given
    if taxel_names is not None and len(taxel_names) == len(columns):
        return [name if name is not None else taxel for name, taxel in zip(given, taxel_names, strict=True)]
    names = [name if name is not None else sanitise_name(column) for name, column in zip(given, columns, strict=True)]
    reserved = set(_known_columns())
    names = [f"channel_{name}" if name in reserved else name for name in names]
    for index, name in enumerate(names):
        if name in names[:index]:
            raise HydrotactError(f"{source}: channels: the columns {columns[names.index(name)]!r} and {columns[index]!r} both become channel {name!r}; name them in the mapping")
    return names


def apply_mapping(table_columns: dict, mapping, source: str, *, sensor: str | None = None, require_sensor: bool = True):
    """Make a barometer log in SI from the columns of a user's table.

    Every mapped column is converted, SI = (raw + offset) x unit factor x scale, and
    renamed to its log name; unmapped columns are dropped. The log remembers which
    file column each of its columns came from, so later errors name the user's column.

    **Arguments:**

    - `table_columns`: the file's columns, name -> 1-D array (as read).
    - `mapping`: a :class:`ColumnMapping` (or a mapping document, checked here).
    - `source`: the data file's name, for messages.
    - `sensor`: the sensor spec (built-in name or JSON path); overrides the mapping's.
    - `require_sensor`: refuse a log whose sensor neither names; without, such a log
      is labelled `unnamed` (a lumped fit needs no model of the sensor).

    **Returns:** a :class:`BarometerLog` (not yet checked: :func:`check_log` does that).
    """

    if not isinstance(mapping, ColumnMapping):
        mapping = check_mapping(mapping)
    document = mapping.document
    sensor = sensor or document.get("sensor") or (None if require_sensor else "unnamed")
    if sensor is None:
        raise HydrotactError(f"{source}: which sensor is this log from? Give one in the mapping ({mapping.source}: sensor) or pass --sensor")
    spec = sensor_spec(sensor, source)
    channel_columns = []
    converted, origins = {}, {}
    for name, path, entry, kind in _entries(document, mapping.source):
        column = entry["column"]
        if column not in table_columns:
            raise HydrotactError(
                f"{source}: missing column {column!r} (named by {mapping.source}: {format_path([*path, 'column'])}); the file has {', '.join(table_columns)}"
            )
        raw = np.asarray(table_columns[column])
        if not (np.issubdtype(raw.dtype, np.number) or raw.dtype == bool) or np.issubdtype(raw.dtype, np.complexfloating):
            raise HydrotactError(f"{source}: column {column!r} is not numeric ({raw.dtype})")
        factor = _factor(entry, kind, mapping.source, path)
        offset = entry.get("offset", 0.0)
        # A column needing no conversion keeps its type (an int8 contact flag stays one).
        values = raw if factor == 1.0 and offset == 0.0 else (raw.astype(np.float64) + offset) * factor
        if kind == "pressure":
            channel_columns.append((column, values))
        else:
            converted[name] = values
            origins[name] = column
    names = _channel_names(mapping, [column for column, _ in channel_columns], spec.taxel_names if spec else None, source)
    columns = {"time": converted.pop("time")}
    for name, (column, values) in zip(names, channel_columns, strict=True):
        columns[name] = values
        origins[name] = column
    columns.update(converted)
    metadata = {
        "format": "hydrotact.barometer_log",
        "version": 1,
        "sensor": str(sensor),
        "source": document.get("source", "recorded"),
        "pressure": document["pressure"],
        "channels": names,
    }
    for key in ("rate_hz", "probe"):
        if key in document:
            metadata[key] = document[key]
    return BarometerLog(metadata=metadata, columns=columns, source_columns=origins)
