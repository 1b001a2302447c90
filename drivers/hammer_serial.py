"""Impact hammer with its own digitiser on a serial port (protocol "HD-1").

ASCII commands, one per line (LF-terminated), each answered by one line:
``ID?``, ``RATE <Hz>``, ``RANGE <mV>``, ``IEPE 0|1``, ``FMT 16|32``, ``START``,
``STOP``. After ``START`` the device streams binary frames::

    offset size  field
    0      2     sync word A5 5A
    2      1     flags: bit0 int32 samples (else int16), bit1 overload, bit7 end of stream
    3      1     reserved, 0
    4      2     sequence counter, uint16 LE, +1 per frame, wraps
    6      2     n, number of samples, uint16 LE (0 in the end-of-stream frame)
    8      w*n   samples, signed LE, w = 2 or 4 bytes
    8+w*n  2     CRC-16/CCITT-FALSE of bytes 2 .. 8+w*n-1, uint16 LE

Full scale is 32767 counts (int16) or 8388607 counts (int32, a 24-bit ADC) at
the configured range. ``STOP`` is answered by an end-of-stream frame then
``OK``. See ``docs/protocols.md``.

Example
-------
>>> ch = ChannelConfig("F", 0, "force", sensitivity=2.25, range_v=5.0, node=101)
>>> hammer = SerialHammer("hammer", "/dev/ttyUSB0", [ch], fs=4096)  # doctest: +SKIP
>>> with hammer:  # doctest: +SKIP
...     hammer.start()
...     block = hammer.read_block(4096, timeout=2.0)
"""

from __future__ import annotations

import binascii
import logging
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from drivers.base import TIMING_SCATTER, ChannelConfig, StreamHealth, StreamingFrontEnd
from drivers.errors import (
    DeviceError,
    DeviceInitializationError,
    DeviceTimeoutError,
    ProtocolError,
)
from drivers.station import DeviceConfig, SerialTransportConfig
from drivers.stream import ReaderThread
from drivers.transports import SerialLink

__all__ = ["FULL_SCALE", "HammerFrame", "SerialHammer", "decode_frames", "encode_command"]

logger = logging.getLogger(__name__)

SYNC = b"\xa5\x5a"
HEADER = struct.Struct("<2sBBHH")  # sync, flags, reserved, seq, n
FLAG_INT32 = 0x01
FLAG_OVERLOAD = 0x02
FLAG_END = 0x80
#: counts at full scale for each sample width in bytes
FULL_SCALE = {2: 32767, 4: 8388607}
MAX_SAMPLES = 1024
IDENTITY_PREFIX = "ID INSITU,HD-1,"


def encode_command(command: str) -> bytes:
    """The bytes of one ASCII command: the text and LF."""
    if "\n" in command or "\r" in command:
        raise ValueError("a command is one line")
    return command.encode("ascii") + b"\n"


@dataclass(frozen=True)
class HammerFrame:
    seq: int
    flags: int
    counts: np.ndarray

    @property
    def end(self) -> bool:
        return bool(self.flags & FLAG_END)

    @property
    def overload(self) -> bool:
        return bool(self.flags & FLAG_OVERLOAD)


def decode_frames(buf: bytearray) -> tuple[list[HammerFrame], int, int]:
    """Take every complete frame off the front of ``buf`` (modified in place).

    Returns ``(frames, bad, skipped)``: frames with a valid CRC, the number of
    frames rejected (bad CRC or impossible header) and bytes skipped while
    looking for the sync word. Incomplete trailing bytes stay in ``buf``, and so
    does everything after an end-of-stream frame.
    """
    frames: list[HammerFrame] = []
    bad = skipped = 0
    while True:
        i = buf.find(SYNC)
        if i < 0:
            keep = 1 if buf.endswith(SYNC[:1]) else 0
            skipped += len(buf) - keep
            del buf[: len(buf) - keep]
            return frames, bad, skipped
        if i:
            skipped += i
            del buf[:i]
        if len(buf) < HEADER.size:
            return frames, bad, skipped
        _, flags, _, seq, n = HEADER.unpack_from(buf)
        width = 4 if flags & FLAG_INT32 else 2
        if n > MAX_SAMPLES:
            bad += 1
            del buf[:1]
            continue
        size = HEADER.size + width * n + 2
        if len(buf) < size:
            return frames, bad, skipped
        (crc,) = struct.unpack_from("<H", buf, size - 2)
        if binascii.crc_hqx(bytes(buf[2 : size - 2]), 0xFFFF) != crc:
            bad += 1
            del buf[:1]  # resynchronise on the next sync word
            continue
        counts = np.frombuffer(bytes(buf[HEADER.size : size - 2]), dtype=f"<i{width}")
        frames.append(HammerFrame(seq, flags, counts.astype(np.int64)))
        del buf[:size]
        if flags & FLAG_END:  # what follows is ASCII again
            return frames, bad, skipped


class SerialHammer(StreamingFrontEnd):
    """Driver of the HD-1 hammer digitiser.

    Parameters
    ----------
    name : str
    url : str
        Serial port or pyserial URL (a pseudo-terminal path works).
    channels : one ChannelConfig
        The hammer's force channel on input 0; its ``range_v`` selects the range.
    fs : float
        Sampling rate, Hz: one of :attr:`supported_rates`.
    baudrate : int
    sample_width : {16, 32}
        Bits per sample on the wire.
    reply_timeout : float
        Seconds to wait for a command's reply.
    stall_timeout : float
        Seconds without any frame after which a read raises DeviceTimeoutError.
    timing_scatter : float
        Largest scatter of the frames' arrival times, s, with which the clock counts as
        measured (:class:`~drivers.base.StreamingFrontEnd`).
    """

    supported_rates: ClassVar[tuple[float, ...]] = (1024.0, 2048.0, 4096.0, 8192.0, 16384.0)
    ranges_mv: ClassVar[tuple[int, ...]] = (1000, 2500, 5000, 10000)
    n_inputs: ClassVar[int] = 1

    def __init__(self, name: str, url: str, channels: Sequence[ChannelConfig], fs: float, *,
                 baudrate: int = 921600, sample_width: int = 32, reply_timeout: float = 0.5,
                 stall_timeout: float = 0.5, timing_scatter: float = TIMING_SCATTER) -> None:
        super().__init__(name, channels, fs, stall_timeout=stall_timeout,
                         timing_scatter=timing_scatter)
        if sample_width not in (16, 32):
            raise ValueError(f"{name}: sample_width must be 16 or 32, got {sample_width}")
        range_mv = round(self.channels[0].range_v * 1000)
        if range_mv not in self.ranges_mv:
            raise ValueError(f"{name}: range {self.channels[0].range_v} V not supported; choose "
                             f"one of {', '.join(str(r / 1000) for r in self.ranges_mv)} V")
        self._range_mv = range_mv
        self.sample_width = sample_width
        self.reply_timeout = reply_timeout
        self._link = SerialLink(url, baudrate, name)
        self._reader = ReaderThread(name)
        self._ended = threading.Event()
        self._leftover = bytearray()
        self._scale = self.channels[0].range_v / FULL_SCALE[sample_width // 8] * (
            1000.0 / self.channels[0].sensitivity)

    @classmethod
    def from_config(cls, config: DeviceConfig, **overrides: Any) -> SerialHammer:
        if not isinstance(config.transport, SerialTransportConfig):
            raise ValueError(f"device {config.name!r}: hammer-serial needs a serial url")
        opts: dict[str, Any] = {"baudrate": config.transport.baudrate, **config.options,
                                **overrides}
        return cls(config.name, config.transport.url, config.channels, config.fs or 4096.0,
                   **opts)

    # -- commands ---------------------------------------------------------------------------------
    def query(self, command: str) -> str:
        """Send one command and return its reply line (without LF); ``ERR`` raises."""
        self._link.write(encode_command(command))
        reply = self._link.readline(self.reply_timeout).decode("ascii", "replace").strip()
        if reply.startswith("ERR"):
            raise DeviceInitializationError(f"{self.name}: {command!r} refused: {reply}",
                                            self.name)
        return reply

    def _expect_ok(self, command: str) -> None:
        reply = self.query(command)
        if reply != "OK":
            raise ProtocolError(f"{self.name}: {command!r} answered {reply!r}, expected 'OK'",
                                self.name)

    def _open_internal(self) -> None:
        self._link.open()
        try:
            # a previous session may have left the device streaming: stop it, drop the rest
            self._link.write(encode_command("STOP"))
            time.sleep(0.05)
            self._link.reset_input()
            ident = self.query("ID?")
            if ident == "OK":  # the STOP's answer, come after the input was dropped (a host
                # that gave this thread no CPU for 50 ms): the identity is the next line
                ident = self._link.readline(self.reply_timeout).decode("ascii", "replace").strip()
            if not ident.startswith(IDENTITY_PREFIX):
                raise DeviceInitializationError(
                    f"{self.name}: not an HD-1 hammer digitiser (identity {ident!r})", self.name)
            self.identity = ident[3:]
            self._expect_ok(f"RATE {self.fs:.0f}")
            self._expect_ok(f"RANGE {self._range_mv}")
            self._expect_ok(f"IEPE {int(self.channels[0].iepe)}")
            self._expect_ok(f"FMT {self.sample_width}")
        except BaseException:
            self._link.close()
            raise

    def _start_internal(self) -> None:
        self.health = StreamHealth()
        self._buffer.reset()
        self._leftover.clear()
        self._ended.clear()
        self._expect_ok("START")
        self._reader.start(self._read_loop)

    def _stop_internal(self) -> None:
        try:
            self._link.write(encode_command("STOP"))
            if not self._ended.wait(self.reply_timeout + 0.5):
                raise DeviceTimeoutError(f"{self.name}: no end-of-stream frame after STOP",
                                         self.name)
            self._reader.join()
            tail = bytes(self._leftover)
            if b"\n" not in tail:
                tail += self._link.readline(self.reply_timeout)
            if tail.split(b"\n")[0].strip() != b"OK":
                raise ProtocolError(f"{self.name}: STOP answered {tail!r}", self.name)
        finally:
            self._reader.join()

    def _shutdown_internal(self) -> None:
        self._reader.join()
        self._link.close()

    # -- streaming --------------------------------------------------------------------------------
    def _read_loop(self) -> None:
        buf = bytearray()
        expected_seq: int | None = None
        frame_len = 0
        try:
            while not self._reader.stopping:
                t_poll = time.monotonic()
                data = self._link.read_some()
                if not data:
                    self._buffer.polled(t_poll)
                    continue
                t_rx = time.monotonic()
                buf += data
                frames, bad, skipped = decode_frames(buf)
                if not frames:  # bytes, but no whole frame: nothing heard yet
                    self._buffer.polled(t_poll)
                self.health.bad_frames += bad
                self.health.resync_bytes += skipped
                for frame in frames:
                    if frame.end:
                        self._leftover = buf
                        self._ended.set()
                        return
                    self.health.frames += 1
                    if expected_seq is not None and frame.seq != expected_seq:
                        lost_frames = (frame.seq - expected_seq) % 65536
                        self.health.gaps += 1
                        self.health.lost_samples += lost_frames * frame_len
                        logger.debug("%s: %d frame(s) lost before seq %d", self.name,
                                       lost_frames, frame.seq)
                        self._buffer.append_missing(lost_frames * frame_len)
                    expected_seq = (frame.seq + 1) % 65536
                    frame_len = len(frame.counts)
                    overloaded = frozenset({0}) if frame.overload else frozenset()
                    if frame.overload:
                        self.health.overloaded.add(self.channels[0].name)
                    self._buffer.append(frame.counts * self._scale, t_rx, overloaded)
        except DeviceError as err:
            self._buffer.fail(err)
        except Exception as err:  # the thread must never die silently
            logger.exception("%s: reader thread failed", self.name)
            self._buffer.fail(err)
