"""The simulated SG-1 shaker: raw SCPI, then the driver against it with each fault."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
import serial

from drivers.errors import DeviceNotAvailableError, DeviceTimeoutError
from drivers.shaker_scpi import ScpiShaker, ShakerError
from hardware_mocks.shaker_device import ShakerDevice


@pytest.fixture
def device() -> Iterator[ShakerDevice]:
    dev = ShakerDevice()
    yield dev
    dev.shutdown()


def wait_for(predicate, timeout: float = 30.0) -> float:
    """Seconds until ``predicate()`` holds; ``timeout`` only guards against a hang."""
    t0 = time.monotonic()
    while not predicate():
        if time.monotonic() - t0 > timeout:
            raise AssertionError("condition not met in time")
        time.sleep(0.005)
    return time.monotonic() - t0


def test_raw_scpi(device: ShakerDevice) -> None:
    with serial.Serial(device.path, timeout=0.5) as port:
        port.write(b"*IDN?\n")
        assert port.read_until(b"\n") == b"INSITU,SG-1,0007,2.1\n"
        port.write(b"SYST:ERR?\n")
        assert port.read_until(b"\n") == b'0,"No error"\n'
        port.write(b"SOUR:WOBBLE 3\nSOUR:VOLT 9\nSOUR:FUNC CHIRP\nSOUR:FUNC?\n")
        assert port.read_until(b"\n") == b"CHIRP\n"
        port.write(b"SYST:ERR?\nSYST:ERR?\nSYST:ERR?\n")
        assert port.read_until(b"\n") == b'-113,"Undefined header"\n'
        assert port.read_until(b"\n") == b'-222,"Data out of range"\n'
        assert port.read_until(b"\n") == b'0,"No error"\n'


#: the watchdog armed on the device, s: heartbeats every 0.25 s, so a loaded host that
#: holds the heartbeat thread back for a few tenths of a second does not trip it
HEARTBEAT = 1.0
#: output ramp, s: long enough to be seen ramping by queries over the serial port
RAMP = 1.0


@pytest.fixture
def shaker(device: ShakerDevice) -> Iterator[ScpiShaker]:
    s = ScpiShaker("shaker", device.path, heartbeat=HEARTBEAT, ramp=RAMP)
    s.open()
    s.set_waveform("burst-random", f_start=5.0, f_stop=150.0, period=2.0, burst=0.6)
    s.set_level(1.0)
    yield s
    s.shutdown()


def levels_until(device: ShakerDevice, target: float) -> tuple[list[float], float]:
    """The device's output levels seen until it reaches ``target``, and the seconds taken."""
    seen: list[float] = []
    took = wait_for(lambda: seen.append(device.level_now) or seen[-1] == target)
    return seen, took


def test_output_ramps_up_and_down(device: ShakerDevice, shaker: ScpiShaker) -> None:
    assert (device.function, device.f_stop, device.duty) == ("BRAN", 150.0, 0.6)
    assert device.ramp == RAMP
    shaker.start()
    up, _ = levels_until(device, 1.0)
    assert any(0.1 < v < 0.9 for v in up) and up == sorted(up)  # seen ramping, not a step
    shaker.wait_ramp()
    assert device.level_now == 1.0 and shaker.output_level() == pytest.approx(1.0)
    shaker.stop()
    down, took = levels_until(device, 0.0)
    assert any(0.1 < v < 0.9 for v in down)  # ramps down, not a step
    assert down == sorted(down, reverse=True)
    assert took > 0.5 * RAMP  # (a loaded host only makes it longer)


def test_heartbeat_keeps_output_on(device: ShakerDevice, shaker: ScpiShaker) -> None:
    shaker.start()
    wait_for(lambda: device.heartbeats >= 8)  # two watchdog periods of heartbeats
    assert device.output and not device.errors


def test_output_off_when_heartbeats_stop(device: ShakerDevice, shaker: ScpiShaker) -> None:
    shaker.start()
    beats = device.heartbeats
    shaker._beat_stop.set()  # the application hangs: no more heartbeats
    took = wait_for(lambda: not device.output)
    assert device.errors == [101]  # the watchdog turned it off, nothing else
    assert took > 0.5 * HEARTBEAT and device.heartbeats <= beats + 1
    with pytest.raises(ShakerError, match="101 Heartbeat lost"):
        shaker.set_level(0.5)


def test_shutdown_turns_output_off(device: ShakerDevice, shaker: ScpiShaker) -> None:
    shaker.start()
    shaker.shutdown()
    assert wait_for(lambda: not device.output, 2.0) < 2.0  # the device thread takes it
    # the last command is not answered: give the device thread time to log it
    deadline = time.monotonic() + 5.0
    while device.commands[-1:] != ["SYST:HEART:TIM 0"] and time.monotonic() < deadline:
        time.sleep(0.005)
    assert device.commands[-2:] == ["OUTP OFF", "SYST:HEART:TIM 0"]


def test_amplifier_fault_is_reported(device: ShakerDevice, shaker: ScpiShaker) -> None:
    shaker.start()
    device.amplifier_fault()
    assert not device.output
    with pytest.raises(ShakerError) as info:
        shaker.set_level(0.8)
    assert info.value.code == 103


def test_silent_device_times_out(device: ShakerDevice, shaker: ScpiShaker) -> None:
    device.faults.silent = True
    with pytest.raises(DeviceTimeoutError, match=r"no reply within 0\.5 s"):  # reply_timeout
        shaker.set_level(0.3)
    device.faults.silent = False


def test_unplug_turns_output_off(device: ShakerDevice, shaker: ScpiShaker) -> None:
    shaker.start()
    device.unplug()
    assert not device.output and device.errors[-1] == 102
    with pytest.raises(DeviceNotAvailableError):
        shaker.set_level(0.3)


APP = """
import sys, time
from drivers.shaker_scpi import ScpiShaker
s = ScpiShaker("shaker", sys.argv[1], heartbeat=float(sys.argv[3]), ramp=0.0)
s.open()
s.set_waveform("sine", frequency=50.0)
s.set_level(0.5)
s.start()
print("on", flush=True)
if sys.argv[2] == "exit":
    sys.exit(0)  # no shutdown(): the atexit hook must turn the output off
time.sleep(30)
"""


@contextmanager
def run_app(path: str, mode: str) -> Iterator[subprocess.Popen[str]]:
    """The shaker driven by another process, which the test may end as it likes."""
    with subprocess.Popen([sys.executable, "-c", APP, path, mode, str(HEARTBEAT)],
                          stdout=subprocess.PIPE, text=True) as proc:
        try:
            assert proc.stdout is not None
            assert proc.stdout.readline() == "on\n"
            yield proc
        finally:
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
                os.kill(proc.pid, signal.SIGCONT)
            proc.wait(60)


def test_application_exit_turns_output_off(device: ShakerDevice) -> None:
    with run_app(device.path, "exit") as proc:
        assert proc.wait(60) == 0
    assert not device.output and "OUTP OFF" in device.commands and not device.errors


def test_application_killed_turns_output_off(device: ShakerDevice) -> None:
    with run_app(device.path, "sleep") as proc:
        assert device.output
        proc.kill()
        proc.wait(60)
        wait_for(lambda: not device.output)
    assert device.errors == [102]  # host gone: the port hung up


def test_application_frozen_turns_output_off(device: ShakerDevice) -> None:
    with run_app(device.path, "sleep") as proc:
        os.kill(proc.pid, signal.SIGSTOP)  # alive, port open, no heartbeats
        took = wait_for(lambda: not device.output)
        assert device.errors == [101]  # the watchdog, not a hung-up port
        assert took > 0.5 * HEARTBEAT  # (the last heartbeat came at most a quarter before)
