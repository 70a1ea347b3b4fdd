"""Sensor specs: built-in sensors and users' own, read from JSON validated against
data_schemas/sensor.schema.json and converted to SI units."""

from ._builtins import BUILTIN_SENSORS as BUILTIN_SENSORS
from ._spec import (
    Geometry as Geometry,
)
from ._spec import (
    Part as Part,
)
from ._spec import (
    SensorSpec as SensorSpec,
)
from ._spec import (
    calc_sensor_surface as calc_sensor_surface,
)
from ._spec import (
    document_text as document_text,
)
from ._spec import (
    known_parts as known_parts,
)
from ._spec import (
    load_sensor as load_sensor,
)
