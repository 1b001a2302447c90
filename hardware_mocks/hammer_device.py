"""Simulated HD-1 hammer digitiser: the device side of the protocol on a pseudo-terminal.

It answers the ASCII commands and streams binary force frames paced by its own
:class:`~hardware_mocks.physics.DeviceClock`; the force comes from the hits
made on the shared :class:`~hardware_mocks.physics.BenchPhysics`. The framing
and the CRC here are written independently of ``drivers.hammer_serial`` so a
bug on one side cannot hide behind the same bug on the other.

Example
-------
>>> with HammerDevice() as dev:  # doctest: +SKIP
...     print(dev.path)  # open this with drivers.hammer_serial.SerialHammer
...     dev.hit(exc=0, peak=300.0)
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hardware_mocks.benches import get_bench
from hardware_mocks.physics import TIP_DURATION, TIP_PEAK, BenchPhysics, DeviceClock, Hit
from hardware_mocks.pty_port import PtyPort
from hardware_mocks.serial_device import SerialMockDevice

__all__ = ["HammerDevice", "HammerFaults", "crc16_ccitt_false"]


def _crc_table() -> list[int]:
    table = []
    for byte in range(256):
        reg = byte << 8
        for _ in range(8):
            reg = ((reg << 1) ^ 0x1021) if reg & 0x8000 else (reg << 1)
        table.append(reg & 0xFFFF)
    return table


_TABLE = _crc_table()


def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, MSB first, no final xor."""
    reg = 0xFFFF
    for b in data:
        reg = ((reg << 8) & 0xFFFF) ^ _TABLE[((reg >> 8) ^ b) & 0xFF]
    return reg


@dataclass
class HammerFaults:
    """Faults the mock can inject; change them at any time, also mid-run.

    Attributes
    ----------
    drop_every : int
        Do not send every n-th frame (the sequence counter still advances).
    corrupt_every : int
        Flip a sample bit in every n-th frame after its CRC was computed.
    seq_jump : int
        Add this to the sequence counter once, at the next frame (a firmware gap).
    garbage : bytes
        Bytes to send once between two frames (line noise).
    silent : bool
        Stop answering commands and stop streaming (a hung device).
    """

    drop_every: int = 0
    corrupt_every: int = 0
    seq_jump: int = 0
    garbage: bytes = b""
    silent: bool = False


class HammerDevice(SerialMockDevice):
    """The hammer and its digitiser, seen from the serial port.

    Parameters
    ----------
    physics : BenchPhysics, optional
        The shared bench (default: the ``engine`` bench alone).
    sensitivity : float
        The hammer's force transducer, mV/N.
    frame_len : int
        Samples per frame.
    noise : float
        Transducer noise, N RMS.
    ppm, offset : float
        Clock error (ppm) and start delay (s), see :class:`DeviceClock`.
    seed : int
        Noise seed.
    now : callable
        The host clock its sample clock runs on (``time.monotonic``; a test may stand it
        still or move it by hand).
    """

    RATES = (1024, 2048, 4096, 8192, 16384)
    RANGES_MV = (1000, 2500, 5000, 10000)

    def __init__(self, physics: BenchPhysics | None = None, *, sensitivity: float = 2.25,
                 frame_len: int = 64, noise: float = 0.0, ppm: float = 0.0, offset: float = 0.0,
                 seed: int = 0, serial_number: str = "0001",
                 now: Callable[[], float] = time.monotonic) -> None:
        self.physics = physics if physics is not None else BenchPhysics(get_bench("engine"))
        self.sensitivity = sensitivity
        self.frame_len = frame_len
        self.noise = noise
        self.ppm = ppm
        self.offset = offset
        self.serial_number = serial_number
        self._now = now
        self.faults = HammerFaults()
        self.rate = 4096
        self.range_mv = 5000
        self.width = 4
        self.iepe = True
        self.streaming = False
        self.frames_sent = 0
        self.commands: list[str] = []
        self._rng = np.random.default_rng(seed)
        self._port = PtyPort()
        self._clock = DeviceClock(self.rate)
        self._seq = 0
        self._produced = 0
        self._frame_no = 0
        self._rx = bytearray()
        self._start_firmware("mock-hammer")

    @property
    def clock(self) -> DeviceClock:
        """The sample clock of the stream (started at the last START), which tests compare
        with what the host measured."""
        return self._clock

    def hit(self, exc: int = 0, peak: float = TIP_PEAK, duration: float = TIP_DURATION,
            double: tuple[float, float] | None = None, delay: float = 0.05) -> list[Hit]:
        """Hit the bench at excitation DOF ``exc``; see :meth:`BenchPhysics.hit`."""
        return self.physics.hit(exc, peak, duration, delay, double)

    def __enter__(self) -> HammerDevice:
        return self

    # -- device firmware ---------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            if self._unplug.is_set() and not self._port.closed:
                self.streaming = False
                self._port.close()
            if self._port.closed:
                time.sleep(0.02)
                continue
            data = self._port.read(0.004 if self.streaming else 0.02)
            if self._port.hung_up:  # host closed the port
                self.streaming = False
                time.sleep(0.01)
                continue
            if self.faults.silent:
                continue
            self._rx += data
            while b"\n" in self._rx:
                line, _, rest = self._rx.partition(b"\n")
                self._rx = bytearray(rest)
                self._command(line.decode("ascii", "replace").strip())
            if self.streaming:
                self._emit_due()

    def _reply(self, text: str) -> None:
        self._port.write(text.encode("ascii") + b"\n")

    def _command(self, cmd: str) -> None:
        if not cmd:
            return
        self.commands.append(cmd)
        word, _, arg = cmd.partition(" ")
        if word == "ID?":
            self._reply(f"ID INSITU,HD-1,{self.serial_number},1.3")
        elif word == "STOP":
            if self.streaming:
                self.streaming = False
                self._send_frame(np.zeros(0, dtype=np.int64), end=True)
            self._reply("OK")
        elif self.streaming:
            self._reply("ERR 3 busy")
        elif word == "START":  # the clock started, then OK: the host's OK means it runs
            self._clock = DeviceClock(self.rate, self.ppm, self.offset)
            self._clock.start(self._now())
            self._seq = self._produced = self._frame_no = 0
            self.streaming = True
            self._reply("OK")
        elif word in ("RATE", "RANGE", "FMT", "IEPE"):
            self._setting(word, arg)
        elif word == "RATE?":
            self._reply(f"RATE {self.rate}")
        elif word == "RANGE?":
            self._reply(f"RANGE {self.range_mv}")
        else:
            self._reply("ERR 1 unknown command")

    def _setting(self, word: str, arg: str) -> None:
        allowed = {"RATE": self.RATES, "RANGE": self.RANGES_MV, "FMT": (16, 32),
                   "IEPE": (0, 1)}[word]
        try:
            value = int(arg)
        except ValueError:
            value = -1
        if value not in allowed:
            self._reply("ERR 2 bad value")
            return
        if word == "RATE":
            self.rate = value
        elif word == "RANGE":
            self.range_mv = value
        elif word == "FMT":
            self.width = value // 8
        else:
            self.iepe = bool(value)
        self._reply("OK")

    def _emit_due(self) -> None:
        due = self._clock.due(self._now())
        while due - self._produced >= self.frame_len:
            n = self.frame_len
            t = self._clock.instants(self._produced, n)
            force = self.physics.force(t, 1.0 / self._clock.true_rate)
            if self.noise:
                force = force + self.noise * self._rng.standard_normal(n)
            full = 32767 if self.width == 2 else 8388607
            counts = np.round(force * self.sensitivity / self.range_mv * full).astype(np.int64)
            over = bool(np.any(np.abs(counts) > full))
            self._send_frame(np.clip(counts, -full, full), overload=over)
            self._produced += n

    def _send_frame(self, counts: np.ndarray, *, overload: bool = False, end: bool = False) -> None:
        f = self.faults
        self._frame_no += 1
        if f.seq_jump:
            self._seq = (self._seq + f.seq_jump) & 0xFFFF
            f.seq_jump = 0
        flags = (1 if self.width == 4 else 0) | (2 if overload else 0) | (0x80 if end else 0)
        body = bytes([flags, 0]) + self._seq.to_bytes(2, "little") + len(counts).to_bytes(
            2, "little") + counts.astype("<i4" if self.width == 4 else "<i2").tobytes()
        frame = bytearray(b"\xa5\x5a" + body + crc16_ccitt_false(body).to_bytes(2, "little"))
        self._seq = (self._seq + 1) & 0xFFFF
        if not end and f.drop_every and self._frame_no % f.drop_every == 0:
            return
        if not end and f.corrupt_every and self._frame_no % f.corrupt_every == 0 and counts.size:
            frame[9] ^= 0x10
        if f.garbage:
            frame[:0] = f.garbage
            f.garbage = b""
        if self._port.write(bytes(frame)):
            self.frames_sent += 1
