"""A minimal socketcand server on 127.0.0.1: CAN buses served over TCP, raw mode only.

It speaks the server side of the socketcand ASCII protocol (linux-can/socketcand
``doc/protocol.md``) as python-can's ``socketcand`` interface uses it, so a driver
on another process reaches a bus of this process (a python-can ``virtual`` bus
with the mock front end on it) with
``can.Bus(interface="socketcand", host="127.0.0.1", port=PORT, channel="can0")``.

Exchange (each element is one ``< ... >`` string, no separator)::

    server: < hi >
    client: < open can0 >        server: < ok >     (or < error could not open bus >)
    client: < rawmode >          server: < ok >
    server: < frame 101 1712345678.123456 0100000000000000 >          classic frame
    server: < fdframe 200 01 1712345678.123456 00000000... >          CAN FD frame
    client: < send 100 8 6 0 0 0 0 0 0 0 >          id hex, length, data bytes hex
    client: < fdsend 100 01 8 6 0 0 0 0 0 0 0 >     id, flags (1 = BRS), length, data
    client: < echo >             server: < echo >

An identifier of 8 hex digits is extended, of 3 standard. A ``< send >`` longer
than 8 bytes or malformed is ignored (logged), as socketcand does; an unknown
command is answered ``< error unknown command >``. python-can 4.6.1's client
neither sends ``< fdsend >`` nor parses ``< fdframe >``: over it, the front end
must use classic frames (``docs/protocols.md``).

The framing here is written from the protocol description, independently of
python-can's client. Frames reach a new client only ``grace`` s after its
``< rawmode >`` was answered, because python-can's client reads the answer with
one ``recv`` and compares it whole.

Example
-------
>>> with SocketcandServer({"can0": "bench-7"}) as server:  # doctest: +SKIP
...     bus = can.Bus(interface="socketcand", host="127.0.0.1", port=server.port,
...                   channel="can0")
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Mapping
from types import TracebackType

import can

__all__ = ["SocketcandServer", "format_frame", "parse_send"]

logger = logging.getLogger(__name__)

MAX_COMMAND = 512  # longest element a client may send, characters


def format_frame(msg: can.Message) -> bytes:
    """The ``< frame ... >`` or ``< fdframe ... >`` element for one received message."""
    ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
    ts = msg.timestamp if msg.timestamp else time.time()
    sec = int(ts)
    usec = min(round((ts - sec) * 1e6), 999999)
    data = bytes(msg.data).hex().upper()
    if msg.is_fd:
        flags = (1 if msg.bitrate_switch else 0) | (2 if msg.error_state_indicator else 0)
        return f"< fdframe {ident} {flags:02X} {sec}.{usec:06d} {data} >".encode("ascii")
    return f"< frame {ident} {sec}.{usec:06d} {data} >".encode("ascii")


def parse_send(element: str) -> can.Message:
    """The message of a ``< send ... >`` or ``< fdsend ... >`` element; ValueError if malformed."""
    words = element.split()
    if len(words) < 5 or words[0] != "<" or words[-1] != ">":
        raise ValueError(f"malformed element {element!r}")
    fd = words[1] == "fdsend"
    fields = words[2:-1]
    ident = fields[0]
    flags = int(fields[1], 16) if fd else 0
    rest = fields[2:] if fd else fields[1:]
    if not rest:
        raise ValueError(f"no length in {element!r}")
    length = int(rest[0])
    data = bytes(int(b, 16) for b in rest[1:])
    if len(data) != length or length > (64 if fd else 8):
        raise ValueError(f"length {length} does not match the {len(data)} data bytes "
                         f"(at most {64 if fd else 8}) in {element!r}")
    if len(ident) not in (3, 8):
        raise ValueError(f"identifier {ident!r} must have 3 or 8 hex digits")
    return can.Message(arbitration_id=int(ident, 16), is_extended_id=len(ident) == 8,
                       data=data, is_fd=fd, bitrate_switch=bool(flags & 1),
                       error_state_indicator=bool(flags & 2))


class _Client:
    """One TCP client: handshake, then frames both ways between its socket and its bus."""

    def __init__(self, server: SocketcandServer, sock: socket.socket, addr: str) -> None:
        self.server = server
        self.sock = sock
        self.addr = addr
        self.bus: can.BusABC | None = None
        self.closed = threading.Event()
        self.raw_since: float | None = None
        self._send_lock = threading.Lock()
        self.frames_out = 0
        self.frames_in = 0
        self._rx = threading.Thread(target=self._from_client, name=f"socketcand-rx {addr}",
                                    daemon=True)
        self._tx = threading.Thread(target=self._to_client, name=f"socketcand-tx {addr}",
                                    daemon=True)

    def start(self) -> None:
        self._rx.start()
        self._tx.start()

    def _write(self, data: bytes) -> bool:
        try:
            with self._send_lock:
                self.sock.sendall(data)
        except OSError:
            self.closed.set()
            return False
        return True

    def _from_client(self) -> None:
        self._write(b"< hi >")
        buf = b""
        try:
            while not self.closed.is_set():
                try:
                    chunk = self.sock.recv(65536)
                except TimeoutError:
                    continue
                if not chunk:
                    break
                buf += chunk
                while True:
                    start, end = buf.find(b"<"), buf.find(b">")
                    if start < 0:
                        buf = b""
                        break
                    if end < 0:
                        if len(buf) - start > MAX_COMMAND:
                            logger.warning("socketcand %s: element too long, dropped", self.addr)
                            buf = b""
                        else:
                            buf = buf[start:]
                        break
                    if end < start:
                        buf = buf[start:]
                        continue
                    element, buf = buf[start : end + 1], buf[end + 1 :]
                    self._element(element.decode("ascii", "replace"))
        except OSError as err:
            logger.debug("socketcand %s: connection lost: %s", self.addr, err)
        finally:
            self.closed.set()

    def _element(self, element: str) -> None:
        words = element.split()
        cmd = words[1] if len(words) > 2 else ""
        if self.bus is None:
            if cmd == "open" and len(words) == 4:
                target = self.server.channels.get(words[2])
                if target is None:
                    self._write(b"< error could not open bus >")
                    return
                self.bus = can.Bus(interface="virtual", channel=target, fd=True)
                self._write(b"< ok >")
            elif cmd == "echo":
                self._write(b"< echo >")
            else:
                self._write(b"< error unknown command >")
        elif cmd == "rawmode":
            self._write(b"< ok >")
            self.raw_since = time.monotonic()
        elif cmd == "echo":
            self._write(b"< echo >")
        elif cmd in ("send", "fdsend") and self.raw_since is not None:
            try:
                msg = parse_send(element)
            except ValueError as err:
                logger.warning("socketcand %s: ignored: %s", self.addr, err)
                return
            self.bus.send(msg)
            self.frames_in += 1
        else:
            self._write(b"< error unknown command >")

    def _to_client(self) -> None:
        while not self.closed.is_set():
            bus, since = self.bus, self.raw_since
            if bus is None or since is None or time.monotonic() - since < self.server.grace:
                time.sleep(0.005)
                continue
            msg = bus.recv(0.05)
            if msg is None:
                continue
            out = [format_frame(msg)]
            while len(out) < 2048:
                more = bus.recv(0)
                if more is None:
                    break
                out.append(format_frame(more))
            if not self._write(b"".join(out)):
                break
            self.frames_out += len(out)
        self._release()

    def _release(self) -> None:
        """Close the socket and the bus (both idempotent)."""
        self.closed.set()
        self.sock.close()
        bus, self.bus = self.bus, None
        if bus is not None:
            bus.shutdown()

    def close(self) -> None:
        """Disconnect the client and wait for its threads."""
        self.closed.set()
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        for t in (self._rx, self._tx):
            if t.is_alive() and t is not threading.current_thread():
                t.join(1.0)
        self._release()


class SocketcandServer:
    """socketcand on 127.0.0.1 serving python-can ``virtual`` channels of this process.

    Parameters
    ----------
    channels : mapping of str to str
        Bus name a client opens (``"can0"``) -> virtual channel it is bridged to.
    port : int
        TCP port; 0 picks a free one (see :attr:`port`).
    grace : float
        Seconds between answering ``< rawmode >`` and sending the first frame.
    """

    def __init__(self, channels: Mapping[str, str], *, port: int = 0,
                 grace: float = 0.1) -> None:
        if not channels:
            raise ValueError("give at least one bus name -> virtual channel")
        self.channels = dict(channels)
        self.grace = grace
        self._listener = socket.create_server(("127.0.0.1", port))
        self._listener.settimeout(0.1)
        self.port: int = self._listener.getsockname()[1]
        self.clients: list[_Client] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="socketcand-accept",
                                        daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                sock, addr = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                break
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.settimeout(0.1)
            client = _Client(self, sock, f"{addr[0]}:{addr[1]}")
            with self._lock:  # clients that left have released their socket and bus
                self.clients = [c for c in self.clients if not c.closed.is_set()]
                self.clients.append(client)
            client.start()

    def shutdown(self) -> None:
        """Stop accepting, disconnect every client and close their buses."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(1.0)
        self._listener.close()
        with self._lock:
            clients, self.clients = self.clients, []
        for c in clients:
            c.close()

    def __enter__(self) -> SocketcandServer:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.shutdown()
