"""The station file: which devices a test cell has, how they are wired and read.

``station.toml`` lists devices by name. Each one names its backend (see
:mod:`drivers.registry`), its transport (a serial ``url`` or a python-can
``interface``), its sampling rate, its channels and backend options::

    [station]
    name = "engine cell 2"

    [devices.frontend]
    backend = "frontend-can"
    fs = 1024
    transport = { interface = "socketcan", channel = "can0", fd = true }
    options = { frame = "fd" }

    [[devices.frontend.channels]]
    name = "a1x"
    input = 0
    quantity = "acceleration"
    sensitivity = 10.2        # mV/(m/s^2)
    range = 5.0               # +/- V
    iepe = true
    node = 1
    direction = [1, 0, 0]

    [devices.shaker]
    backend = "shaker-scpi"
    transport = { url = "/dev/ttyUSB1", baudrate = 115200 }
    options = { heartbeat = 0.5, ramp = 1.0 }

A transport is one of four kinds, told apart by its first key: a serial ``url``, a
python-can ``interface``, NI-DAQmx device names (``nidaqmx = "cDAQ1Mod1"`` or a list of
modules) or a VISA resource string (``visa = "TCPIP0::10.0.0.5::inst0::INSTR"``, with an
optional PyVISA ``backend`` such as ``"@py"``).

A top-level ``[simulation]`` table says that the vendor APIs (nidaqmx, PyVISA) of this
station are the simulated ones, driven by a built-in bench's physics
(``bench = "engine-rigid"``); :attr:`StationConfig.simulation` keeps it as it is, empty
for a real station. The drivers never read it: the application injects the simulated
APIs at each driver's boundary.

A top-level ``[extra]`` table is kept as it is (:attr:`StationConfig.extra`) for
tools that share the file (``insitu mock-bench`` puts its control address there).

Every error is one line naming the key, e.g.
``station.toml: devices.frontend.channels[2].sensitivity: must be > 0, got -1``.

Example
-------
>>> cfg = parse_station({"devices": {"h": {"backend": "hammer-serial", "fs": 4096,
...     "transport": {"url": "loop://"}, "channels": [{"name": "F", "input": 0,
...     "quantity": "force", "sensitivity": 2.25}]}}})
>>> cfg.devices["h"].channels[0].unit
'N'
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.base import QUANTITY_UNITS, ChannelConfig, Quantity
from drivers.errors import one_line

__all__ = [
    "CanTransportConfig",
    "DeviceConfig",
    "NiDaqTransportConfig",
    "SerialTransportConfig",
    "StationConfig",
    "StationConfigError",
    "Transport",
    "VisaTransportConfig",
    "load_station",
    "parse_station",
]


class StationConfigError(ValueError):
    """The station file is invalid; the message names the file and the bad key."""


@dataclass(frozen=True)
class SerialTransportConfig:
    """A serial port: device path or pyserial URL, and baud rate."""

    url: str
    baudrate: int = 115200


@dataclass(frozen=True)
class CanTransportConfig:
    """A python-can bus: ``interface`` and ``channel`` plus any other ``can.Bus`` keywords."""

    interface: str
    channel: str | int | None = None
    fd: bool = False
    bitrate: int | None = None
    data_bitrate: int | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def bus_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``can.Bus``."""
        kw: dict[str, Any] = {"interface": self.interface, "fd": self.fd, **self.extra}
        if self.channel is not None:
            kw["channel"] = self.channel
        if self.bitrate is not None:
            kw["bitrate"] = self.bitrate
        if self.data_bitrate is not None:
            kw["data_bitrate"] = self.data_bitrate
        return kw


@dataclass(frozen=True)
class NiDaqTransportConfig:
    """NI-DAQmx devices (module names as NI MAX shows them), in the order their inputs are
    numbered."""

    devices: tuple[str, ...]


@dataclass(frozen=True)
class VisaTransportConfig:
    """A VISA resource string and the PyVISA backend to open it with (None: PyVISA's default)."""

    resource: str
    backend: str | None = None


Transport = SerialTransportConfig | CanTransportConfig | NiDaqTransportConfig | VisaTransportConfig


@dataclass(frozen=True)
class DeviceConfig:
    """One device of the station."""

    name: str
    backend: str
    transport: Transport
    fs: float | None = None
    channels: tuple[ChannelConfig, ...] = ()
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class StationConfig:
    """The whole station: a name, its devices by name, the ``[simulation]`` table (empty for
    real hardware) and the free-form ``[extra]`` table."""

    name: str
    devices: Mapping[str, DeviceConfig]
    source: str = "station.toml"
    extra: Mapping[str, Any] = field(default_factory=dict)
    simulation: Mapping[str, Any] = field(default_factory=dict)


_DEVICE_KEYS = {"backend", "transport", "fs", "channels", "options"}
_CHANNEL_KEYS = {"name", "input", "quantity", "sensitivity", "range", "iepe", "node", "direction"}
_CAN_KEYS = {"interface", "channel", "fd", "bitrate", "data_bitrate"}


class _Ctx:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, msg: str) -> StationConfigError:
        return StationConfigError(one_line(f"{self.source}: {key}: {msg}"))

    def table(self, value: object, key: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(key, f"must be a table, got {type(value).__name__}")
        return value

    def unknown(self, table: Mapping[str, Any], allowed: set[str], key: str) -> None:
        extra = sorted(set(table) - allowed)
        if extra:
            raise self.fail(f"{key}.{extra[0]}",
                            f"unknown key; allowed: {', '.join(sorted(allowed))}")

    def number(self, table: Mapping[str, Any], name: str, key: str, *, positive: bool = True,
               integer: bool = False, default: Any = None) -> Any:
        if name not in table:
            if default is None:
                raise self.fail(f"{key}.{name}", "missing")
            return default
        v = table[name]
        ok_types = (int,) if integer else (int, float)
        if isinstance(v, bool) or not isinstance(v, ok_types):
            kind = "an integer" if integer else "a number"
            raise self.fail(f"{key}.{name}", f"must be {kind}, got {v!r}")
        if positive and not v > 0:
            raise self.fail(f"{key}.{name}", f"must be > 0, got {v!r}")
        return v

    def string(self, table: Mapping[str, Any], name: str, key: str) -> str:
        v = table.get(name)
        if not isinstance(v, str) or not v:
            raise self.fail(f"{key}.{name}",
                            "missing" if v is None else f"must be a non-empty string, got {v!r}")
        return v


def _channel(ctx: _Ctx, raw: object, key: str) -> ChannelConfig:
    t = ctx.table(raw, key)
    ctx.unknown(t, _CHANNEL_KEYS, key)
    name = ctx.string(t, "name", key)
    text = ctx.string(t, "quantity", key)
    if text not in QUANTITY_UNITS:
        raise ctx.fail(f"{key}.quantity", f"{text!r} is not one of {', '.join(QUANTITY_UNITS)}")
    quantity: Quantity = "force" if text == "force" else "acceleration"
    inp = ctx.number(t, "input", key, positive=False, integer=True)
    if inp < 0:
        raise ctx.fail(f"{key}.input", f"must be >= 0, got {inp}")
    sens = ctx.number(t, "sensitivity", key)
    rng = ctx.number(t, "range", key, default=5.0)
    iepe = t.get("iepe", True)
    if not isinstance(iepe, bool):
        raise ctx.fail(f"{key}.iepe", f"must be true or false, got {iepe!r}")
    node = t.get("node")
    if node is not None and (isinstance(node, bool) or not isinstance(node, int)):
        raise ctx.fail(f"{key}.node", f"must be an integer node id, got {node!r}")
    direction = t.get("direction")
    if direction is not None:
        if (not isinstance(direction, list) or len(direction) != 3
                or not all(isinstance(x, int | float) and not isinstance(x, bool)
                           for x in direction)
                or not any(direction)):
            raise ctx.fail(f"{key}.direction", f"must be a non-zero [x, y, z], got {direction!r}")
        direction = tuple(float(x) for x in direction)
    return ChannelConfig(name, inp, quantity, float(sens), iepe, float(rng), node, direction)


_TRANSPORT_KINDS = ("url", "interface", "nidaqmx", "visa")


def _transport(ctx: _Ctx, raw: object, key: str) -> Transport:
    t = ctx.table(raw, key)
    kinds = [k for k in _TRANSPORT_KINDS if k in t]
    if len(kinds) != 1:
        raise ctx.fail(key, "give exactly one of url (serial), interface (CAN), nidaqmx "
                            "(NI-DAQmx device) or visa (VISA resource)")
    if "url" in t:
        ctx.unknown(t, {"url", "baudrate"}, key)
        baud = ctx.number(t, "baudrate", key, integer=True, default=115200)
        return SerialTransportConfig(ctx.string(t, "url", key), int(baud))
    if "nidaqmx" in t:
        ctx.unknown(t, {"nidaqmx"}, key)
        names = t["nidaqmx"]
        names = [names] if isinstance(names, str) else names
        if (not isinstance(names, list) or not names
                or not all(isinstance(n, str) and n for n in names)):
            raise ctx.fail(f"{key}.nidaqmx", "must be a device name or a list of names, "
                                             f"got {t['nidaqmx']!r}")
        if len(set(names)) != len(names):
            raise ctx.fail(f"{key}.nidaqmx", f"a device is listed twice in {names!r}")
        return NiDaqTransportConfig(tuple(names))
    if "visa" in t:
        ctx.unknown(t, {"visa", "backend"}, key)
        backend = t.get("backend")
        if backend is not None:
            backend = ctx.string(t, "backend", key)
        return VisaTransportConfig(ctx.string(t, "visa", key), backend)
    interface = ctx.string(t, "interface", key)
    fd = t.get("fd", False)
    if not isinstance(fd, bool):
        raise ctx.fail(f"{key}.fd", f"must be true or false, got {fd!r}")
    channel = t.get("channel")
    if channel is not None and (isinstance(channel, bool) or not isinstance(channel, str | int)):
        raise ctx.fail(f"{key}.channel", f"must be a string or an integer, got {channel!r}")
    bitrate = ctx.number(t, "bitrate", key, integer=True, default=0) or None
    dbitrate = ctx.number(t, "data_bitrate", key, integer=True, default=0) or None
    extra = {k: v for k, v in t.items() if k not in _CAN_KEYS}
    return CanTransportConfig(interface, channel, fd, bitrate, dbitrate, extra)


def _device(ctx: _Ctx, name: str, raw: object, known_backends: list[str] | None) -> DeviceConfig:
    key = f"devices.{name}"
    t = ctx.table(raw, key)
    ctx.unknown(t, _DEVICE_KEYS, key)
    backend = ctx.string(t, "backend", key)
    if known_backends is not None and backend not in known_backends:
        raise ctx.fail(f"{key}.backend",
                       f"unknown backend {backend!r}; choose one of {', '.join(known_backends)}")
    if "transport" not in t:
        raise ctx.fail(f"{key}.transport", "missing")
    transport = _transport(ctx, t["transport"], f"{key}.transport")
    fs = ctx.number(t, "fs", key, default=0.0) or None
    raw_channels = t.get("channels", [])
    if not isinstance(raw_channels, list):
        raise ctx.fail(f"{key}.channels", "must be an array of tables ([[...channels]])")
    channels = tuple(_channel(ctx, c, f"{key}.channels[{i}]") for i, c in enumerate(raw_channels))
    seen: dict[int, str] = {}
    for i, ch in enumerate(channels):
        if ch.input in seen:
            raise ctx.fail(f"{key}.channels[{i}].input",
                           f"input {ch.input} already used by channel {seen[ch.input]!r}")
        seen[ch.input] = ch.name
    options = ctx.table(t.get("options", {}), f"{key}.options")
    return DeviceConfig(name, backend, transport, None if fs is None else float(fs), channels,
                        dict(options))


def parse_station(data: Mapping[str, Any], source: str = "station.toml",
                  check_backends: bool = True) -> StationConfig:
    """Validate a parsed station file; raises :class:`StationConfigError` naming the bad key."""
    ctx = _Ctx(source)
    ctx.unknown(data, {"station", "devices", "extra", "simulation"}, "(top level)")
    extra = ctx.table(data.get("extra", {}), "extra")
    simulation = ctx.table(data.get("simulation", {}), "simulation")
    if simulation:
        ctx.string(simulation, "bench", "simulation")
    station = ctx.table(data.get("station", {}), "station")
    ctx.unknown(station, {"name"}, "station")
    name = station.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise ctx.fail("station.name", f"must be a string, got {name!r}")
    devices_raw = ctx.table(data.get("devices"), "devices") if "devices" in data else None
    if not devices_raw:
        raise ctx.fail("devices", "missing: list at least one [devices.NAME] table")
    known: list[str] | None = None
    if check_backends:
        from drivers.registry import available_backends

        known = available_backends()
    devices = {n: _device(ctx, n, d, known) for n, d in devices_raw.items()}
    owner: dict[str, str] = {}
    for dev in devices.values():
        for i, ch in enumerate(dev.channels):
            if ch.name in owner:
                raise ctx.fail(f"devices.{dev.name}.channels[{i}].name",
                               f"channel name {ch.name!r} already used by device "
                               f"{owner[ch.name]!r}")
            owner[ch.name] = dev.name
    return StationConfig(name, devices, source, dict(extra), dict(simulation))


def load_station(path: str | Path) -> StationConfig:
    """Read and validate ``station.toml``."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise StationConfigError(f"{p}: not valid TOML: {err}") from err
    return parse_station(data, str(p))
