"""Argument types and flags shared by several commands."""

import argparse

from .._defaults import DEFAULT_MODULUS
from .._units import LENGTH_UNITS

MODULUS_HELP = f"hydroelastic modulus in Pa (default {DEFAULT_MODULUS:.0e})".replace("e+0", "e")
"""Help of every --modulus flag (its default is hydrotact.field.DEFAULT_MODULUS)."""


def number(text: str) -> float:
    """An argparse type: a float, or a one-line usage error."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def number_pair(text: str) -> tuple[float, float]:
    """An argparse type: LOW,HIGH, two floats, or a one-line usage error."""
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH (two numbers), got {text!r}") from None


def add_source_arguments(parser: argparse.ArgumentParser, what: str, optional: bool = False) -> None:
    """The sensor-or-file argument and its meshing flags (mesh, field)."""
    parser.add_argument("source", metavar=what, nargs="?" if optional else None, help="a built-in sensor (pad5x5, sphere8, ellipsoid8) or a file")
    parser.add_argument("--edge-length", type=number, metavar="L", help="target tet edge length in --units (sensors, surfaces; default: the sensor's own, a surface's size / 20)")
    parser.add_argument("--units", default="m", choices=list(LENGTH_UNITS), help="length unit of a surface file's coordinates, --edge-length and --core-plane (default m)")
    parser.add_argument("--core-plane", type=number, metavar="Z", help="the core (bonded) faces lie on the plane z = Z, in --units (default: the lowest z)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
