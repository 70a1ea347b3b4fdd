"""A barometer log in memory, the columns a log may carry, and the sensor a log names:
what both the log reader (`_log.py`) and the column mappings (`_mapping.py`) build on."""

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._errors import HydrotactError
from .._schemas import load_schema


def known_columns() -> dict:
    """The optional columns a log may carry: name -> {unit, description, ...}."""
    return load_schema("barometer_log")["$defs"]["columns"]["default"]


@dataclass(frozen=True)
class BarometerLog:
    """A log in memory: `metadata` (the schema's document) and `columns` (name ->
    1-D NumPy array, all of one length), SI units. `source_columns` says, for a log
    read through a column mapping, which column of the user's file each log column
    came from (messages name that column too)."""

    metadata: dict
    columns: dict
    source_columns: dict = field(default_factory=dict, compare=False)

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

    def describe_column(self, name: str) -> str:
        """`'b00'`, or `'b00' (file column 'Sensor_0')` for a mapped log."""
        origin = self.source_columns.get(name)
        return f"{name!r}" if origin is None or origin == name else f"{name!r} (file column {origin!r})"


@functools.cache
def _cached_spec(sensor: str, modified: float | None):
    from ..sensors import load_sensor

    return load_sensor(sensor)


def sensor_spec(sensor: str, source: str | None = None):
    """The sensor spec a log's `sensor` names (a built-in name or an existing sensor
    JSON file), or None when it names neither (a log may come from elsewhere)."""
    from ..sensors import BUILTIN_SENSORS

    if sensor in BUILTIN_SENSORS:
        return _cached_spec(sensor, None)
    path = Path(sensor)
    if not path.is_file():
        return None
    try:
        return _cached_spec(str(path), path.stat().st_mtime)
    except HydrotactError as error:
        raise HydrotactError(f"{source}: sensor: {error}") from None
