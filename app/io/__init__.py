"""File input and output: Universal File Format (UFF) FRF and time-data files.

Public API (see :mod:`app.io.uff`): :func:`read_frf_uff`, :func:`read_frf_measurement_uff`,
:func:`write_frf_uff`,
:func:`read_time_uff`, :func:`write_time_uff`, :class:`TimeRun`, :func:`read_units`,
:class:`UnitFactors`, :func:`read_geometry`, :func:`read_geometry_uff`.
"""

from app.io.uff import (
    TimeRun,
    UnitFactors,
    read_frf_measurement_uff,
    read_frf_uff,
    read_geometry,
    read_geometry_uff,
    read_time_uff,
    read_units,
    write_frf_uff,
    write_time_uff,
)

__all__ = [
    "TimeRun",
    "UnitFactors",
    "read_frf_measurement_uff",
    "read_frf_uff",
    "read_geometry",
    "read_geometry_uff",
    "read_time_uff",
    "read_units",
    "write_frf_uff",
    "write_time_uff",
]
