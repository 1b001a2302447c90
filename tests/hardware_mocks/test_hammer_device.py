"""The simulated hammer digitiser, talked to with raw bytes (no driver code)."""

from __future__ import annotations

import binascii
import os
import select
import struct
import time
from collections.abc import Callable

import numpy as np
import pytest
import serial

from hardware_mocks.hammer_device import HammerDevice, crc16_ccitt_false

FRAME = bytes.fromhex("a5 5a 01 00")  # the start of a 32-bit sample frame


END = bytes.fromhex("a5 5a 80 00")  # the start of the 16-bit end-of-stream frame


def read_until(port: serial.Serial, done: Callable[[bytes], bool]) -> bytes:
    """What the device sends until ``done(received)``; 30 s only guard against a hang."""
    out = b""
    deadline = time.monotonic() + 30.0
    while not done(out):
        assert time.monotonic() < deadline, f"not done after 30 s: {out[-200:]!r}"
        out += port.read(max(1, port.in_waiting))
    return out


@pytest.fixture
def device(engine_physics_factory):
    dev = HammerDevice(engine_physics_factory(), frame_len=4)
    yield dev
    dev.shutdown()


@pytest.fixture
def port(device: HammerDevice):
    p = serial.Serial(device.path, timeout=0.05)
    yield p
    p.close()


def test_mock_crc_matches_the_standard_check_value() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(bytes.fromhex("81 00 02 00 00 00")) == 0x72F8


def test_identity_and_settings(port: serial.Serial) -> None:
    port.write(b"ID?\n")
    assert port.read_until(b"\n") == b"ID INSITU,HD-1,0001,1.3\n"
    port.write(b"RATE 2048\n")
    assert port.read_until(b"\n") == b"OK\n"
    port.write(b"RATE?\n")
    assert port.read_until(b"\n") == b"RATE 2048\n"
    port.write(b"RATE 2000\n")
    assert port.read_until(b"\n") == b"ERR 2 bad value\n"
    port.write(b"FIRE\n")
    assert port.read_until(b"\n") == b"ERR 1 unknown command\n"


def test_stream_frames_have_the_documented_layout(port: serial.Serial) -> None:
    port.write(b"FMT 16\nRATE 1024\nSTART\n")
    assert port.read_until(b"\n") + port.read_until(b"\n") + port.read_until(b"\n") == \
        b"OK\nOK\nOK\n"
    data = read_until(port, lambda got: len(got) >= 24)  # two frames and more
    # frame 0: sync, flags 0 (int16), reserved, seq 0, n = 4, 4 x int16, CRC
    assert data[:8] == bytes.fromhex("a5 5a 00 00 00 00 04 00")
    frame = data[:8 + 8 + 2]
    assert struct.unpack("<4h", frame[8:16]) == (0, 0, 0, 0)  # no hit yet, no noise
    assert int.from_bytes(frame[-2:], "little") == binascii.crc_hqx(frame[2:-2], 0xFFFF)
    assert data[18:24] == bytes.fromhex("a5 5a 00 00 01 00")  # next frame: seq 1
    port.write(b"RATE 2048\n")  # settings are refused while streaming
    port.write(b"STOP\n")
    tail = read_until(port, lambda got: END in got and got.endswith(b"OK\n"))
    assert b"ERR 3 busy\n" in tail
    end = tail.index(END)
    assert tail[end + 6:end + 8] == b"\x00\x00"  # n = 0
    assert tail.endswith(b"OK\n")


def test_frames_are_paced_by_the_device_clock(engine_physics_factory) -> None:
    """The device sends a frame once its samples are due on its own clock, and not before:
    with that clock standing still, half a second of it at 1024 Hz is 128 frames of 4."""
    host = [100.0]
    dev = HammerDevice(engine_physics_factory(), frame_len=4, now=lambda: host[0])
    try:
        with serial.Serial(dev.path, timeout=0.05) as port:
            port.write(b"RATE 1024\nSTART\n")
            assert port.read_until(b"\n") + port.read_until(b"\n") == b"OK\nOK\n"
            host[0] += 0.5  # samples 0..512 are due: 128 whole frames
            data = b""
            deadline = time.monotonic() + 30.0  # only guards against a hang
            while data.count(FRAME) < 128 and time.monotonic() < deadline:
                data += port.read(max(1, port.in_waiting))
            port.write(b"STOP\n")  # the end frame follows whatever the device sent
            data += port.read_until(b"OK\n")
    finally:
        dev.shutdown()
    assert data.endswith(b"OK\n")
    frames = data[:data.index(bytes.fromhex("a5 5a 81 00"))]  # up to the end-of-stream frame
    assert frames.count(FRAME) == 128 and dev.frames_sent == 128 + 1  # and the end frame


def test_host_closing_the_port_stops_the_stream(device: HammerDevice) -> None:
    p = serial.Serial(device.path, timeout=0.05)
    p.write(b"START\n")
    assert p.read_until(b"\n") == b"OK\n"
    p.close()
    deadline = time.monotonic() + 1.0
    while device.streaming and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not device.streaming


def test_unplug_removes_the_port(device: HammerDevice) -> None:
    path = device.path
    device.unplug()
    with pytest.raises(serial.SerialException):
        serial.Serial(path, timeout=0.05)


def test_raw_pty_has_no_echo(device: HammerDevice) -> None:
    fd = os.open(device.path, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(fd, b"ID?\n")
        got = b""
        while not got.endswith(b"\n"):  # the answer, however it comes in pieces
            r, _, _ = select.select([fd], [], [], 30.0)  # only guards against a hang
            assert r, got
            got += os.read(fd, 100)
        assert got == b"ID INSITU,HD-1,0001,1.3\n"  # no echo of the command before it
    finally:
        os.close(fd)


def test_hit_force_follows_the_half_sine(device: HammerDevice) -> None:
    t = np.arange(0.0, 0.02, 1 / 16384)
    hits = device.hit(exc=0, peak=250.0, duration=0.004, delay=0.0)
    f = device.physics.force(hits[0].t0 + t, 1 / 16384)
    assert abs(f.max() - 250.0) < 1.0
    assert np.sum(f) / 16384 == pytest.approx(2 * 250.0 * 0.004 / np.pi, rel=1e-3)
