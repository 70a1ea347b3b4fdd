"""Logs and datasets: barometer log I/O (Parquet, CSV, users' layouts through a column
mapping) with validation, tare calibration, and material documents."""

from ._log import (
    BarometerLog as BarometerLog,
    LogWarning as LogWarning,
    check_log as check_log,
    known_columns as known_columns,
    read_log as read_log,
    read_table as read_table,
    write_log as write_log,
)
from ._mapping import (
    UNITS as UNITS,
    ColumnMapping as ColumnMapping,
    apply_mapping as apply_mapping,
    check_mapping as check_mapping,
    load_mapping as load_mapping,
)
from ._material import (
    check_material as check_material,
    make_material_document as make_material_document,
    material_prony as material_prony,
    parameter_names as parameter_names,
    read_material as read_material,
    write_material as write_material,
)
from ._rig import Rig as Rig, RigParameter as RigParameter, read_rig as read_rig
from ._table import (
    sensor_spec as sensor_spec,
)
from ._tare import (
    estimate_noise as estimate_noise,
    find_no_load_segments as find_no_load_segments,
    interpolate_baseline as interpolate_baseline,
    tare_log as tare_log,
)
