"""station.toml parsing and backend lookup."""

from __future__ import annotations

from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

import drivers.registry as registry
from drivers.base import ChannelConfig, TimeBlock
from drivers.frontend_can import CanFrontEnd
from drivers.hammer_serial import SerialHammer
from drivers.shaker_scpi import ScpiShaker
from drivers.station import (
    CanTransportConfig,
    NiDaqTransportConfig,
    StationConfigError,
    VisaTransportConfig,
    load_station,
    parse_station,
)

STATION = """
[station]
name = "engine cell"

[devices.frontend]
backend = "frontend-can"
fs = 1024
transport = { interface = "virtual", channel = "cell", fd = true, bitrate = 500000, \
receive_own_messages = false }
options = { frame = "fd" }

[[devices.frontend.channels]]
name = "a1x"
input = 0
quantity = "acceleration"
sensitivity = 10.2
range = 5.0
iepe = true
node = 1
direction = [2, 0, 0]

[devices.hammer]
backend = "hammer-serial"
fs = 4096
transport = { url = "loop://", baudrate = 921600 }

[[devices.hammer.channels]]
name = "F"
input = 0
quantity = "force"
sensitivity = 2.25

[devices.shaker]
backend = "shaker-scpi"
transport = { url = "loop://" }
options = { heartbeat = 0.5, ramp = 2.0 }
"""


def test_load_station(tmp_path: Path) -> None:
    path = tmp_path / "station.toml"
    path.write_text(STATION)
    st = load_station(path)
    assert st.name == "engine cell" and list(st.devices) == ["frontend", "hammer", "shaker"]
    fe = st.devices["frontend"]
    assert fe.channels[0] == ChannelConfig("a1x", 0, "acceleration", 10.2, True, 5.0, 1,
                                           (1.0, 0.0, 0.0))
    assert isinstance(fe.transport, CanTransportConfig)
    assert fe.transport.bus_kwargs() == {"interface": "virtual", "fd": True, "channel": "cell",
                                         "bitrate": 500000, "receive_own_messages": False}
    assert st.devices["hammer"].channels[0].range_v == 5.0  # default range


def test_station_builds_devices(tmp_path: Path) -> None:
    path = tmp_path / "station.toml"
    path.write_text(STATION)
    st = load_station(path)
    fe = registry.create_device(st.devices["frontend"])
    hammer = registry.create_device(st.devices["hammer"])
    shaker = registry.create_device(st.devices["shaker"])
    assert isinstance(fe, CanFrontEnd) and fe.layout.fd and fe.fs == 1024
    assert isinstance(hammer, SerialHammer) and hammer.fs == 4096
    assert isinstance(shaker, ScpiShaker) and (shaker.heartbeat, shaker.ramp) == (0.5, 2.0)
    for dev in (fe, hammer, shaker):
        dev.shutdown()  # never opened: shutdown is still fine


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("sensitivity = 10.2", "sensitivity = -1"),
         "devices.frontend.channels[0].sensitivity: must be > 0, got -1"),
        (('quantity = "force"', 'quantity = "torque"'),
         "devices.hammer.channels[0].quantity: 'torque' is not one of force, acceleration"),
        (('backend = "shaker-scpi"', 'backend = "shaker-9000"'),
         "devices.shaker.backend: unknown backend 'shaker-9000'"),
        (('transport = { url = "loop://" }', 'transport = { url = "loop://", interface = "x" }'),
         "devices.shaker.transport: give exactly one of url"),
        (("direction = [2, 0, 0]", "direction = [0, 0, 0]"),
         "devices.frontend.channels[0].direction: must be a non-zero"),
        (("iepe = true", "iepe = 1"), "devices.frontend.channels[0].iepe: must be true or false"),
        (("fs = 4096", "fs = 4096\ngain = 3"), "devices.hammer.gain: unknown key"),
        (('name = "F"', 'name = "a1x"'),
         "devices.hammer.channels[0].name: channel name 'a1x' already used by device 'frontend'"),
    ],
)
def test_errors_name_the_key(tmp_path: Path, edit: tuple[str, str], message: str) -> None:
    path = tmp_path / "station.toml"
    assert edit[0] in STATION
    path.write_text(STATION.replace(edit[0], edit[1], 1))
    with pytest.raises(StationConfigError) as info:
        load_station(path)
    text = str(info.value)
    assert "\n" not in text and text.startswith(f"{path}: ") and message in text


def test_not_toml(tmp_path: Path) -> None:
    path = tmp_path / "station.toml"
    path.write_text("[devices\n")
    with pytest.raises(StationConfigError, match="not valid TOML"):
        load_station(path)


def test_no_devices() -> None:
    with pytest.raises(StationConfigError, match="devices: missing"):
        parse_station({"station": {"name": "x"}})


def test_builtin_backends_resolve_lazily() -> None:
    assert registry.get_backend("hammer-serial") is SerialHammer
    assert {"frontend-can", "hammer-serial", "shaker-scpi"} <= set(registry.available_backends())
    with pytest.raises(ValueError, match="unknown device backend 'nope': choose one of"):
        registry.get_backend("nope")


def test_entry_point_backend(monkeypatch: pytest.MonkeyPatch) -> None:
    eps = [EntryPoint("acme-hammer", "drivers.hammer_serial:SerialHammer", "insitu.drivers"),
           EntryPoint("not-a-device", "drivers.base:TimeBlock", "insitu.drivers")]
    monkeypatch.setattr(registry, "entry_points",
                        lambda group: [e for e in eps if e.group == group])
    assert registry.get_backend("acme-hammer") is SerialHammer
    assert "acme-hammer" in registry.available_backends()
    # the entry point loads drivers.base.TimeBlock, a class but not a Device: refused by name
    with pytest.raises(TypeError) as err:
        registry.get_backend("not-a-device")
    assert str(err.value) == (f"backend 'not-a-device' is {TimeBlock!r}, "
                              "not a drivers.base.Device subclass")


def test_nidaqmx_and_visa_transports_and_simulation() -> None:
    cfg = parse_station({
        "simulation": {"bench": "engine-rigid"},
        "devices": {
            "daq": {"backend": "frontend-can", "fs": 1024,
                    "transport": {"nidaqmx": ["cDAQ1Mod1", "cDAQ1Mod2"]}},
            "gen": {"backend": "shaker-scpi",
                    "transport": {"visa": "TCPIP0::127.0.0.1::5025::SOCKET", "backend": "@py"}},
        }}, check_backends=False)
    assert cfg.simulation == {"bench": "engine-rigid"}
    assert cfg.devices["daq"].transport == NiDaqTransportConfig(("cDAQ1Mod1", "cDAQ1Mod2"))
    assert cfg.devices["gen"].transport == VisaTransportConfig(
        "TCPIP0::127.0.0.1::5025::SOCKET", "@py")
    assert parse_station({"devices": {"d": {"backend": "x", "transport": {"nidaqmx": "Dev1"}}}},
                         check_backends=False).simulation == {}
    for transport, message in [({"nidaqmx": []}, "nidaqmx: must be a device name"),
                               ({"nidaqmx": ["A", "A"]}, "listed twice"),
                               ({"visa": "X", "baud": 3}, "transport.baud: unknown key"),
                               ({"visa": "X", "url": "loop://"}, "give exactly one of")]:
        with pytest.raises(StationConfigError, match=message):
            parse_station({"devices": {"d": {"backend": "x", "transport": transport}}},
                          check_backends=False)
    with pytest.raises(StationConfigError, match=r"simulation\.bench: missing"):
        parse_station({"simulation": {"seed": 1},
                       "devices": {"d": {"backend": "x", "transport": {"nidaqmx": "Dev1"}}}},
                      check_backends=False)
