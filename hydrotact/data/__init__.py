"""Logs and datasets: barometer log I/O (Parquet, CSV, users' layouts through a column
mapping) with validation, tare calibration, and material documents."""

from ._log import (
    BarometerLog as BarometerLog,
)
from ._log import (
    LogWarning as LogWarning,
)
from ._log import (
    check_log as check_log,
)
from ._log import (
    known_columns as known_columns,
)
from ._log import (
    read_log as read_log,
)
from ._log import (
    read_table as read_table,
)
from ._log import (
    write_log as write_log,
)
from ._mapping import (
    UNITS as UNITS,
)
from ._mapping import (
    ColumnMapping as ColumnMapping,
)
from ._mapping import (
    apply_mapping as apply_mapping,
)
from ._mapping import (
    check_mapping as check_mapping,
)
from ._mapping import (
    load_mapping as load_mapping,
)
from ._material import (
    check_material as check_material,
)
from ._material import (
    make_material_document as make_material_document,
)
from ._material import (
    material_prony as material_prony,
)
from ._material import (
    parameter_names as parameter_names,
)
from ._material import (
    read_material as read_material,
)
from ._material import (
    write_material as write_material,
)
from ._table import (
    sensor_spec as sensor_spec,
)
from ._tare import (
    estimate_noise as estimate_noise,
)
from ._tare import (
    find_no_load_segments as find_no_load_segments,
)
from ._tare import (
    interpolate_baseline as interpolate_baseline,
)
from ._tare import (
    tare_log as tare_log,
)
