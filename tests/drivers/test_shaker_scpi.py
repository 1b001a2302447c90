"""SG-1 shaker driver: literal SCPI bytes against a scripted device."""

from __future__ import annotations

import pytest

from drivers.base import DeviceState
from drivers.errors import DeviceError, DeviceInitializationError
from drivers.shaker_scpi import ScpiShaker, ShakerError

NO_ERROR = b'0,"No error"\n'
OPEN = [
    (b"*IDN?\n", b"INSITU,SG-1,0007,2.1\n"),
    (b"OUTP OFF\n*RST\n*CLS\nOUTP:RAMP 1\nSYST:ERR?\n", NO_ERROR),
    (b"SYST:HEART:TIM 0\nSYST:ERR?\n", NO_ERROR),
]
CLOSE = [(b"OUTP OFF\nSYST:HEART:TIM 0\n", b"")]


def test_open_and_close_literal(scripted) -> None:
    dev = scripted([*OPEN, *CLOSE])
    with ScpiShaker("shaker", dev.path, heartbeat=0) as shaker:
        assert shaker.identity == "INSITU,SG-1,0007,2.1"
    dev.check()
    shaker.shutdown()


def test_random_run_literal(scripted) -> None:
    dev = scripted([
        *OPEN,
        (b"SOUR:FUNC RAND\nSYST:ERR?\n", NO_ERROR),
        (b"SOUR:FREQ:STAR 5\nSYST:ERR?\n", NO_ERROR),
        (b"SOUR:FREQ:STOP 200\nSYST:ERR?\n", NO_ERROR),
        (b"SOUR:VOLT 0.5\nSYST:ERR?\n", NO_ERROR),
        (b"OUTP ON\nSYST:ERR?\n", NO_ERROR),
        (b"OUTP OFF\n", b""),
        *CLOSE,
    ])
    with ScpiShaker("shaker", dev.path, heartbeat=0) as shaker:
        shaker.set_waveform("random", f_start=5.0, f_stop=200.0)
        shaker.set_level(0.5)
        shaker.start()
        assert shaker.state is DeviceState.RUNNING
        shaker.stop()
    dev.check()


def test_shutdown_while_running_turns_output_off(scripted) -> None:
    dev = scripted([
        *OPEN,
        (b"SOUR:FUNC SIN\nSYST:ERR?\n", NO_ERROR),
        (b"SOUR:FREQ 80\nSYST:ERR?\n", NO_ERROR),
        (b"OUTP ON\nSYST:ERR?\n", NO_ERROR),
        *CLOSE,
    ])
    shaker = ScpiShaker("shaker", dev.path, heartbeat=0)
    shaker.open()
    shaker.set_waveform("sine", frequency=80.0)
    shaker.start()
    shaker.shutdown()
    shaker.shutdown()
    dev.check()


def test_device_error_turns_output_off_and_raises(scripted) -> None:
    dev = scripted([
        *OPEN,
        (b"SOUR:VOLT 1.5\nSYST:ERR?\n", b'-222,"Data out of range"\n'),
        (b"SYST:ERR?\n", NO_ERROR),
        (b"OUTP OFF\n", b""),
        *CLOSE,
    ])
    with ScpiShaker("shaker", dev.path, heartbeat=0) as shaker:
        with pytest.raises(ShakerError, match="-222 Data out of range") as info:
            shaker.set_level(1.5)
        assert info.value.code == -222
    dev.check()


def test_level_above_station_limit_is_not_sent(scripted) -> None:
    dev = scripted([*OPEN, *CLOSE])
    with ScpiShaker("shaker", dev.path, heartbeat=0, max_level=1.0) as shaker:
        with pytest.raises(ValueError, match="above the station's limit"):
            shaker.set_level(1.2)
    dev.check()


def test_start_needs_a_waveform(scripted) -> None:
    dev = scripted([*OPEN, *CLOSE])
    with ScpiShaker("shaker", dev.path, heartbeat=0) as shaker:
        with pytest.raises(DeviceError, match="choose a waveform"):
            shaker.start()
    dev.check()


def test_wrong_parameters_for_waveform(scripted) -> None:
    dev = scripted([*OPEN, *CLOSE])
    with ScpiShaker("shaker", dev.path, heartbeat=0) as shaker:
        with pytest.raises(ValueError, match="sine takes"):
            shaker.set_waveform("sine", f_start=3.0)
    dev.check()


def test_wrong_identity(scripted) -> None:
    dev = scripted([(b"*IDN?\n", b"ACME,PSU,1,1\n")])
    with pytest.raises(DeviceInitializationError, match="not an SG-1"):
        ScpiShaker("shaker", dev.path, heartbeat=0).open()
