"""What the NI-DAQmx backends share: importing nidaqmx, creating a task, one-line errors.

The front end (:mod:`drivers.frontend_nidaqmx`) and the analogue-output shaker drive
(:mod:`drivers.shaker_nidaqmx`) both reach NI-DAQmx through an injected ``api`` (the
``nidaqmx`` package by default, imported when the device opens) and turn its failures into
the same one-line errors: the package missing (:func:`import_nidaqmx`), NI's driver missing
(:func:`new_task`), an unknown device, a module removed or the chassis gone
(:func:`daq_error`).

Example
-------
>>> ni = import_nidaqmx("shaker", "shaker-nidaqmx", ("constants", "errors"))  # doctest: +SKIP
>>> task = new_task(ni, "shaker", ["cDAQ1Mod5"])  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Sequence
from typing import Any

from drivers.errors import (
    DeviceError,
    DeviceInitializationError,
    DeviceNotAvailableError,
    one_line,
)

__all__ = ["DEVICE_GONE", "INSTALL", "INVALID_DEVICE_ID", "close_task", "daq_error",
           "device_options", "first_line", "import_nidaqmx", "new_task"]

#: what installs the nidaqmx package
INSTALL = "pip install 'insitu[ni]'"
#: NI-DAQmx error codes the drivers name (nidaqmx.error_codes.DAQmxErrors)
INVALID_DEVICE_ID = (-200220, -200207)
DEVICE_GONE = (-201003, -200045)


logger = logging.getLogger(__name__)


def import_nidaqmx(device: str, backend: str, submodules: Sequence[str]) -> Any:
    """The ``nidaqmx`` package with ``submodules`` (``"constants"``, ``"stream_readers"``...)
    imported; one line naming the install when it is missing."""
    try:
        api = importlib.import_module("nidaqmx")
        for sub in submodules:
            importlib.import_module(f"nidaqmx.{sub}")
    except ImportError as err:
        raise DeviceNotAvailableError(
            f"{device}: backend {backend} needs the nidaqmx package, which is not "
            f"installed: {INSTALL}", device) from err
    return api


def first_line(err: BaseException) -> str:
    """The first non-blank line of ``err``'s message (nidaqmx's run over several)."""
    lines = [s.strip() for s in str(err).splitlines() if s.strip()]
    return one_line(lines[0]) if lines else type(err).__name__


def daq_error(device: str, modules: Sequence[str], err: BaseException,
              doing: str) -> DeviceError:
    """One line for an NI-DAQmx error raised while ``doing``, on a device of ``modules``.

    Parameters
    ----------
    device : str
        The device's name in the station file.
    modules : sequence of str
        Its NI-DAQmx module names (the station's ``transport nidaqmx``).
    err : nidaqmx.errors.DaqError
    doing : str
        What the driver was doing, e.g. ``"starting"``.
    """
    code = int(getattr(err, "error_code", 0))
    text = first_line(err).rstrip(".")
    devs = ", ".join(modules)
    if code in INVALID_DEVICE_ID:
        return DeviceNotAvailableError(
            f"{device}: {doing}: NI-DAQmx has no such device ({text}, error {code}): "
            f"check the module names NI MAX shows against transport nidaqmx = [{devs}]",
            device)
    if code in DEVICE_GONE:
        return DeviceNotAvailableError(
            f"{device}: {doing}: {text} (NI-DAQmx error {code}): a module of {devs} was "
            "removed, or the chassis lost power or its connection: check it, then resume",
            device)
    return DeviceInitializationError(f"{device}: {doing}: {text} (NI-DAQmx error {code})",
                                     device)


def new_task(ni: Any, device: str, modules: Sequence[str]) -> Any:
    """``ni.Task()``; one line when NI's driver is missing or NI-DAQmx refuses."""
    try:
        return ni.Task()
    except ni.errors.DaqNotFoundError as err:
        raise DeviceNotAvailableError(
            f"{device}: the NI-DAQmx driver is not installed (nidaqmx found no "
            "NI-DAQmx library): install NI-DAQmx from ni.com (Linux: python -m nidaqmx "
            "installdriver)", device) from err
    except ni.errors.DaqError as err:
        raise daq_error(device, modules, err, "creating the task") from err


def close_task(task: Any, ni: Any, device: str) -> None:
    """Close an NI-DAQmx task (None: nothing to close); a failure is logged, not raised: a
    task is closed on the way out, where the error that led there is the one to report."""
    if task is None:
        return
    try:
        task.close()
    except ni.errors.DaqError as err:
        logger.warning("%s: closing the task: %s", device, first_line(err))


def device_options(config: Any, overrides: dict[str, Any], allowed: Sequence[str]
                   ) -> dict[str, Any]:
    """A station device's options with the caller's overrides; ValueError naming the first
    option not in ``allowed`` (the injected ``api`` is not listed to the operator)."""
    opts = {**config.options, **overrides}
    if unknown := sorted(set(opts) - set(allowed)):
        raise ValueError(f"device {config.name!r}: unknown option {unknown[0]!r}; allowed: "
                         f"{', '.join(o for o in allowed if o != 'api')}")
    return opts
