"""Sensor specs: built-in sensors and users' own, read from JSON validated against
data_schemas/sensor.schema.json and converted to SI units."""

from ._builtins import BUILTIN_SENSORS as BUILTIN_SENSORS
from ._spec import (
    Geometry as Geometry,
    Part as Part,
    SensorSpec as SensorSpec,
    calc_sensor_surface as calc_sensor_surface,
    document_text as document_text,
    known_parts as known_parts,
    load_sensor as load_sensor,
    with_receptive_fields as with_receptive_fields,
)
