"""The simulated 33500, device side: literal SCPI lines over its TCP socket (no driver code),
its output as a force on the bench, and its faults (silent, error queued, connection dropped)."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
from numpy.testing import assert_allclose

from hardware_mocks.benches import get_bench
from hardware_mocks.generator_33500 import IDENTITY, Generator33500
from hardware_mocks.physics import BenchPhysics


def _line(sock: socket.socket, timeout: float = 5.0) -> bytes:
    sock.settimeout(timeout)
    out = b""
    while not out.endswith(b"\n"):
        chunk = sock.recv(1)
        if not chunk:
            return out
        out += chunk
    return out


@pytest.fixture
def gen():
    with Generator33500(BenchPhysics(get_bench("engine-rigid")), force_per_volt=40.0) as g:
        yield g


@pytest.fixture
def sock(gen: Generator33500):
    with socket.create_connection(("127.0.0.1", gen.port)) as s:
        yield s


def test_literal_exchange(gen: Generator33500, sock: socket.socket) -> None:
    sock.sendall(b"*IDN?\n")
    assert _line(sock) == IDENTITY.encode() + b"\n"
    sock.sendall(b"VOLT 30\nSYST:ERR?\n")  # beyond 10 Vpp into the default 50 ohm
    assert _line(sock) == b'-222,"Data out of range"\n'
    sock.sendall(b"BURS:STAT ON\nFUNC SQU\nDATA:VOL:CLE\nSYST:ERR?\nSYST:ERR?\nSYST:ERR?\n")
    assert _line(sock) == b'-113,"Undefined header"\n'
    assert _line(sock) == b'-224,"Illegal parameter value"\n'
    assert _line(sock) == b'+0,"No error"\n'
    sock.sendall(b"OUTP:LOAD INF\n:SOUR1:FUNC SIN\nFREQ 20\nVOLT:UNIT VPP\nVOLT 2\nOUTP ON\n"
                 b"OUTP?\nFUNC?\nVOLT?\nOUTP:LOAD?\nSYST:ERR?\n")
    assert [_line(sock) for _ in range(5)] == [b"1\n", b"SIN\n", b"+2.000000000E+00\n",
                                               b"9.9E+37\n", b'+0,"No error"\n']
    assert gen.output and gen.peak_volts() == 1.0


def test_an_uploaded_arbitrary_waveform_is_the_force_played_over_and_over(
        gen: Generator33500, sock: socket.socket) -> None:
    counts = np.round(32767 * np.sin(2 * np.pi * np.arange(100) / 100)).astype(int)
    sock.sendall(b"DATA:ARB:DAC INSITU," + ",".join(map(str, counts)).encode() + b"\n"
                 b"DATA:ARB:DAC INSITU,1,2,3,4,5,6,7,8\n"  # the name is taken
                 b"FUNC:ARB INSITU\nFUNC ARB\nFUNC:ARB:SRAT 1000\nVOLT 4\nOUTP ON\n"
                 b"DATA:VOL:CLE\nSYST:ERR?\nSYST:ERR?\nSYST:ERR?\n")
    assert _line(sock) == b'-221,"Settings conflict"\n'
    assert _line(sock) == b'-221,"Settings conflict"\n'  # the waveform playing
    assert _line(sock) == b'+0,"No error"\n'
    gen.attach(3)
    t = time.monotonic() + np.arange(0.0, 0.2, 0.001)
    f = gen.force(t)
    # a 10 Hz sine (100 samples at 1000 Sa/s) of 2 V peak, 40 N/V: 80 N peak, period 0.1 s
    assert np.abs(f).max() == pytest.approx(80.0, rel=1e-3)
    # the same samples a period later, to the host clock's resolution: the times are
    # seconds since boot, whose last bit (np.spacing) times the sine's steepest slope
    # (80 N x 2 pi x 10 Hz) bounds what t + 0.1 may round to
    slope = 80.0 * 2 * np.pi * 10.0
    assert_allclose(gen.force(t + 0.1), f, rtol=0, atol=8 * slope * np.spacing(t.max() + 0.1))
    assert gen.physics is not None and gen.physics.source_forces(t)[0][0] == 3


def test_noise_is_flat_to_its_bandwidth_at_the_rms_set(gen: Generator33500,
                                                       sock: socket.socket) -> None:
    sock.sendall(b"FUNC NOIS\nFUNC:NOIS:BAND 100\nVOLT:UNIT VRMS\nVOLT 0.5\nOUTP ON\n"
                 b"SYST:ERR?\n")
    assert _line(sock) == b'+0,"No error"\n'
    f = gen.force(time.monotonic() + np.arange(0.0, 16.0, 1 / 512))
    assert np.sqrt(np.mean(f**2)) == pytest.approx(0.5 * 40.0, rel=1e-6)
    spec = np.abs(np.fft.rfft(f)) ** 2
    freq = np.fft.rfftfreq(f.size, 1 / 512)
    assert spec[freq > 101].sum() < 1e-20 * spec.sum()


def test_no_force_before_the_output_came_on(gen: Generator33500, sock: socket.socket) -> None:
    """A front end started just before the output came on asks for its past: 0 N there (the
    generator has no ramp), the sine from the instant it switched on."""
    sock.sendall(b"FUNC SIN\nFREQ 20\nVOLT 2\nOUTP ON\nSYST:ERR?\n")
    assert _line(sock) == b'+0,"No error"\n'
    on = gen._on_since
    t = on + np.arange(-2.0, 0.5, 1 / 1024)
    f = gen.force(t)
    assert not np.any(f[t < on])
    assert_allclose(f[t >= on], 40.0 * np.sin(2 * np.pi * 20.0 * (t[t >= on] - gen._t_origin)))
    sock.sendall(b"OUTP ON\nSYST:ERR?\n")  # already on: the instant stays
    assert _line(sock) == b'+0,"No error"\n' and gen._on_since == on


def test_faults_silent_error_and_dropped_connection(gen: Generator33500,
                                                    sock: socket.socket) -> None:
    sock.sendall(b"OUTP ON\nOUTP?\n")
    assert _line(sock) == b"1\n"
    gen.silent = True
    sock.sendall(b"*IDN?\n")
    with pytest.raises(TimeoutError):
        _line(sock, timeout=0.3)
    gen.silent = False  # the command waited in the socket: answered now
    assert _line(sock).startswith(b"Keysight Technologies,33511B,")
    gen.push_error(-241, "Hardware missing")
    sock.sendall(b"SYST:ERR?\nOUTP?\n")
    assert _line(sock) == b'-241,"Hardware missing"\n'
    assert _line(sock) == b"1\n"  # no watchdog, no turning off on an error: the host does it
    gen.drop()
    assert _line(sock) == b""  # closed
    assert gen.output  # and the output stays on, as a real one's does
    with socket.create_connection(("127.0.0.1", gen.port)) as again:
        again.sendall(b"OUTP OFF\nOUTP?\n")
        assert _line(again) == b"0\n"
    assert gen.connections == 2
