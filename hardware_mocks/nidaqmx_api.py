"""The constants and error classes of the simulated NI-DAQmx: nidaqmx's own where installed.

With the ``nidaqmx`` package (the ``ni`` extra) the simulated system raises nidaqmx's
``DaqError`` and ``DaqNotFoundError`` and takes nidaqmx's enums, so the driver is tested
against the library's own classes. Without it, stand-ins with the same names, members,
values and signatures (nidaqmx 1.7) let the simulated bench run on the core install.

Example
-------
>>> constants.AccelUnits.METERS_PER_SECOND_SQUARED.value
12470
>>> errors.DaqError("Device identifier is invalid.", -200220).error_code
-200220
"""

from __future__ import annotations

import types
from enum import Enum
from typing import Any

__all__ = ["REAL", "constants", "errors"]


class _StandInDaqError(Exception):
    """nidaqmx.errors.DaqError: the message ends with the status code, as nidaqmx's does."""

    def __init__(self, message: str, error_code: int, task_name: str = "") -> None:
        self._error_code = int(error_code)
        if task_name:
            message = f"{message}\n\nTask Name: {task_name}"
        if str(self._error_code) not in message:
            message = f"{message}\n\nStatus Code: {self._error_code}"
        super().__init__(message)

    @property
    def error_code(self) -> int:
        return self._error_code


class _StandInDaqNotFoundError(Exception):
    """nidaqmx.errors.DaqNotFoundError: the NI-DAQmx driver is not installed."""


def _stand_in_constants() -> Any:
    def enum(name: str, **members: int) -> type[Enum]:
        return Enum(name, members)  # type: ignore[return-value]

    ns = types.SimpleNamespace(
        READ_ALL_AVAILABLE=-1,
        WAIT_INFINITELY=-1.0,
        AccelUnits=enum("AccelUnits", G=10186, METERS_PER_SECOND_SQUARED=12470,
                        INCHES_PER_SECOND_SQUARED=12471, FROM_CUSTOM_SCALE=10065),
        AccelSensitivityUnits=enum("AccelSensitivityUnits", MILLIVOLTS_PER_G=12509,
                                   VOLTS_PER_G=12510),
        ForceUnits=enum("ForceUnits", NEWTONS=15875, POUNDS=15876, KILOGRAM_FORCE=15877,
                        FROM_CUSTOM_SCALE=10065),
        ForceIEPESensorSensitivityUnits=enum("ForceIEPESensorSensitivityUnits",
                                             MILLIVOLTS_PER_NEWTON=15891,
                                             MILLIVOLTS_PER_POUND=15892),
        ExcitationSource=enum("ExcitationSource", INTERNAL=10200, EXTERNAL=10167, NONE=10230),
        Coupling=enum("Coupling", AC=10045, DC=10050, GND=10066),
        AcquisitionType=enum("AcquisitionType", FINITE=10178, CONTINUOUS=10123,
                             HW_TIMED_SINGLE_POINT=12522),
        Edge=enum("Edge", RISING=10280, FALLING=10171),
        EveryNSamplesEventType=enum("EveryNSamplesEventType", ACQUIRED_INTO_BUFFER=1,
                                    TRANSFERRED_FROM_BUFFER=2),
        TerminalConfiguration=enum("TerminalConfiguration", RSE=10083, NRSE=10078, DIFF=10106,
                                   PSEUDO_DIFF=12529, DEFAULT=-1),
        VoltageUnits=enum("VoltageUnits", VOLTS=10348, FROM_CUSTOM_SCALE=10065),
        RegenerationMode=enum("RegenerationMode", ALLOW_REGENERATION=10097,
                              DONT_ALLOW_REGENERATION=10158),
        SampleTimingType=enum("SampleTimingType", SAMPLE_CLOCK=10388, HANDSHAKE=10389,
                              IMPLICIT=10451, ON_DEMAND=10390, CHANGE_DETECTION=12504),
    )
    return ns


constants: Any
errors: Any
try:
    import nidaqmx.constants as _constants
    import nidaqmx.errors as _errors

    constants = _constants
    errors = types.SimpleNamespace(DaqError=_errors.DaqError,
                                   DaqNotFoundError=_errors.DaqNotFoundError)
    REAL = True
except ImportError:
    constants = _stand_in_constants()
    errors = types.SimpleNamespace(DaqError=_StandInDaqError,
                                   DaqNotFoundError=_StandInDaqNotFoundError)
    REAL = False
