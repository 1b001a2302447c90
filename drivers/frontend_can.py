"""Accelerometer front end on CAN / CAN FD (model "FE-16"), decoded with cantools.

Sixteen IEPE inputs digitised at 24 bits. The messages are described in
``drivers/dbc/insitu_frontend.dbc`` (the single source of truth for the
layout, see ``docs/protocols.md``):

=======  ================  ==========================================================
id       name              content
=======  ================  ==========================================================
0x100    FE_CMD            host command, multiplexed by OPCODE
0x101    FE_ACK            answer to every command (opcode, result)
0x102    FE_INFO           identity: serial number, firmware, number of inputs
0x110    FE_STATUS         state, buffer overflow, overload mask, sample count (10 Hz)
0x200    FE_SAMPLES_FD     CAN FD, 64 bytes: 5 samples x 4 inputs of one group
0x201    FE_SAMPLES        classic CAN, 8 bytes: 1 sample x 2 inputs of one group
=======  ================  ==========================================================

The transport is any ``can.BusABC`` (socketcan, pcan, kvaser, vector,
virtual, socketcand...), injected or built from the station file. A reader
thread decodes the frames; if it dies its error is raised by the next read.

Example
-------
>>> fe = CanFrontEnd("fe", channels, fs=1024, bus=can.Bus(interface="socketcan",
...                  channel="can0", fd=True))  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import queue
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib.resources import files
from typing import Any, ClassVar

import can
import cantools
import numpy as np
from cantools.database.can import Database
from cantools.database.namedsignalvalue import NamedSignalValue

from drivers.base import TIMING_SCATTER, ChannelConfig, StreamHealth, StreamingFrontEnd
from drivers.errors import (
    DeviceError,
    DeviceInitializationError,
    DeviceTimeoutError,
    ProtocolError,
)
from drivers.station import CanTransportConfig, DeviceConfig
from drivers.stream import ReaderThread
from drivers.transports import CanLink

__all__ = ["FULL_SCALE", "CanFrontEnd", "FrameLayout", "load_dbc"]

logger = logging.getLogger(__name__)

FULL_SCALE = 8388607
OPCODES = {"CONFIG_ACQ": 1, "CONFIG_CHANNEL": 2, "START": 3, "STOP": 4, "STATUS_REQUEST": 5,
           "IDENTIFY": 6}
RESULTS = {0: "ok", 1: "bad parameter", 2: "busy", 3: "unknown opcode"}
ID_CMD, ID_ACK, ID_INFO, ID_STATUS, ID_FD, ID_CLASSIC = 0x100, 0x101, 0x102, 0x110, 0x200, 0x201


def load_dbc() -> Database:
    """The front end's message database, from the DBC file shipped with the package."""
    text = files("drivers").joinpath("dbc/insitu_frontend.dbc").read_text(encoding="ascii")
    db = cantools.database.load_string(text, database_format="dbc")
    assert isinstance(db, Database)
    return db


class FrameLayout:
    """How sample frames carry samples: per frame, ``samples`` x ``per_group`` inputs."""

    def __init__(self, fd: bool) -> None:
        self.fd = fd
        self.frame_id = ID_FD if fd else ID_CLASSIC
        self.samples = 5 if fd else 1
        self.per_group = 4 if fd else 2
        self.seq_modulo = 65536 if fd else 1024
        self.signals = [[f"S{k}C{j}" for j in range(self.per_group)] for k in range(self.samples)]


def _as_int(value: int | float | str | NamedSignalValue) -> int:
    """One decoded signal as an integer (a named value by its number)."""
    return int(value.value if isinstance(value, NamedSignalValue) else value)


@dataclass
class _Assembly:
    """The sample block being assembled from its groups' frames."""

    counts: np.ndarray  # (n_inputs, samples) raw counts
    current: int | None = None  # sequence number of the block being assembled
    got: set[int] = field(default_factory=set)  # groups received
    ovl: set[int] = field(default_factory=set)  # inputs flagged overloaded
    pending: bool = False  # a block is being assembled and not yet handed over


class CanFrontEnd(StreamingFrontEnd):
    """Driver of the FE-16 CAN accelerometer front end.

    Parameters
    ----------
    name : str
    channels : sequence of ChannelConfig
        Inputs 0..15; ``range_v`` one of 1, 5, 10 V.
    fs : float
        Sampling rate, Hz: one of :attr:`supported_rates`.
    bus : can.BusABC, optional
        An open bus to use (not shut down by the driver). Otherwise ``bus_kwargs``
        are passed to ``can.Bus`` at ``open()``.
    frame : {"fd", "classic"}
        CAN FD 64-byte sample frames or classic 8-byte ones.
    reply_timeout, stall_timeout : float
        Seconds to wait for a command's answer; seconds without any frame after
        which a read raises DeviceTimeoutError.
    timing_scatter : float
        Largest scatter of the frames' arrival times, s, with which the clock counts as
        measured (:class:`~drivers.base.StreamingFrontEnd`).
    """

    supported_rates: ClassVar[tuple[float, ...]] = (256.0, 512.0, 1024.0, 2048.0, 4096.0)
    ranges_mv: ClassVar[tuple[int, ...]] = (1000, 5000, 10000)
    n_inputs: ClassVar[int] = 16

    def __init__(self, name: str, channels: Sequence[ChannelConfig], fs: float, *,
                 bus: can.BusABC | None = None, bus_kwargs: dict[str, Any] | None = None,
                 frame: str = "fd", reply_timeout: float = 0.5,
                 stall_timeout: float = 0.5, timing_scatter: float = TIMING_SCATTER) -> None:
        super().__init__(name, channels, fs, stall_timeout=stall_timeout,
                         timing_scatter=timing_scatter)
        if frame not in ("fd", "classic"):
            raise ValueError(f"{name}: frame must be 'fd' or 'classic', got {frame!r}")
        for ch in self.channels:
            if round(ch.range_v * 1000) not in self.ranges_mv:
                raise ValueError(f"{name}: channel {ch.name!r} range {ch.range_v} V not "
                                 f"supported; choose 1, 5 or 10 V")
        self.layout = FrameLayout(frame == "fd")
        self.reply_timeout = reply_timeout
        self.db = load_dbc()
        self._msg_cmd = self.db.get_message_by_frame_id(ID_CMD)
        self._decoders = {m.frame_id: m for m in self.db.messages}
        self._link = CanLink(bus, name, **(bus_kwargs or {}))
        self._groups = sorted({ch.input // self.layout.per_group for ch in self.channels})
        self._rows = np.array([ch.input for ch in self.channels])
        self._scale = np.array([ch.range_v / FULL_SCALE * 1000.0 / ch.sensitivity
                                for ch in self.channels])
        self._acks: queue.Queue[tuple[int, int]] = queue.Queue()
        self._reader = ReaderThread(name)
        self.serial_number = 0
        self.last_status: dict[str, int] = {}
        self._n_status = 0  # FE_STATUS frames received in this stream

    @classmethod
    def from_config(cls, config: DeviceConfig, **overrides: Any) -> CanFrontEnd:
        if not isinstance(config.transport, CanTransportConfig):
            raise ValueError(f"device {config.name!r}: frontend-can needs a CAN interface")
        opts: dict[str, Any] = {"bus_kwargs": config.transport.bus_kwargs(), **config.options,
                                **overrides}
        return cls(config.name, config.channels, config.fs or 1024.0, **opts)

    def decode(self, frame_id: int, data: bytes | bytearray, scaling: bool = True
               ) -> dict[str, int]:
        """Signals of one received frame, decoded with cantools (raw integers)."""
        decoded = self._decoders[frame_id].decode(bytes(data), decode_choices=False,
                                                  scaling=scaling)
        if not isinstance(decoded, dict):
            raise ProtocolError(f"{self.name}: frame {frame_id:#x} is a container", self.name)
        return {k: _as_int(v) for k, v in decoded.items()}

    # -- commands ---------------------------------------------------------------------------------
    def encode_command(self, opcode: str, **fields: int) -> bytes:
        """The 8 data bytes of an FE_CMD message."""
        return bytes(self._msg_cmd.encode({"OPCODE": OPCODES[opcode], **fields}, strict=True))

    def _send(self, opcode: str, **fields: int) -> None:
        data = self.encode_command(opcode, **fields)
        self._link.send(can.Message(arbitration_id=ID_CMD, data=data, is_extended_id=False))

    def command(self, opcode: str, **fields: int) -> None:
        """Send a command and wait for its FE_ACK; a refusal raises."""
        while not self._acks.empty():
            self._acks.get_nowait()
        self._send(opcode, **fields)
        deadline = time.monotonic() + self.reply_timeout
        while True:
            # what has arrived is taken before the time is looked at (a loaded host)
            remaining = max(deadline - time.monotonic(), 0.0)
            ack = self._next_ack(remaining)
            if ack is None:
                if time.monotonic() >= deadline:
                    raise DeviceTimeoutError(f"{self.name}: no answer to {opcode} within "
                                             f"{self.reply_timeout:g} s", self.name)
                continue
            ack_op, result = ack
            if ack_op != OPCODES[opcode]:
                continue
            if result != 0:
                raise DeviceInitializationError(
                    f"{self.name}: {opcode} {fields} refused: {RESULTS.get(result, result)}",
                    self.name)
            return

    def _next_ack(self, timeout: float) -> tuple[int, int] | None:
        """The next FE_ACK (opcode, result) within ``timeout`` s, from the reader thread's
        queue while it runs, else from the bus; None if none came."""
        if self._reader.is_alive():
            try:
                return self._acks.get(timeout=timeout)
            except queue.Empty:
                return None
        msg = self._link.recv(min(timeout, 0.05))
        if msg is None or msg.arbitration_id != ID_ACK:
            return None
        return msg.data[0], msg.data[1]

    def _identify(self) -> dict[str, int]:
        self._send("IDENTIFY")
        deadline = time.monotonic() + self.reply_timeout
        while True:  # what has arrived is read before the time is looked at
            msg = self._link.recv(0.05)
            if msg is not None and msg.arbitration_id == ID_INFO:
                return self.decode(ID_INFO, msg.data)
            if time.monotonic() >= deadline:
                raise DeviceTimeoutError(f"{self.name}: no FE_INFO answer to IDENTIFY within "
                                         f"{self.reply_timeout:g} s", self.name)

    def _open_internal(self) -> None:
        self._link.open()
        try:
            info = self._identify()
            self.serial_number = int(info["SERIAL"])
            self.identity = (f"INSITU,FE-{info['N_INPUTS']},{self.serial_number},"
                             f"{info['FW_MAJOR']}.{info['FW_MINOR']}")
            if int(info["N_INPUTS"]) < max(int(r) for r in self._rows) + 1:
                raise DeviceInitializationError(
                    f"{self.name}: device has {info['N_INPUTS']} inputs", self.name)
            self.command("STOP")
            self.command("CONFIG_ACQ", RATE_HZ=int(self.fs), FRAME_FORMAT=int(self.layout.fd),
                         GROUP_MASK=sum(1 << g for g in self._groups))
            for ch in self.channels:
                self.command("CONFIG_CHANNEL", CHANNEL=ch.input,
                             RANGE_MV=round(ch.range_v * 1000), IEPE=int(ch.iepe))
        except BaseException:
            self._link.close()
            raise

    def _start_internal(self) -> None:
        self.health = StreamHealth()
        self._buffer.reset()
        self.command("START")
        self._reader.start(self._read_loop)

    def _stop_internal(self) -> None:
        try:
            self.command("STOP")
        finally:
            self._reader.join()

    def _shutdown_internal(self) -> None:
        self._reader.join()
        self._link.close()

    def request_status(self) -> dict[str, int]:
        """Ask for an FE_STATUS now and return it (while running)."""
        before = self.last_status.get("_n", 0)
        self._send("STATUS_REQUEST")
        deadline = time.monotonic() + self.reply_timeout
        while self.last_status.get("_n", 0) == before:
            if time.monotonic() > deadline:
                raise DeviceTimeoutError(f"{self.name}: no status", self.name)
            time.sleep(0.005)
        return self.last_status

    # -- streaming --------------------------------------------------------------------------------
    def _read_loop(self) -> None:
        try:
            self._stream()
        except DeviceError as err:
            self._buffer.fail(err)
        except Exception as err:  # never die silently (see PITFALLS.md on Notifier threads)
            logger.exception("%s: reader thread failed", self.name)
            self._buffer.fail(err)

    def _stream(self) -> None:
        """Dispatch received frames until the reader is asked to stop."""
        block = _Assembly(np.zeros((self.n_inputs, self.layout.samples)))
        self._n_status = 0
        while not self._reader.stopping:
            t_poll = time.monotonic()
            msg = self._link.recv(0.05)
            if msg is not None:
                t_rx = time.monotonic()
                fid = msg.arbitration_id
                if fid == ID_ACK:
                    self._on_ack(msg)
                elif fid == ID_STATUS:
                    self._on_status(msg)
                elif fid == self.layout.frame_id:
                    self._on_samples(msg, t_rx, block)
            self._buffer.polled(t_poll)

    def _on_ack(self, msg: can.Message) -> None:
        """Queue an FE_ACK for :meth:`command`."""
        if len(msg.data) < 2:  # a damaged answer: the command then times out
            self.health.bad_frames += 1
            return
        self._acks.put((msg.data[0], msg.data[1]))
        self._buffer.touch()

    def _on_status(self, msg: can.Message) -> None:
        """Keep an FE_STATUS as :attr:`last_status`; count a device buffer overflow."""
        try:
            status = self.decode(ID_STATUS, msg.data)
        except (cantools.database.DecodeError, ProtocolError, ValueError) as err:
            self.health.bad_frames += 1
            logger.debug("%s: bad status frame %s: %s", self.name, msg.data.hex(), err)
            return
        self._n_status += 1
        status["_n"] = self._n_status
        self.last_status = status
        if status["BUFFER_OVERFLOW"]:
            self.health.buffer_overflows += 1
            logger.warning("%s: device buffer overflow (samples lost)", self.name)
        self._buffer.touch()

    def _decode_samples(self, msg: can.Message) -> tuple[dict[str, int], int, int] | None:
        """A sample frame's signals, group and sequence number; None (counted) if it is bad."""
        try:
            sig = self.decode(msg.arbitration_id, msg.data, scaling=False)
            group, seq = int(sig["GROUP"]), int(sig["SEQ"])
            if group not in self._groups:
                raise ProtocolError(f"{self.name}: frame for group {group} not requested",
                                    self.name)
        except (cantools.database.DecodeError, ProtocolError, KeyError, ValueError) as err:
            self.health.bad_frames += 1
            logger.debug("%s: bad sample frame %s: %s", self.name, msg.data.hex(), err)
            return None
        return sig, group, seq

    def _on_samples(self, msg: can.Message, t_rx: float, block: _Assembly) -> None:
        """Add a sample frame to the block it belongs to; hand the block over once complete."""
        decoded = self._decode_samples(msg)
        if decoded is None:
            return
        sig, group, seq = decoded
        self.health.frames += 1
        if seq != block.current:
            self._begin_block(block, seq, t_rx)
        elif not block.pending or group in block.got:
            self.health.bad_frames += 1  # duplicate frame
            return
        lay = self.layout
        base = group * lay.per_group
        for k, names in enumerate(lay.signals):
            for j, s in enumerate(names):
                block.counts[base + j, k] = sig[s]
        for j in range(lay.per_group):
            if sig[f"OVL{j}"]:
                block.ovl.add(base + j)
        block.got.add(group)
        if len(block.got) == len(self._groups):
            self._flush(block, t_rx)
            block.pending = False

    def _begin_block(self, block: _Assembly, seq: int, t_rx: float) -> None:
        """Start block ``seq``: hand over an unfinished one, count the blocks skipped."""
        if block.pending:
            self._flush(block, t_rx)  # the block lost some of its frames
        if block.current is not None:
            lost = (seq - block.current - 1) % self.layout.seq_modulo
            if lost:
                self.health.gaps += 1
                self.health.lost_samples += lost * self.layout.samples
                self._buffer.append_missing(lost * self.layout.samples)
        block.current = seq
        block.got.clear()
        block.ovl.clear()
        block.counts[:] = 0.0
        block.pending = True

    def _flush(self, block: _Assembly, t_rx: float) -> None:
        """Scale the block to physical units and append it; a missing group's rows are NaN."""
        lay = self.layout
        missing_groups = set(self._groups) - block.got
        data = block.counts[self._rows] * self._scale[:, None]
        if missing_groups:
            for g in missing_groups:
                data[(self._rows // lay.per_group) == g] = np.nan
            self.health.lost_samples += lay.samples
            self.health.gaps += 1
            logger.debug("%s: block %s lost group(s) %s", self.name, block.current,
                           sorted(missing_groups))
        rows = frozenset(i for i, r in enumerate(self._rows) if int(r) in block.ovl)
        for i in rows:
            self.health.overloaded.add(self.channels[i].name)
        self._buffer.append(data, t_rx, rows)
