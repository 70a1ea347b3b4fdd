"""The built-in sensor specs, written out as the JSON files in `data/`.

The JSON files are the source the loader reads; this module is how they were made
(``python -m hydrotact.sensors._builtins --regenerate``), and the test suite checks
that the two agree. Lengths in mm and angles in degrees, as a user would write them.
"""

import json
import math
import re
import sys
from importlib.resources import files

from .._files import write_text_atomic

BUILTIN_SENSORS = ("pad5x5", "sphere8", "ellipsoid8", "sphere8-cones", "ellipsoid8-cones")
_DATA = files("hydrotact.sensors") / "data"
_NUMBERS = re.compile(r"\[\s*(-?[0-9][-0-9.e+]*(?:,\s*-?[0-9][-0-9.e+]*)*)\s*\]")


def _round(value: float) -> float:
    return round(value, 9) + 0.0  # 0.0 turns -0.0 into 0.0


def _tilted_axis(tilt_deg: float, azimuth_deg: float) -> list[float]:
    """(sin t cos az, sin t sin az, cos t): +z tilted by t outward towards azimuth az."""
    t, az = math.radians(tilt_deg), math.radians(azimuth_deg)
    return [_round(math.sin(t) * math.cos(az)), _round(math.sin(t) * math.sin(az)), _round(math.cos(t))]


def _ring(names, azimuths, rx, ry, z, tilt_deg, field):
    return [
        {
            "name": name,
            "position": [_round(rx * math.cos(math.radians(az))), _round(ry * math.sin(math.radians(az))), z],
            "axis": _tilted_axis(tilt_deg, az),
            "receptive_field": dict(field),
        }
        for name, az in zip(names, azimuths, strict=True)
    ]


def _pad5x5() -> dict:
    pitch = 2.2
    centres = [-4.4, -2.2, 0.0, 2.2, 4.4]
    taxels = [
        {
            "name": f"b{row}{col}",
            "position": [centres[col], centres[row], 0.0],
            "axis": [0.0, 0.0, 1.0],
            "receptive_field": {"kind": "disk", "radius": pitch / 2},
        }
        for row in range(5)
        for col in range(5)
    ]
    return {
        "name": "pad5x5",
        "description": (
            "The flat 5 x 5 BMP388 array of the hydroelastic tactile paper: 2.2 mm pitch (from the paper), "
            "ports on the PCB (z = 0) at the cell centres, sensing along +z. Channel b{row}{col} is at "
            "x = -4.4 mm + 2.2 mm col, y = -4.4 mm + 2.2 mm row (index 5 row + col). Our choices: the disk "
            "receptive field of radius 1.1 mm (half the pitch, so neighbouring disks touch) and the "
            "elastomer block (13.2 x 13.2 x 4 mm, hydrotact.mesh seed pad5x5)."
        ),
        "units": {"length": "mm", "angle": "deg"},
        "geometry": {"kind": "seed", "seed": "pad5x5"},
        "part": "BMP388",
        "taxels": taxels,
    }


def _curved(name, shape_text, inner, outer, centre_z, theta_range, phi_range, ranges_text, cones=False) -> dict:
    field = {"kind": "cone", "half_angle": 40.0} if cones else {"kind": "elastic"}
    taxels = [
        {"name": "b0", "position": [0.0, 0.0, inner[2]], "axis": [0.0, 0.0, 1.0], "receptive_field": dict(field)},
        *_ring(["b1", "b2", "b3", "b4"], [0, 90, 180, 270], inner[0], inner[1], inner[2], 30.0, field),
        *_ring(["b5", "b6", "b7"], [60, 180, 300], outer[0], outer[1], outer[2], 60.0, field),
    ]
    if cones:
        reading = (
            "every receptive field a cone of half-angle 40 deg (also our choice): the barometer sees the "
            f"contact pressure on the skin inside it. A heuristic kept beside {name} (which reads the "
            "elastomer's stress) to compare with and for fast runs; no sensor has confirmed it."
        )
    else:
        reading = (
            "every barometer reads the elastomer's hydrostatic pressure averaged over a 0.5 mm port "
            "(the elastic receptive field, nu 0.49; its fields ship with hydrotact). "
            f"{name}-cones is the same layout under the earlier 40 deg cones."
        )
    return {
        "name": name + ("-cones" if cones else ""),
        "description": (
            f"The {shape_text} of the barometric estimation paper with 8 BMP388 barometers. The elastomer "
            f"(hydrotact.mesh seed {name}) and the contact-angle convention and ranges ({ranges_text}) are "
            "from the paper; the paper does not give the barometer positions, so this non-planar layout is "
            f"our choice: b0 on the axis at z = {inner[2]:g} mm sensing along +z; b1..b4 on an inner ring "
            "at azimuths 0, 90, 180, 270 deg, axes tilted 30 deg outward from +z; b5..b7 on an outer ring at "
            f"z = {outer[2]:g} mm (on angled risers) at azimuths 60, 180, 300 deg, axes tilted 60 deg "
            "outward; " + reading
        ),
        "units": {"length": "mm", "angle": "deg"},
        "geometry": {"kind": "seed", "seed": name},
        "part": "BMP388",
        "contact_angles": {"center": [0.0, 0.0, centre_z], "theta_range": theta_range, "phi_range": phi_range},
        "taxels": taxels,
    }


def builtin_documents() -> dict[str, dict]:
    """The JSON documents of the built-in sensors, by name."""
    documents = {"pad5x5": _pad5x5()}
    for cones in (False, True):
        for document in _curved_documents(cones):
            documents[document["name"]] = document
    return documents


def _curved_documents(cones: bool) -> list[dict]:
    a, b = 10.7, 9.0
    return [
        _curved(
            "sphere8",
            "three-quarter silicone sphere (R = 10 mm, centre 5 mm above the PCB)",
            (3.0, 3.0, 1.0),
            (6.0, 6.0, 2.0),
            5.0,
            [-45.0, 45.0],
            [-135.0, 45.0],
            "theta in [-45, 45] deg, phi in [-135, 45] deg, measured from the sphere's centre",
            cones,
        ),
        _curved(
            "ellipsoid8",
            "silicone ellipsoid (a, b, c = 10.7, 9, 6.8 mm, centre 3.4 mm above the PCB)",
            (_round(0.33 * a), _round(0.33 * b), 0.8),
            (_round(0.6 * a), _round(0.6 * b), 1.5),
            3.4,
            [-40.0, 40.0],
            [-72.0, 72.0],
            "theta within +-40 deg, phi within +-72 deg, measured from the ellipsoid's centre",
            cones,
        ),
    ]


def builtin_text(name: str) -> str:
    """The JSON text of a built-in sensor, with each list of numbers on one line."""
    text = json.dumps(builtin_documents()[name], indent=2)
    return _NUMBERS.sub(lambda match: "[" + ", ".join(re.split(r",\s*", match.group(1))) + "]", text) + "\n"


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        sys.exit("usage: python -m hydrotact.sensors._builtins --regenerate")
    for sensor in BUILTIN_SENSORS:
        write_text_atomic(_DATA / f"{sensor}.json", builtin_text(sensor))
        print(f"wrote {_DATA / f'{sensor}.json'}")
