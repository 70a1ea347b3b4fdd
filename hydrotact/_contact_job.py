"""Probe and length specs as the command line writes them (`cylinder:d=2mm`, `0.4mm`).

The contact job itself is `hydrotact.contact.press_probe`."""

import re

from ._errors import HydrotactError
from .contact import HalfSpace, make_cylinder_probe, make_sphere_probe

_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(m|mm|um|cm)?\s*$")
_SCALE = {None: 1.0, "m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6}


def parse_length(text: str, what: str) -> float:
    """'2mm' -> 0.002; a bare number is metres."""
    match = _LENGTH.match(text)
    if not match:
        raise HydrotactError(f"{what}: cannot read {text!r} as a length (e.g. 2mm, 0.5e-3)")
    return float(match.group(1)) * _SCALE[match.group(2)]


def parse_probe(spec: str):
    """'cylinder:d=2mm[,length=10mm]', 'sphere:r=3mm' or 'plane' -> a rigid body."""
    kind, _, rest = spec.partition(":")
    options = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        options[key.strip()] = parse_length(value, f"--probe {key.strip()}")
    if kind == "plane" and not options:
        return HalfSpace()
    if kind == "cylinder" and set(options) <= {"d", "length"} and "d" in options:
        return make_cylinder_probe(options["d"], options.get("length"))
    if kind == "sphere" and set(options) == {"r"}:
        return make_sphere_probe(options["r"])
    raise HydrotactError(f"--probe: unknown probe {spec!r}; use cylinder:d=2mm, sphere:r=3mm or plane")
