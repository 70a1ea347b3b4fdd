"""Units: the one table of length units the package reads, and '2mm'-style lengths.

Lengths are SI metres inside the package; files and command lines may give them in
any unit of :data:`LENGTH_UNITS` (each unit's size in metres).
"""

import re

from ._errors import HydrotactError

LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6}
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
