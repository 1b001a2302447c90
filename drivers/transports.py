"""Transports the drivers talk through: a serial link and a CAN bus.

Both are injected into the drivers (a URL for :func:`serial.serial_for_url`, or
any :class:`can.BusABC`). Wire traffic is logged here, once, at DEBUG level
on the ``drivers.wire`` logger, as PyMeasure's adapters do.

Example
-------
>>> link = SerialLink("loop://", name="demo")
>>> link.open()
>>> link.write(b"ID?\\n")
>>> link.readline(timeout=0.5)
b'ID?\\n'
>>> link.close()
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from typing import Any

import can
import serial

from drivers.errors import DeviceNotAvailableError, DeviceTimeoutError

__all__ = ["CanLink", "SerialLink", "log_wire"]

wire_logger = logging.getLogger("drivers.wire")
logger = logging.getLogger(__name__)

#: pauses (s) after each failed connection to a network transport: 4 tries in about 1.5 s
CONNECT_BACKOFF = (0.1, 0.3, 0.6, 0.0)
#: one connection attempt's time limit, s
CONNECT_TIMEOUT = 1.0


class _SplitMessageFilter(logging.Filter):
    """Drop python-can socketcand's warnings about elements split across TCP reads.

    Its client reads 1024 bytes at a time and logs a WARNING ("Got incomplete
    message => waiting for more data") every time a read ends inside an
    element, which at a few thousand frames per second is most reads; the element
    is reassembled correctly. Its failed connection attempts (one warning per try,
    hundreds of thousands in its 10 s loop) are dropped too. Other warnings pass.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        # its connect loop retries without a pause for 10 s and logs every refusal:
        # CanLink.open probes the server first and says it once
        return not str(record.msg).startswith(("Got incomplete message",
                                                "Failed to connect to server"))


_socketcand_filter = _SplitMessageFilter()


def log_wire(name: str, direction: str, payload: bytes | str) -> None:
    """Log one exchange on the wire at DEBUG: ``name`` device, ``direction`` ``>>`` or ``<<``."""
    if wire_logger.isEnabledFor(logging.DEBUG):
        text = payload if isinstance(payload, str) else payload.hex(" ")
        wire_logger.debug("%s %s %s", name, direction, text)


class SerialLink:
    """A serial port opened by URL, with deadlines on every read.

    Parameters
    ----------
    url : str
        Port name or pyserial URL: ``/dev/ttyUSB0``, a pseudo-terminal path,
        ``loop://``, ``socket://host:port``.
    baudrate : int
    name : str
        Device name for logs and errors.
    """

    def __init__(self, url: str, baudrate: int = 115200, name: str = "serial") -> None:
        self.url = url
        self.baudrate = baudrate
        self.name = name
        self._port: serial.SerialBase | None = None
        self._write_lock = threading.Lock()

    def open(self) -> None:
        try:
            self._port = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0.05,
                                               write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as err:
            raise DeviceNotAvailableError(
                f"{self.name}: cannot open serial port {self.url!r}: {err}", self.name
            ) from err

    @property
    def is_open(self) -> bool:
        return self._port is not None and self._port.is_open

    def _require(self) -> serial.SerialBase:
        if self._port is None:
            raise DeviceNotAvailableError(f"{self.name}: serial port is not open", self.name)
        return self._port

    def write(self, data: bytes) -> None:
        port = self._require()
        log_wire(self.name, ">>", data)
        try:
            with self._write_lock:
                port.write(data)
                port.flush()
        except (serial.SerialException, OSError) as err:
            raise DeviceNotAvailableError(f"{self.name}: write failed: {err}", self.name) from err

    def read_some(self, max_bytes: int = 4096) -> bytes:
        """Whatever arrives within the port's short timeout (may be empty)."""
        port = self._require()
        try:
            n = max(1, min(max_bytes, port.in_waiting))
            data = bytes(port.read(n))
        except (serial.SerialException, OSError, TypeError) as err:
            # pyserial raises TypeError when the port is closed under a blocked read
            raise DeviceNotAvailableError(
                f"{self.name}: serial port lost (unplugged?): {err}", self.name
            ) from err
        if data:
            log_wire(self.name, "<<", data)
        return data

    def readline(self, timeout: float, terminator: bytes = b"\n") -> bytes:
        """One line including its terminator; :class:`DeviceTimeoutError` after ``timeout`` s.

        What has arrived is read before the time is looked at: a reader that got no CPU
        for a while (a loaded host) finds the rest of the reply waiting, not a timeout.
        """
        port = self._require()
        deadline = time.monotonic() + timeout
        buf = bytearray()
        while not buf.endswith(terminator):
            try:
                got = port.read(1)
            except (serial.SerialException, OSError, TypeError) as err:
                raise DeviceNotAvailableError(
                    f"{self.name}: serial port lost (unplugged?): {err}", self.name
                ) from err
            buf += got
            if not got and time.monotonic() > deadline:
                raise DeviceTimeoutError(
                    f"{self.name}: no reply within {timeout:g} s"
                    + (f" (got {bytes(buf)!r})" if buf else ""), self.name
                )
        log_wire(self.name, "<<", bytes(buf))
        return bytes(buf)

    def reset_input(self) -> None:
        port = self._require()
        try:
            port.reset_input_buffer()
        except (serial.SerialException, OSError) as err:
            raise DeviceNotAvailableError(f"{self.name}: serial port lost: {err}",
                                          self.name) from err

    def close(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError) as err:
                wire_logger.debug("%s: close failed: %s", self.name, err)


def _brief(err: BaseException) -> str:
    """The first line of an exception's text (some libraries put a traceback in it)."""
    lines = str(err).strip().splitlines()
    # python-can's socketcand client appends "  Traceback (most recent call last):" to it
    first = lines[0].split("Traceback (most recent call last)")[0].strip() if lines else ""
    return first[:200] or type(err).__name__


class CanLink:
    """A python-can bus, injected or created from keyword arguments of :class:`can.Bus`.

    Parameters
    ----------
    bus : can.BusABC, optional
        An open bus; the link does not shut it down unless ``own_bus``.
    name : str
    **bus_kwargs
        Passed to ``can.Bus`` when ``bus`` is None (``interface``, ``channel``,
        ``fd``, ``bitrate``, ``data_bitrate``...).
    """

    def __init__(self, bus: can.BusABC | None = None, name: str = "can",
                 **bus_kwargs: Any) -> None:
        self.name = name
        self._bus = bus
        self._own_bus = bus is None
        self._bus_kwargs = bus_kwargs

    def open(self) -> None:
        if self._bus is not None:
            return
        if self._bus_kwargs.get("interface") == "socketcand":
            logging.getLogger("can.interfaces.socketcand.socketcand").addFilter(
                _socketcand_filter)  # adding the same filter twice is a no-op
            self._probe_server()
        try:
            self._bus = can.Bus(**self._bus_kwargs)
        except (can.CanError, OSError, ValueError, ImportError) as err:
            raise DeviceNotAvailableError(
                f"{self.name}: cannot open CAN bus {self._bus_kwargs}: {_brief(err)}", self.name
            ) from err

    def _probe_server(self) -> None:
        """Reach a socketcand server's TCP port, retrying with back-off, or refuse in one line."""
        host = str(self._bus_kwargs.get("host", "localhost"))
        port = int(str(self._bus_kwargs.get("port", 29536)))
        last: OSError = ConnectionRefusedError()
        for attempt, pause in enumerate(CONNECT_BACKOFF, start=1):
            try:
                with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT) as sock:
                    greeting = sock.recv(64)
            except OSError as err:
                last = err
                logger.debug("%s: socketcand %s:%d try %d: %s", self.name, host, port,
                             attempt, err)
            else:
                # python-can's client waits without end for a greeting that never comes
                if greeting.startswith(b"< hi >"):
                    return
                raise DeviceNotAvailableError(
                    f"{self.name}: the server at {host}:{port} does not speak socketcand (it "
                    f"greeted {greeting[:20]!r}, not '< hi >'): correct host and port in the "
                    "station file", self.name)
            time.sleep(pause)
        reason = last.strerror or type(last).__name__
        raise DeviceNotAvailableError(
            f"{self.name}: socketcand server {host}:{port} not reachable ({reason}) after "
            f"{len(CONNECT_BACKOFF)} tries: start the bench's server or correct host and "
            "port in the station file", self.name)

    @property
    def bus(self) -> can.BusABC:
        if self._bus is None:
            raise DeviceNotAvailableError(f"{self.name}: CAN bus is not open", self.name)
        return self._bus

    def send(self, msg: can.Message) -> None:
        log_wire(self.name, ">>", f"{msg.arbitration_id:03X} {msg.data.hex(' ')}")
        try:
            self.bus.send(msg, timeout=0.5)
        except (can.CanError, OSError) as err:
            raise DeviceNotAvailableError(f"{self.name}: CAN send failed: {_brief(err)}",
                                          self.name) from err

    def recv(self, timeout: float) -> can.Message | None:
        try:
            msg = self.bus.recv(timeout)
        except (can.CanError, OSError, ValueError, IndexError, KeyError) as err:
            # (python-can's socketcand client raises its parser's errors, some wrapped in a
            # CanError whose text holds a whole traceback: one line of it is kept)
            raise DeviceNotAvailableError(f"{self.name}: CAN receive failed: {_brief(err)}",
                                          self.name) from err
        if msg is not None:
            log_wire(self.name, "<<", f"{msg.arbitration_id:03X} {msg.data.hex(' ')}")
        return msg

    def close(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None and self._own_bus:
            bus.shutdown()
