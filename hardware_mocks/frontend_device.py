"""Simulated FE-16 accelerometer front end: the device side of its CAN protocol.

It listens on a python-can bus (``virtual`` by default, so driver and mock
share one process), answers commands, and streams sample frames paced by its
own :class:`~hardware_mocks.physics.DeviceClock`. Inputs are wired to the bench:
by default inputs 0..11 carry the 12 accelerometer DOFs of the bench and input
12 the force (the hammer's, plus the force sensor of a shaker attached to the
bench). What the inputs carry, hits and shakers on the shared :class:`BenchPhysics`
turned into the model's accelerations on the front end's own sample grid, is
:class:`hardware_mocks.input_signals.InputSignals`. An input wired to
``shaker_force(k)`` carries the force sensor of the shakers whose ``sensor`` is
``k`` only (two shakers driven at once, each with its own force sensor).

The frames are packed here with ``struct``/numpy, independently of the DBC and
of cantools, so a layout bug cannot pass on both sides.

Example
-------
>>> with FrontEndDevice(channel="bench") as dev:  # doctest: +SKIP
...     fe = CanFrontEnd("fe", chans, fs=1024, bus_kwargs={"interface": "virtual",
...                      "channel": "bench"})
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from dataclasses import dataclass
from types import TracebackType

import can
import numpy as np
from numpy.typing import NDArray

from hardware_mocks.benches import get_bench
from hardware_mocks.input_signals import FORCE, LOOKAHEAD, InputSignals, shaker_force
from hardware_mocks.physics import BenchPhysics, DeviceClock

__all__ = ["FORCE", "LOOKAHEAD", "FrontEndDevice", "FrontEndFaults", "shaker_force",
           "shaker_force_inputs"]

logger = logging.getLogger(__name__)

def shaker_force_inputs(shakers: int, suffix: str = "") -> list[tuple[str, int]]:
    """Channel name and wiring code of a mock bench's front-end force inputs.

    With one shaker, one input ``F{suffix}`` carries every force (:data:`FORCE`: the
    hammer's and the shaker's); with more, input ``k`` (from 0) is ``F{k+1}{suffix}``,
    shaker ``k``'s force sensor alone (:func:`shaker_force`).
    """
    if shakers < 1:
        raise ValueError(f"a bench has at least one shaker, not {shakers}")
    if shakers == 1:
        return [(f"F{suffix}", FORCE)]
    return [(f"F{k + 1}{suffix}", shaker_force(k)) for k in range(shakers)]


FULL = 8388607
RATES = (256, 512, 1024, 2048, 4096)
RANGES_MV = (1000, 5000, 10000)


@dataclass
class FrontEndFaults:
    """Faults the mock can inject; change them at any time.

    Attributes
    ----------
    drop_every : int
        Do not send every n-th sample frame.
    bad_frame_every : int
        Send every n-th sample frame truncated to 6 bytes (undecodable).
    seq_jump : int
        Add this to the sequence counter once (firmware gap).
    overflow : int
        Lose this many samples once inside the device, as a buffer overflow does:
        the counter jumps and the next status reports BUFFER_OVERFLOW.
    silent : bool
        Stop answering and streaming.
    """

    drop_every: int = 0
    bad_frame_every: int = 0
    seq_jump: int = 0
    overflow: int = 0
    silent: bool = False


class FrontEndDevice:
    """The front end as seen from the CAN bus.

    Parameters
    ----------
    physics : BenchPhysics, optional
        Shared bench (default: ``engine``).
    interface, channel : str
        python-can bus the device sits on.
    wiring : sequence of int
        Per input: index of the bench response DOF it measures, :data:`FORCE` (every
        force: hammer and shakers) or :func:`shaker_force` (one shaker's force sensor);
        inputs beyond the list are open. Default: DOFs 0..11 then the force.
    sensitivity : sequence of float
        Transducer sensitivities per input, mV/(m/s^2) or mV/N (default 10.2 and 2.25).
    accel_noise, force_noise : float
        Sensor noise, m/s^2 RMS and N RMS.
    ppm, offset : float
        Clock error and start delay, see :class:`DeviceClock`.
    tail : float, optional
        Length of each hit's computed response, s (default: until the model's
        impulse response has decayed to 1e-7 of its peak).
    source_block : float
        Continuous forces (shakers) are simulated this many seconds at a time.
    """

    N_INPUTS = 16

    def __init__(self, physics: BenchPhysics | None = None, *, interface: str = "virtual",
                 channel: str = "insitu-bench", wiring: list[int] | None = None,
                 sensitivity: list[float] | None = None, accel_noise: float = 0.0,
                 force_noise: float = 0.0, ppm: float = 0.0, offset: float = 0.0,
                 tail: float | None = None, seed: int = 0, serial_number: int = 4242,
                 source_block: float = 0.1) -> None:
        self.physics = physics if physics is not None else BenchPhysics(get_bench("engine"))
        self.wiring = [*range(12), FORCE] if wiring is None else list(wiring)
        if sensitivity is None:
            sensitivity = [2.25 if w < 0 else 10.2 for w in self.wiring]
        self.sensitivity = np.zeros(self.N_INPUTS)
        self.sensitivity[: len(sensitivity)] = sensitivity
        self.ppm = ppm
        self.offset = offset
        self.signals = InputSignals(self.physics, self.wiring, self.N_INPUTS,
                                    accel_noise=accel_noise, force_noise=force_noise,
                                    tail=tail, source_block=source_block, seed=seed)
        self.serial_number = serial_number
        self.faults = FrontEndFaults()
        self.rate = 1024
        self.fd = True
        self.group_mask = 0xF
        self.range_mv = np.full(self.N_INPUTS, 10000)
        self.iepe = np.ones(self.N_INPUTS, dtype=bool)
        self.running = False
        self.frames_sent = 0
        self.commands: list[bytes] = []
        self._bus = can.Bus(interface=interface, channel=channel, fd=True)
        self._clock = DeviceClock(self.rate)
        self._reset_stream()
        self._stop = threading.Event()
        self._unplugged = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mock-frontend", daemon=True)
        self._thread.start()

    def _reset_stream(self) -> None:
        self._produced = 0
        self._seq = 0
        self._frame_no = 0
        self._overload_mask = 0
        self._overflow_flag = False
        self._last_status = time.monotonic()

    @property
    def accel_noise(self) -> float:
        """Accelerometer noise, m/s^2 RMS."""
        return self.signals.accel_noise

    @property
    def force_noise(self) -> float:
        """Force sensor noise, N RMS."""
        return self.signals.force_noise

    @property
    def clock(self) -> DeviceClock:
        """The sample clock of the stream (started at the last START), which tests compare
        with what the host measured."""
        return self._clock

    def unplug(self) -> None:
        """Disconnect from the bus: no more frames, no more answers."""
        self._unplugged.set()

    def shutdown(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self._bus.shutdown()

    def __enter__(self) -> FrontEndDevice:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.shutdown()

    # -- firmware ---------------------------------------------------------------------------------
    def _send(self, arbitration_id: int, data: bytes, fd: bool = False) -> None:
        self._bus.send(can.Message(arbitration_id=arbitration_id, data=data, is_fd=fd,
                                   is_extended_id=False, bitrate_switch=fd))

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self._bus.recv(0.003 if self.running else 0.02)
            if self._unplugged.is_set() or self.faults.silent:
                continue
            if msg is not None and msg.arbitration_id == 0x100:
                self._command(bytes(msg.data))
            if self.running:
                # one instant for both: only samples whose shaker forces are simulated are
                # sent, however long the simulation took (a loaded host)
                due = self._clock.due()
                self.signals.advance(due)
                self._emit_due(due)
                if time.monotonic() - self._last_status >= 0.1:
                    self._status()

    def _ack(self, opcode: int, result: int) -> None:
        self._send(0x101, bytes([opcode, result, 0, 0, 0, 0, 0, 0]))

    def _status(self) -> None:
        flags = 1 if self._overflow_flag else 0
        data = struct.pack("<BBHI", 1 if self.running else 0, flags, self._overload_mask,
                           self._produced & 0xFFFFFFFF)
        self._send(0x110, data)
        self._overload_mask = 0
        self._overflow_flag = False
        self._last_status = time.monotonic()

    def _command(self, data: bytes) -> None:
        self.commands.append(data)
        if len(data) < 1:
            return
        op = data[0]
        if op == 6:  # IDENTIFY
            self._send(0x102, struct.pack("<IBBBB", self.serial_number, 2, 4, self.N_INPUTS, 0))
        elif op == 4:  # STOP
            self.running = False
            self._ack(op, 0)
        elif op == 5:  # STATUS_REQUEST
            self._status()
        elif op in (1, 2, 3) and self.running:
            self._ack(op, 2)
        elif op == 1:  # CONFIG_ACQ
            rate, fmt, mask = struct.unpack_from("<HBB", data, 1)
            if rate not in RATES or fmt > 1 or mask == 0:
                self._ack(op, 1)
                return
            self.rate, self.fd, self.group_mask = rate, bool(fmt), mask
            self._ack(op, 0)
        elif op == 2:  # CONFIG_CHANNEL
            ch, rng, iepe = struct.unpack_from("<BHB", data, 1)
            if ch >= self.N_INPUTS or rng not in RANGES_MV:
                self._ack(op, 1)
                return
            self.range_mv[ch], self.iepe[ch] = rng, bool(iepe & 1)
            self._ack(op, 0)
        elif op == 3:  # START
            clock = DeviceClock(self.rate, self.ppm, self.offset)
            self.physics.impulse_response(clock.true_rate, 0)  # computed once per rate
            self._ack(op, 0)
            self._clock = clock
            self._clock.start()
            self._reset_stream()
            self.signals.start(clock)
            self.running = True
        else:
            self._ack(op, 3)

    def _emit_due(self, due: int) -> None:
        """Send the whole frames of the samples before sample ``due``."""
        per_frame = 5 if self.fd else 1
        while due - self._produced >= per_frame:
            f = self.faults
            if f.overflow:  # samples lost inside the device
                lost = f.overflow - f.overflow % per_frame
                self.signals.take(lost)
                self._produced += lost
                self._seq += lost // per_frame
                self._overflow_flag = True
                f.overflow = 0
                continue
            if f.seq_jump:
                self._seq += f.seq_jump
                f.seq_jump = 0
            volts = self.signals.take(per_frame) * self.sensitivity[:, None] / 1000.0
            counts = np.round(volts / (self.range_mv[:, None] / 1000.0) * FULL).astype(np.int64)
            over = np.abs(counts) > FULL
            counts = np.clip(counts, -FULL, FULL)
            for i in np.flatnonzero(over.any(axis=1)):
                self._overload_mask |= 1 << int(i)
            if self.fd:
                self._send_fd(counts, over)
            else:
                self._send_classic(counts, over)
            self._produced += per_frame
            self._seq += 1

    def _deliver(self, arbitration_id: int, data: bytes, fd: bool) -> None:
        f = self.faults
        self._frame_no += 1
        if f.drop_every and self._frame_no % f.drop_every == 0:
            return
        if f.bad_frame_every and self._frame_no % f.bad_frame_every == 0:
            data = data[:6]
        self._send(arbitration_id, data, fd)
        self.frames_sent += 1

    @staticmethod
    def _int24(values: NDArray[np.int64]) -> bytes:
        """Little-endian 24-bit two's complement of each value, in order."""
        raw = (np.asarray(values, dtype=np.int64) & 0xFFFFFF).astype("<u4")
        return raw.view(np.uint8).reshape(-1, 4)[:, :3].tobytes()

    def _send_fd(self, counts: NDArray[np.int64], over: NDArray[np.bool_]) -> None:
        seq = self._seq & 0xFFFF
        for g in range(4):
            if not self.group_mask >> g & 1:
                continue
            rows = slice(4 * g, 4 * g + 4)
            ovl = sum(1 << j for j in range(4) if over[4 * g + j].any())
            # samples in time order, the group's 4 inputs within each sample
            payload = self._int24(counts[rows].T.reshape(-1))
            self._deliver(0x200, struct.pack("<HBB", seq, g, ovl) + payload, fd=True)

    def _send_classic(self, counts: NDArray[np.int64], over: NDArray[np.bool_]) -> None:
        seq = self._seq & 0x3FF
        for g in range(8):
            if not self.group_mask >> g & 1:
                continue
            a, b = 2 * g, 2 * g + 1
            head = seq | (int(over[a, 0]) << 10) | (int(over[b, 0]) << 11) | (g << 12)
            payload = self._int24(np.array([counts[a, 0], counts[b, 0]]))
            self._deliver(0x201, struct.pack("<H", head) + payload, fd=False)
