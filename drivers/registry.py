"""Backends by name: a lazy-import table plus the ``insitu.drivers`` entry points.

A station file names each device's backend with a string. Built-in backends are
listed in :data:`BACKENDS` as ``(module, class)`` and imported only when used;
third-party packages add theirs through the entry-point group ``insitu.drivers``::

    [project.entry-points."insitu.drivers"]
    my-frontend = "my_package.frontend:MyFrontEnd"

Example
-------
>>> get_backend("hammer-serial").__name__
'SerialHammer'
"""

from __future__ import annotations

import importlib
import logging
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any

from drivers.base import Device

if TYPE_CHECKING:
    from drivers.station import DeviceConfig

__all__ = ["BACKENDS", "ENTRY_POINT_GROUP", "available_backends", "create_device", "get_backend"]

logger = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "insitu.drivers"

#: built-in backends: name -> (module, class name)
BACKENDS: dict[str, tuple[str, str]] = {
    "frontend-can": ("drivers.frontend_can", "CanFrontEnd"),
    "frontend-nidaqmx": ("drivers.frontend_nidaqmx", "NiDaqFrontEnd"),
    "generator-visa": ("drivers.generator_visa", "VisaGenerator"),
    "hammer-serial": ("drivers.hammer_serial", "SerialHammer"),
    "shaker-nidaqmx": ("drivers.shaker_nidaqmx", "NiDaqShaker"),
    "shaker-scpi": ("drivers.shaker_scpi", "ScpiShaker"),
}


def _entry_point_names() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available_backends() -> list[str]:
    """Names of every backend, built-in and installed through entry points, sorted."""
    return sorted(set(BACKENDS) | set(_entry_point_names()))


def get_backend(name: str) -> type[Device]:
    """The device class registered as ``name``.

    Raises
    ------
    ValueError
        ``name`` is neither built in nor an installed entry point; the message
        lists the known names.
    """
    if name in BACKENDS:
        module_name, class_name = BACKENDS[name]
        cls = getattr(importlib.import_module(module_name), class_name)
    else:
        eps = _entry_point_names()
        if name not in eps:
            raise ValueError(
                f"unknown device backend {name!r}: choose one of {', '.join(available_backends())}"
            )
        cls = eps[name].load()
    if not (isinstance(cls, type) and issubclass(cls, Device)):
        raise TypeError(f"backend {name!r} is {cls!r}, not a drivers.base.Device subclass")
    return cls


def create_device(config: DeviceConfig, **overrides: Any) -> Device:
    """Build (not open) the device a station-file entry describes."""
    cls = get_backend(config.backend)
    logger.debug("creating %s with backend %s", config.name, config.backend)
    return cls.from_config(config, **overrides)
