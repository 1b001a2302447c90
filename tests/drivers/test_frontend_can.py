"""FE-16 CAN front-end driver: the DBC, literal frames, and a scripted device on a virtual bus."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import can
import numpy as np
import pytest
from numpy.testing import assert_allclose

from drivers.base import ChannelConfig
from drivers.errors import DeviceInitializationError, DeviceTimeoutError
from drivers.frontend_can import FULL_SCALE, CanFrontEnd, load_dbc

INFO = bytes.fromhex("92 10 00 00 02 04 10 00")  # serial 4242, fw 2.4, 16 inputs
# FD frame: seq 0x0102, group 0, overload on the group's input 1, then 5 samples x 4 inputs
FD_FRAME = bytes.fromhex(
    "02 01 00 02"
    "01 00 00  ff ff ff  00 00 00  00 00 00"  # sample 0: 1, -1, 0, 0
    + " 00 00 00" * 12
    + " ff ff 7f  01 00 80  00 01 00  00 00 00"  # sample 4: 8388607, -8388607, 256, 0
)
# classic frame: seq 5, group 3 (inputs 6, 7), samples 256 and -2
CLASSIC_FRAME = bytes.fromhex("05 30 00 01 00 fe ff ff")


def channels(n: int = 4, range_v: float = 5.0) -> list[ChannelConfig]:
    return [ChannelConfig(f"a{i}", i, "acceleration", sensitivity=10.0, range_v=range_v)
            for i in range(n)]


def test_dbc_describes_the_messages() -> None:
    db = load_dbc()
    fd = db.get_message_by_frame_id(0x200)
    assert fd.is_fd and fd.length == 64 and len(fd.signals) == 2 + 4 + 20
    assert db.get_message_by_frame_id(0x201).length == 8
    assert db.get_message_by_name("FE_CMD").is_multiplexed()


def test_command_bytes() -> None:
    fe = CanFrontEnd("fe", channels(), fs=1024, bus_kwargs={})
    assert fe.encode_command("CONFIG_ACQ", RATE_HZ=1024, FRAME_FORMAT=1, GROUP_MASK=0x0F) == \
        bytes.fromhex("01 00 04 01 0f 00 00 00")
    assert fe.encode_command("CONFIG_CHANNEL", CHANNEL=3, RANGE_MV=5000, IEPE=1) == \
        bytes.fromhex("02 03 88 13 01 00 00 00")
    assert fe.encode_command("START") == bytes.fromhex("03 00 00 00 00 00 00 00")
    assert fe.encode_command("IDENTIFY") == bytes.fromhex("06 00 00 00 00 00 00 00")


def test_decode_literal_fd_frame() -> None:
    fe = CanFrontEnd("fe", channels(), fs=1024, bus_kwargs={})
    sig = fe.decode(0x200, FD_FRAME, scaling=False)
    assert (sig["SEQ"], sig["GROUP"], sig["OVL1"], sig["OVL0"]) == (0x0102, 0, 1, 0)
    assert [sig[f"S0C{j}"] for j in range(4)] == [1, -1, 0, 0]
    assert [sig[f"S4C{j}"] for j in range(4)] == [FULL_SCALE, -FULL_SCALE, 256, 0]


def test_decode_literal_classic_frame() -> None:
    fe = CanFrontEnd("fe", channels(), fs=256, bus_kwargs={}, frame="classic")
    sig = fe.decode(0x201, CLASSIC_FRAME, scaling=False)
    assert (sig["SEQ"], sig["GROUP"], sig["S0C0"], sig["S0C1"]) == (5, 3, 256, -2)


class ScriptedFrontEnd:
    """Answers commands with literal frames on a virtual bus; records what it got."""

    def __init__(self, channel: str, stream: list[bytes], refuse: int | None = None) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.stream = stream
        self.refuse = refuse
        self.received: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.01)
            if msg is None or msg.arbitration_id != 0x100:
                continue
            data = bytes(msg.data)
            self.received.append(data)
            if data[0] == 6:
                self.bus.send(can.Message(arbitration_id=0x102, data=INFO, is_extended_id=False))
                continue
            result = 1 if data[0] == self.refuse else 0
            self.bus.send(can.Message(arbitration_id=0x101, data=bytes([data[0], result]) +
                                      bytes(6), is_extended_id=False))
            if data[0] == 3:
                for frame in self.stream:
                    self.bus.send(can.Message(arbitration_id=0x200, data=frame, is_fd=True,
                                              is_extended_id=False))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.bus.shutdown()


@pytest.fixture
def scripted_fe(request: pytest.FixtureRequest) -> Iterator[type[ScriptedFrontEnd]]:
    made: list[ScriptedFrontEnd] = []

    def make(*args: object, **kwargs: object) -> ScriptedFrontEnd:
        dev = ScriptedFrontEnd(*args, **kwargs)
        made.append(dev)
        return dev

    yield make
    for dev in made:
        dev.close()


def test_open_start_read_stop_literal(scripted_fe) -> None:
    dev = scripted_fe("fe-literal", [FD_FRAME])
    bus = can.Bus(interface="virtual", channel="fe-literal")
    try:
        with CanFrontEnd("fe", channels(range_v=5.0), fs=1024, bus=bus) as fe:
            assert fe.identity == "INSITU,FE-16,4242,2.4"
            fe.start()
            block = fe.read_block(5, timeout=1.0)
            fe.stop()
    finally:
        bus.shutdown()
    assert dev.received == [bytes.fromhex(h) for h in (
        "06 00 00 00 00 00 00 00",  # IDENTIFY
        "04 00 00 00 00 00 00 00",  # STOP (in case it was left running)
        "01 00 04 01 01 00 00 00",  # CONFIG_ACQ 1024 Hz, FD, group 0 only
        "02 00 88 13 01 00 00 00",  # CONFIG_CHANNEL input 0, 5000 mV, IEPE
        "02 01 88 13 01 00 00 00",
        "02 02 88 13 01 00 00 00",
        "02 03 88 13 01 00 00 00",
        "03 00 00 00 00 00 00 00",  # START
        "04 00 00 00 00 00 00 00",  # STOP
    )]
    per_count = 5.0 / FULL_SCALE * 1000 / 10.0  # V per count, then (m/s^2) per V
    assert_allclose(block.data[:, 0], np.array([1, -1, 0, 0]) * per_count, rtol=1e-12)
    assert_allclose(block.data[:, 4], np.array([FULL_SCALE, -FULL_SCALE, 256, 0]) * per_count,
                    rtol=1e-12)
    assert block.overloaded == ("a1",)
    assert block.first_sample == 0 and block.missing == 0


def test_refused_configuration(scripted_fe) -> None:
    scripted_fe("fe-refuse", [], refuse=2)
    fe = CanFrontEnd("fe", channels(), fs=1024,
                     bus_kwargs={"interface": "virtual", "channel": "fe-refuse"})
    with pytest.raises(DeviceInitializationError, match=r"CONFIG_CHANNEL.*bad parameter"):
        fe.open()
    fe.shutdown()


def test_nobody_on_the_bus_times_out() -> None:
    fe = CanFrontEnd("fe", channels(), fs=1024, reply_timeout=0.2,
                     bus_kwargs={"interface": "virtual", "channel": "fe-empty"})
    with pytest.raises(DeviceTimeoutError, match="no FE_INFO"):
        fe.open()
    fe.shutdown()


def test_bad_settings_rejected() -> None:
    with pytest.raises(ValueError, match=r"range 2\.0 V not supported"):
        CanFrontEnd("fe", channels(range_v=2.0), fs=1024, bus_kwargs={})
    with pytest.raises(ValueError, match="input 16 does not exist"):
        CanFrontEnd("fe", [ChannelConfig("x", 16, "force", 1.0)], fs=1024, bus_kwargs={})
    with pytest.raises(ValueError, match="frame must be"):
        CanFrontEnd("fe", channels(), fs=1024, bus_kwargs={}, frame="xl")
