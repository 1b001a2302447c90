"""The Keysight 33500 driver (generator-visa): command-level behaviour against pyvisa-sim's
description of the generator (hardware_mocks/visa_33500.yaml), the literal commands of a run
against the simulated 33500 on a TCP socket, and its one-line refusals."""

from __future__ import annotations

import socket
import sys
import threading
from pathlib import Path

import pytest

from drivers.base import DeviceState
from drivers.errors import (
    DeviceInitializationError,
    DeviceNotAvailableError,
    DeviceTimeoutError,
)
from drivers.generator_visa import GeneratorError, VisaGenerator
from drivers.registry import get_backend
from drivers.station import parse_station
from hardware_mocks.generator_33500 import Generator33500

pyvisa = pytest.importorskip("pyvisa")
pytest.importorskip("pyvisa_sim")

YAML = Path(__file__).resolve().parents[2] / "hardware_mocks" / "visa_33500.yaml"
LAN = "TCPIP0::192.168.1.20::5025::SOCKET"


@pytest.fixture
def rm():
    manager = pyvisa.ResourceManager(f"{YAML}@sim")
    yield manager
    manager.close()


def _gen(rm, resource: str = LAN, **kw) -> VisaGenerator:
    return VisaGenerator("shaker", resource, resource_manager=rm, reply_timeout=0.3, **kw)


def test_station_entry_builds_the_driver_with_the_stations_resource_and_limits() -> None:
    station = parse_station({"devices": {"shaker": {
        "backend": "generator-visa",
        "transport": {"visa": "TCPIP0::10.0.0.5::5025::SOCKET", "backend": "@py"},
        "options": {"max_level": 1.0, "load": 50}}}})
    cfg = station.devices["shaker"]
    cls = get_backend("generator-visa")
    assert cls is VisaGenerator
    assert cls.setting_limits(cfg)["level"] == (0.0, 1.0)
    gen = cls.from_config(cfg)
    assert isinstance(gen, VisaGenerator)
    assert (gen.resource, gen.backend, gen.load) == ("TCPIP0::10.0.0.5::5025::SOCKET", "@py",
                                                     "50")


def test_open_identifies_resets_and_sets_a_random_drive(rm) -> None:
    with _gen(rm) as gen:
        assert gen.identity.startswith("Keysight Technologies,33511B,")
        assert gen.query("OUTP:LOAD?") == "INF" and gen.query("OUTP?") == "OFF"
        gen.set_waveform("random", f_start=2.0, f_stop=200.0)
        gen.set_level(0.5)
        assert gen.query("FUNC?") == "NOIS"
        assert float(gen.query("FUNC:NOIS:BAND?")) == 200.0
        assert gen.query("VOLT:UNIT?") == "VRMS" and float(gen.query("VOLT?")) == 0.5
        gen.start()
        assert gen.query("OUTP?") == "ON" and gen.output_problem() == ""
        gen.stop()
        assert gen.query("OUTP?") == "OFF"
        gen.set_waveform("sine", frequency=80.0)  # the level follows the new waveform: V peak
        assert gen.query("FUNC?") == "SIN" and float(gen.query("FREQ?")) == 80.0
        assert gen.query("VOLT:UNIT?") == "VPP" and float(gen.query("VOLT?")) == 1.0
    assert gen.state is DeviceState.SHUT_DOWN


def test_a_setting_the_generator_refuses_turns_the_output_off_and_names_it(rm) -> None:
    with _gen(rm, load=50, max_level=8.0) as gen:
        gen.set_waveform("sine", frequency=80.0)
        gen.set_level(1.0)
        gen.start()
        with pytest.raises(GeneratorError) as err:
            gen.command("FUNC SQU")  # not in this 33500's subset: -100 in the queue
        assert err.value.code == -100
        assert str(err.value) == ("shaker: the generator refused 'FUNC SQU': -100 Command "
                                  "error; output turned off")
        assert gen.state is DeviceState.OPEN and gen.query("OUTP?") == "OFF"
        # a level beyond the 33500's 10 Vpp into 50 ohm is refused before it is sent
        with pytest.raises(ValueError, match=r"12 VPP for this waveform, outside the "
                           r"generator's 0.001..10 Vpp into load 50"):
            gen.set_level(6.0)
        with pytest.raises(ValueError, match="above the station's limit 8 V"):
            gen.set_level(8.5)
        with pytest.raises(ValueError, match=r"sine takes \['frequency'\]"):
            gen.set_waveform("sine", f_stop=3.0)


def test_another_makers_generator_is_refused_by_its_identity(rm) -> None:
    gen = _gen(rm, "USB0::0x1AB1::0x0642::DG1ZA000000001::INSTR")
    with pytest.raises(DeviceInitializationError, match=r"is not a Keysight 33500/33600 "
                       r"generator \(identity 'Rigol Technologies,DG1022Z"):
        gen.open()
    gen.shutdown()


def test_a_silent_generator_is_a_one_line_timeout(rm) -> None:
    gen = _gen(rm, "TCPIP0::192.168.1.21::5025::SOCKET")
    with pytest.raises(DeviceTimeoutError) as err:
        gen.open()
    assert str(err.value) == ("shaker: no answer from the generator to '*IDN?' within 0.3 s: "
                              "check that it is on and reachable at "
                              "TCPIP0::192.168.1.21::5025::SOCKET")
    gen.shutdown()


def test_without_pyvisa_one_line_names_the_pip_install(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyvisa", None)
    with pytest.raises(DeviceNotAvailableError) as err:
        VisaGenerator("shaker", LAN)
    assert str(err.value) == ("shaker: the generator-visa backend needs PyVISA, which is not "
                              "installed: pip install 'insitu[visa]'")


def test_an_unknown_backend_or_an_unreachable_generator_is_one_line() -> None:
    gen = VisaGenerator("shaker", LAN, backend="@nosuchbackend")
    with pytest.raises(DeviceNotAvailableError, match=r"no VISA library for backend "
                       r"@nosuchbackend .*pip install 'insitu\[visa\]'") as err:
        gen.open()
    assert "\n" not in str(err.value)
    with socket.create_server(("127.0.0.1", 0)) as s:
        port = s.getsockname()[1]
    gen = VisaGenerator("shaker", f"TCPIP0::127.0.0.1::{port}::SOCKET", backend="@py",
                        reply_timeout=0.5)
    with pytest.raises(DeviceNotAvailableError, match=rf"cannot open TCPIP0::127.0.0.1::{port}"
                       r"::SOCKET .*check the resource string") as err:
        gen.open()
    assert "\n" not in str(err.value)


def test_literal_commands_of_a_burst_random_drive_on_the_simulated_33500() -> None:
    with Generator33500() as mock, VisaGenerator("shaker", mock.resource, backend="@py",
                                                 reply_timeout=2.0, bursts=2) as gen:
        gen.set_waveform("burst-random", f_start=5.0, f_stop=100.0, period=0.5, burst=0.25)
        gen.set_level(0.2)
        gen.start()
        gen.stop()
    arb = mock.arbs["INSITU"]
    # 2 bursts a period of 0.5 s at 20 samples a cycle at 100 Hz (2000 Sa/s), the loudest
    # sample at full scale, each burst on for a quarter of its period
    assert arb.size == 2000 and max(abs(arb)) == 1.0
    assert (abs(arb.reshape(2, 1000)[:, 251:]) == 0).all()
    on = arb.reshape(2, 1000)[:, :250]
    vpp = 2 * 0.2 / (on**2).mean() ** 0.5  # twice the RMS in the bursts, crest factor
    volt = next(c for c in mock.commands if c.startswith("VOLT "))
    assert float(volt.split()[1]) == pytest.approx(vpp, rel=0.02)
    upload = next(c for c in mock.commands if c.startswith("DATA:ARB:DAC"))
    assert upload.startswith("DATA:ARB:DAC INSITU,")
    assert mock.commands == [
        "*IDN?", "OUTP OFF", "*RST", "*CLS", "OUTP:LOAD INF", "VOLT:OFFS 0", "SYST:ERR?",
        "FUNC SIN", "DATA:VOL:CLE", "SYST:ERR?",
        upload, "FUNC:ARB INSITU", "FUNC ARB", "FUNC:ARB:SRAT 2000", "SYST:ERR?",
        "VOLT:UNIT VPP", volt, "SYST:ERR?",
        "OUTP ON", "SYST:ERR?",
        "OUTP OFF",  # stop
        "OUTP OFF",  # shutdown
    ]


def test_output_off_does_not_wait_on_a_generator_that_stopped_reading() -> None:
    """A write the backend cannot finish (the generator's input full) holds the session;
    the output-off attempt gives up in one line after twice the reply timeout."""
    with Generator33500() as mock:
        gen = VisaGenerator("shaker", mock.resource, backend="@py", reply_timeout=0.2)
        gen.open()
        gen.set_waveform("sine", frequency=50.0)
        gen.set_level(0.1)
        gen.start()
        release = threading.Event()
        writer = gen._inst.write

        def stuck(cmd: str) -> int:  # a write blocked in the backend
            release.wait(30)
            return writer(cmd)

        gen._inst.write = stuck
        with pytest.raises(DeviceTimeoutError, match=r"OUTP OFF not sent within 0\.4 s: turn "
                           r"the generator's output off by hand"):
            gen.stop()
        assert not release.is_set()  # stop() returned while the write was still blocked
        release.set()
        gen._inst.write = writer
        gen.shutdown()
    assert mock.commands[-1] == "OUTP OFF"
