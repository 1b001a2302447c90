"""The socketcand server: literal protocol bytes on a raw socket, and python-can's own client."""

from __future__ import annotations

import gc
import re
import socket
import time
from collections.abc import Iterator

import can
import pytest

from drivers.base import ChannelConfig
from drivers.errors import DeviceNotAvailableError, DeviceTimeoutError
from drivers.frontend_can import CanFrontEnd
from hardware_mocks.frontend_device import FrontEndDevice
from hardware_mocks.physics import REPLY_TIMEOUT, STALL_TIMEOUT
from hardware_mocks.socketcand import SocketcandServer, format_frame, parse_send


@pytest.fixture
def served(request: pytest.FixtureRequest) -> Iterator[tuple[SocketcandServer, can.BusABC]]:
    channel = f"sc-{request.node.name}"
    with SocketcandServer({"can0": channel}, grace=0.05) as server, \
            can.Bus(interface="virtual", channel=channel, fd=True) as device_bus:
        yield server, device_bus


#: seconds a socket read may wait: only guards against a hang
HANG = 30.0


def recv_exact(sock: socket.socket, expected: bytes) -> bytes:
    got = b""
    deadline = time.monotonic() + HANG
    while len(got) < len(expected) and time.monotonic() < deadline:
        got += sock.recv(len(expected) - len(got))
    return got


def raw_session(server: SocketcandServer) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=HANG)
    assert recv_exact(sock, b"< hi >") == b"< hi >"
    sock.sendall(b"< open can0 >")
    assert recv_exact(sock, b"< ok >") == b"< ok >"
    sock.sendall(b"< rawmode >")
    assert recv_exact(sock, b"< ok >") == b"< ok >"
    return sock


def test_handshake_errors_and_echo(served: tuple[SocketcandServer, can.BusABC]) -> None:
    server, _ = served
    with socket.create_connection(("127.0.0.1", server.port), timeout=HANG) as sock:
        assert recv_exact(sock, b"< hi >") == b"< hi >"
        sock.sendall(b"< open can9 >")
        assert recv_exact(sock, b"< error could not open bus >") == b"< error could not open bus >"
        sock.sendall(b"< echo >")
        assert recv_exact(sock, b"< echo >") == b"< echo >"
        sock.sendall(b"< bogus >")
        assert recv_exact(sock, b"< error unknown command >") == b"< error unknown command >"


def test_send_elements_reach_the_bus(served: tuple[SocketcandServer, can.BusABC]) -> None:
    server, bus = served
    with raw_session(server) as sock:
        # python-can writes bytes without leading zeros and the length in hex
        sock.sendall(b"< send 100 8 6 0 0 0 0 0 0 0 >< send 1ABCDEF0 2 ff 1 >")
        sock.sendall(b"< fdsend 200 01 12 0 1 2 3 4 5 6 7 8 9 a b >")
        sock.sendall(b"< send 100 9 0 0 0 0 0 0 0 0 0 >< send 100 3 1 2 >")  # ignored: bad length
        sock.sendall(b"< send 7FF 1 5a >")  # the next one the bus gets: nothing in between
        msgs = [bus.recv(HANG) for _ in range(4)]
    assert all(m is not None for m in msgs)
    assert (msgs[3].arbitration_id, bytes(msgs[3].data)) == (0x7FF, b"\x5a")
    msgs = msgs[:3]
    a, b, c = msgs
    assert a is not None and b is not None and c is not None
    assert (a.arbitration_id, a.is_extended_id, bytes(a.data)) == (
        0x100, False, bytes.fromhex("06 00 00 00 00 00 00 00"))
    assert (b.arbitration_id, b.is_extended_id, bytes(b.data)) == (0x1ABCDEF0, True, b"\xff\x01")
    assert (c.is_fd, c.bitrate_switch, bytes(c.data)) == (True, True, bytes(range(12)))


def test_bus_frames_reach_the_client(served: tuple[SocketcandServer, can.BusABC]) -> None:
    server, bus = served
    with raw_session(server) as sock:  # frames sent now wait in the server for its grace
        bus.send(can.Message(arbitration_id=0x101, data=bytes.fromhex("0300"),
                             is_extended_id=False, timestamp=1712345678.5))
        bus.send(can.Message(arbitration_id=0x200, data=bytes(range(12)), is_fd=True,
                             bitrate_switch=True, is_extended_id=False))
        got = b""
        deadline = time.monotonic() + HANG
        while got.count(b">") < 2 and time.monotonic() < deadline:
            got += sock.recv(4096)
    text = got.decode("ascii")
    assert re.fullmatch(r"< frame 101 \d+\.\d{6} 0300 >"
                        r"< fdframe 200 01 \d+\.\d{6} 000102030405060708090A0B >", text), text


def test_format_and_parse_literals() -> None:
    msg = can.Message(arbitration_id=0x12345, is_extended_id=True, data=b"\x01\xab",
                      timestamp=10.000001)
    assert format_frame(msg) == b"< frame 00012345 10.000001 01AB >"
    m = parse_send("< send 7FF 2 0 fe >")
    assert (m.arbitration_id, bytes(m.data), m.is_fd) == (0x7FF, b"\x00\xfe", False)
    with pytest.raises(ValueError, match="does not match"):
        parse_send("< send 100 3 1 2 >")
    with pytest.raises(ValueError, match="3 or 8 hex digits"):
        parse_send("< send 10000 1 0 >")


def chans() -> list[ChannelConfig]:
    return [ChannelConfig(f"a{i}", i, "acceleration", 10.2, range_v=1.0) for i in range(4)]


def test_python_can_client_drives_the_front_end_with_classic_frames(
        engine_physics_factory, served: tuple[SocketcandServer, can.BusABC],
        request: pytest.FixtureRequest) -> None:
    server, _ = served
    physics = engine_physics_factory()
    with FrontEndDevice(physics, channel=f"sc-{request.node.name}") as dev:
        fe = CanFrontEnd("fe", chans(), fs=512, frame="classic", bus_kwargs={
            "interface": "socketcand", "host": "127.0.0.1", "port": server.port,
            "channel": "can0"}, stall_timeout=STALL_TIMEOUT, reply_timeout=REPLY_TIMEOUT)
        try:
            fe.open()
            assert fe.identity == "INSITU,FE-16,4242,2.4"
            fe.start()
            physics.hit(exc=0, peak=200.0)
            block = fe.read_block(512, timeout=HANG)
            assert block.complete and fe.health.ok() and dev.frames_sent >= 2 * 512
            assert abs(block.data).max() > 0.1  # the hit's accelerations came through
        finally:
            fe.shutdown()


def test_can_fd_does_not_pass_python_cans_client(
        engine_physics_factory, served: tuple[SocketcandServer, can.BusABC],
        request: pytest.FixtureRequest) -> None:
    """python-can 4.6.1 drops < fdframe > elements: FD sample frames never arrive."""
    server, _ = served
    with FrontEndDevice(engine_physics_factory(), channel=f"sc-{request.node.name}"):
        # status frames come, samples never: the read's own timeout ends it, not a stall
        fe = CanFrontEnd("fe", chans(), fs=512, frame="fd", bus_kwargs={
            "interface": "socketcand", "host": "127.0.0.1", "port": server.port,
            "channel": "can0"}, stall_timeout=STALL_TIMEOUT, reply_timeout=REPLY_TIMEOUT)
        try:
            fe.open()
            fe.start()
            with pytest.raises(DeviceTimeoutError, match="only 0 of 512 samples"):
                fe.read_block(512, timeout=1.0)
        finally:
            fe.shutdown()


# python-can 4.6.1's SocketCanDaemonBus does not close its socket when the handshake fails
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_unknown_bus_is_a_clear_error(served: tuple[SocketcandServer, can.BusABC]) -> None:
    server, _ = served
    fe = CanFrontEnd("fe", chans(), fs=512, frame="classic", bus_kwargs={
        "interface": "socketcand", "host": "127.0.0.1", "port": server.port, "channel": "can7"})
    with pytest.raises(DeviceNotAvailableError, match="could not open bus"):
        fe.open()
    fe.shutdown()
    gc.collect()  # the leaked socket's warning is raised here, not in a later test
