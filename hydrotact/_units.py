"""Units: the one table of units the package reads, and '2mm'-style lengths.

Everything is SI inside the package (s, m, Pa, rad, N, N m); files, column mappings
and command lines may give a quantity in any unit of its kind in :data:`UNITS`.
"""

import math
import re

from ._errors import HydrotactError

UNITS = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0},
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6},
    "pressure": {"Pa": 1.0, "hPa": 100.0, "kPa": 1e3, "mbar": 100.0, "bar": 1e5, "psi": 6894.757293168361},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0},
    "force": {"N": 1.0, "mN": 1e-3},
    "torque": {"N m": 1.0, "N mm": 1e-3},
    "dimensionless": {"1": 1.0},
}
"""Per quantity kind: unit name -> its size in the SI unit of that kind."""

SI_UNITS = {"s": "time", "m": "length", "Pa": "pressure", "rad": "angle", "N": "force", "N m": "torque", "1": "dimensionless"}
"""The SI unit of each kind -> the kind (the units of barometer_log's $defs/columns)."""

LENGTH_UNITS = UNITS["length"]
"""Each length unit's size in metres."""

_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(" + "|".join(LENGTH_UNITS) + r")?\s*$")


def parse_length(text: str, what: str) -> float:
    """A length in metres from text such as '2mm', '0.5 um' or '3e-3' (a bare number
    is metres; units from :data:`LENGTH_UNITS`).

    **Arguments:**

    - `text`: the number, optionally followed by a unit.
    - `what`: where the text came from (an option or field), to start the error.

    **Returns:** the length in metres (the number times the unit's size).

    **Raises:** :class:`HydrotactError` naming `what` and `text` when it is not a length.
    """
    match = _LENGTH.match(text)
    if not match:
        raise HydrotactError(f"{what}: cannot read {text!r} as a length (e.g. 2mm, 0.5e-3)")
    return float(match.group(1)) * LENGTH_UNITS[match.group(2) or "m"]


def format_length(value: float) -> str:
    """The shortest text that :func:`parse_length` reads back as exactly `value` (m):
    '2mm' for 0.002, '1.5um', or the bare number of metres."""
    best = repr(float(value))
    for unit, scale in LENGTH_UNITS.items():
        text = f"{value / scale:.15g}{unit}"
        if float(text[: -len(unit)]) * scale == value and len(text) < len(best):
            best = text
    return best
