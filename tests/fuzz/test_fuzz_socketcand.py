"""python-can's socketcand client behind our CAN link, fed any bytes by a server on loopback.

After the handshake the server sends fuzzed bytes (valid frames among them): the link gives
frames, nothing, or one DeviceError line; it never raises anything else and never hangs.
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


def _server(payload: bytes) -> tuple[socket.socket, threading.Thread]:
    srv = socket.socket()
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
                try:
                    conn.sendall(b"< hi >")
                    if not conn.recv(64):  # < open vcan0 > (the probe just closes)
                        continue
                    conn.sendall(b"< ok >")
                    conn.recv(64)  # < rawmode >
                    conn.sendall(b"< ok >")
                    conn.sendall(payload)
                    conn.recv(1)  # until the client closes
                except OSError:
                    pass
                return

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return srv, t


@FUZZ
@given(st.lists(CHUNK, max_size=12))
def test_any_bytes_from_the_server(chunks: list[bytes]) -> None:
    srv, t = _server(b"".join(chunks))
    link = CanLink(name="fe", interface="socketcand", host="127.0.0.1",
                   port=srv.getsockname()[1], channel="vcan0")
    try:
        with no_hang(10.0):
            link.open()
            for _ in range(len(chunks) + 2):
                try:
                    msg = link.recv(0.02)
                except DeviceError as err:
                    assert str(err) and "\n" not in str(err)
                    break
                assert msg is None or isinstance(msg, can.Message)
    finally:
        link.close()
        srv.close()
        t.join(5)
