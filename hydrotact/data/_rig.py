"""Stage rigs: how a positioning stage's logged columns become the probe's pose on a
sensor (`data_schemas/rig.schema.json`), read into SI units.

A stage log has no probe pose: it has the pressing axis' travel from its home and the
other axes' positions, in the stage's own frame. The rig says where that frame sits on
the sensor (the offsets, the height of the tip at travel 0) and how far the pressures
lag the logged travel; each of these is fixed or, within bounds, fitted
(:func:`hydrotact.sysid.fit_logs` with a rig).
"""

import dataclasses
import math
from pathlib import Path

import numpy as np

from .._errors import HydrotactError
from .._schemas import read_json, validate
from .._units import LENGTH_UNITS

DEFAULT_COLUMNS = {"travel": "indentation", "x": "stage_x", "y": "stage_y"}
MAX_SLOPE = 0.3  # |slope_x| beyond this is a stage tilted over ~17 degrees: an angle or a unit mistaken, not a rig
DEFAULT_TABLE_STEP = {"xy": 0.25e-3, "height": 0.05e-3}  # m


@dataclasses.dataclass(frozen=True)
class RigParameter:
    """A rig parameter in SI: fixed (`low` == `high` == `start`) or fitted from
    `start` within [`low`, `high`]."""

    start: float
    low: float
    high: float

    @property
    def fixed(self) -> bool:
        return self.low == self.high

    @staticmethod
    def at(value: float) -> "RigParameter":
        return RigParameter(float(value), float(value), float(value))


@dataclasses.dataclass(frozen=True)
class Rig:
    """A stage rig (SI units): the `probe` spec (pressed upright along the sensor's
    −z), the log's stage `columns` (travel, x, y), `offset_x`, `offset_y` (the
    sensor-frame position of the stage's origin), `home` (the tip's height at travel
    0 over the stage's x = 0, per log), `lag_s` (the pressures' lag behind the
    logged travel), `slope_x` (None: level; else the change of that height per metre
    of stage x, per log: the tip at home + slope_x · stage x − travel), and the
    response table's steps `xy_step`, `height_step` (m) and the deepest travel it
    covers, `max_travel` (m; None: the fitted logs' deepest)."""

    probe: str
    columns: dict
    offset_x: RigParameter
    offset_y: RigParameter
    home: RigParameter
    lag_s: RigParameter
    slope_x: RigParameter | None = None
    xy_step: float = DEFAULT_TABLE_STEP["xy"]
    height_step: float = DEFAULT_TABLE_STEP["height"]
    max_travel: float | None = None
    name: str = "rig"
    source: str = "rig"

    def stage_columns(self, log, source: str) -> tuple[np.ndarray, np.ndarray]:
        """(stage x, y (T, 2) m; travel (T,) m) of a log, or an error naming the log
        and the missing or non-finite column."""
        values = {}
        for role in ("travel", "x", "y"):
            name = self.columns[role]
            if name not in log.columns:
                if role == "y":
                    values[role] = np.zeros(log.num_samples)
                    continue
                raise HydrotactError(
                    f"{source}: the rig ({self.source}) reads the stage's {role} from column {name!r}, which the log does not have "
                    f"(columns: {', '.join(log.columns)}); name the column in the rig's `columns`, or map it with --mapping"
                )
            column = np.asarray(log.columns[name], dtype=np.float64)
            bad = np.flatnonzero(~np.isfinite(column))
            if bad.size:
                raise HydrotactError(f"{source}: row {bad[0] + 1}: {name} is not a finite number; the rig needs the stage's position at every sample")
            values[role] = column
        return np.column_stack([values["x"], values["y"]]), values["travel"]


def _parameter(document: dict, key: str, scale: float, source: str, default: float | None = None) -> RigParameter:
    entry = document.get(key)
    if entry is None:
        return RigParameter.at(default)
    if "value" in entry:
        return RigParameter.at(scale * entry["value"])
    start, low, high = (scale * entry[k] for k in ("start", "min", "max"))
    if not low < high:
        raise HydrotactError(f"{source}: {key}: min ({entry['min']:g}) must be below max ({entry['max']:g}); give a `value` to fix it")
    if not low <= start <= high:
        raise HydrotactError(f"{source}: {key}: start {entry['start']:g} lies outside [{entry['min']:g}, {entry['max']:g}]")
    return RigParameter(start, low, high)


def read_rig(path) -> Rig:
    """Read and check a rig file (`data_schemas/rig.schema.json`) into SI units; one
    error line naming the file and the field."""
    from ..contact import parse_probe

    source = str(path)
    document = read_json(Path(path), source)
    validate(document, "rig", source)
    scale = LENGTH_UNITS[document["units"]["length"]]
    try:
        parse_probe(document["probe"])
    except HydrotactError as error:
        raise HydrotactError(f"{source}: probe: {str(error).removeprefix('--probe').lstrip(': ')}") from None
    lag = _parameter(document, "lag_s", 1.0, source, default=0.0)
    if lag.low < 0.0:
        raise HydrotactError(f"{source}: lag_s: {lag.low:g} s is negative; the pressures lag the logged travel, they cannot lead it")
    steps = {key: scale * value for key, value in document.get("table_step", {}).items()}
    rig = Rig(
        probe=document["probe"],
        columns={**DEFAULT_COLUMNS, **document.get("columns", {})},
        offset_x=_parameter(document, "offset_x", scale, source, default=0.0),
        offset_y=_parameter(document, "offset_y", scale, source, default=0.0),
        home=_parameter(document, "home", scale, source),
        lag_s=lag,
        slope_x=_parameter(document, "slope_x", 1.0, source) if "slope_x" in document else None,
        xy_step=steps.get("xy", DEFAULT_TABLE_STEP["xy"]),
        height_step=steps.get("height", DEFAULT_TABLE_STEP["height"]),
        max_travel=scale * document["max_travel"] if "max_travel" in document else None,
        name=document.get("name", Path(path).stem),
        source=source,
    )
    if rig.slope_x is not None and max(abs(rig.slope_x.low), abs(rig.slope_x.high)) > MAX_SLOPE:
        raise HydrotactError(f"{source}: slope_x: {max(abs(rig.slope_x.low), abs(rig.slope_x.high)):g} is steeper than {MAX_SLOPE:g} (a stage tilted over ~17 degrees): "
                             "slope_x is the change of the tip's height per unit of stage x, not an angle")
    for key, step in (("table_step.xy", rig.xy_step), ("table_step.height", rig.height_step)):
        if not 1e-6 <= step <= 5e-3 or not math.isfinite(step):
            raise HydrotactError(f"{source}: {key}: {step * 1e3:g} mm is not a table step (1 um to 5 mm)")
    return rig
