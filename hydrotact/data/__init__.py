"""Logs and datasets: barometer log I/O with validation."""

from ._log import (
    BarometerLog as BarometerLog,
    check_log as check_log,
    known_columns as known_columns,
    read_log as read_log,
    write_log as write_log,
)
