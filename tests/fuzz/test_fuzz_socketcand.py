"""python-can's socketcand client behind our CAN link, fed any bytes by a server on loopback.

After the handshake the server sends fuzzed bytes (valid frames among them): the link gives
frames, nothing, or one DeviceError line; it never raises anything else and never hangs.

The fuzzed bytes end with ``>`` (closing any message left open) and an end marker, an
extended frame the fuzzed frames cannot be: the link is read until the marker comes (or
an error), so no example waits out a receive timeout once its bytes are parsed.
"""

from __future__ import annotations

import socket
import threading

import can
from _fuzz import FUZZ, no_hang
from hypothesis import given
from hypothesis import strategies as st

from drivers.errors import DeviceError
from drivers.transports import CanLink

FRAME = st.builds(lambda i, d: f"< frame {i:X} 1.000000 {d.hex().upper()} >".encode(),
                  st.integers(0, 0x7FF), st.binary(max_size=8))
CHUNK = FRAME | st.binary(max_size=60) | st.sampled_from([b"<", b">", b"< frame >",
                                                          b"< frame 12 x 00 >", b"\xff\xfe"])
#: sent after the fuzzed bytes: ">" closes a message left open, then an extended frame
END = b"> < frame 1FFFFFFF 0.000000 5A5A >"
END_ID = 0x1FFFFFFF


def _server(payload: bytes) -> tuple[socket.socket, threading.Thread, threading.Event]:
    """A socketcand server on loopback: the handshake, then ``payload`` once the returned
    event is set (python-can takes whatever arrives with the last ``< ok >`` for the reply)."""
    srv = socket.socket()
    go = threading.Event()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)

    def serve() -> None:
        for _ in range(2):  # the link's probe, then python-can's client
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn:
                conn.settimeout(2.0)
                # no Nagle: the payload after "< ok >" would wait for the client's delayed
                # ACK (40 ms an example, most of the fuzzing's time)
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                try:
                    conn.sendall(b"< hi >")
                    if not conn.recv(64):  # < open vcan0 > (the probe just closes)
                        continue
                    conn.sendall(b"< ok >")
                    conn.recv(64)  # < rawmode >
                    conn.sendall(b"< ok >")
                    go.wait(5.0)
                    conn.sendall(payload)
                    conn.recv(1)  # until the client closes
                except OSError:
                    pass
                return

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return srv, t, go


@FUZZ
@given(st.lists(CHUNK, max_size=12))
def test_any_bytes_from_the_server(chunks: list[bytes]) -> None:
    srv, t, go = _server(b"".join(chunks) + END)
    link = CanLink(name="fe", interface="socketcand", host="127.0.0.1",
                   port=srv.getsockname()[1], channel="vcan0")
    try:
        with no_hang(10.0):
            link.open()
            go.set()
            for _ in range(len(chunks) + 2):  # at most one frame a chunk, then the marker
                try:
                    msg = link.recv(1.0)  # returns as soon as a frame is parsed
                except DeviceError as err:
                    assert str(err) and "\n" not in str(err) and "Traceback" not in str(err)
                    break
                assert msg is None or isinstance(msg, can.Message)
                if msg is None or msg.arbitration_id == END_ID:
                    break
    finally:
        link.close()
        srv.close()
        t.join(5)
