"""HD-1 hammer digitiser driver: literal bytes on the wire, against a scripted device."""

from __future__ import annotations

import binascii

import numpy as np
import pytest
from numpy.testing import assert_allclose

from drivers.base import ChannelConfig, DeviceState
from drivers.errors import DeviceInitializationError, DeviceTimeoutError
from drivers.hammer_serial import SerialHammer, decode_frames, encode_command

# int32 frame, seq 0, two samples (1000, -1000); CRC 0xAFB8 (checked with crccheck)
FRAME_I32 = bytes.fromhex("a5 5a 01 00 00 00 02 00 e8 03 00 00 18 fc ff ff b8 af")
# int16 frame, seq 1, three samples (32767, -32767, 100); CRC 0x8509
FRAME_I16 = bytes.fromhex("a5 5a 00 00 01 00 03 00 ff 7f 01 80 64 00 09 85")
# end-of-stream frame, int32 flag, seq 2, no samples; CRC 0x72F8
FRAME_END = bytes.fromhex("a5 5a 81 00 02 00 00 00 f8 72")

OPEN_SCRIPT = [
    (b"STOP\n", b"OK\n"),
    (b"ID?\n", b"ID INSITU,HD-1,0042,1.3\n"),
    (b"RATE 4096\n", b"OK\n"),
    (b"RANGE 5000\n", b"OK\n"),
    (b"IEPE 1\n", b"OK\n"),
    (b"FMT 32\n", b"OK\n"),
]


def force_channel(range_v: float = 5.0) -> ChannelConfig:
    return ChannelConfig("F", 0, "force", sensitivity=2.25, range_v=range_v, node=101,
                         direction=(1.0, 0.0, 0.0))


def test_crc_is_ccitt_false() -> None:
    assert binascii.crc_hqx(b"123456789", 0xFFFF) == 0x29B1


def test_encode_command() -> None:
    assert encode_command("RATE 4096") == b"RATE 4096\n"
    with pytest.raises(ValueError, match="one line"):
        encode_command("RATE 1\nSTART")


def test_decode_literal_frames() -> None:
    buf = bytearray(FRAME_I32 + FRAME_I16 + FRAME_I32[:5])
    frames, bad, skipped = decode_frames(buf)
    assert (bad, skipped) == (0, 0)
    assert [f.seq for f in frames] == [0, 1]
    assert frames[0].counts.tolist() == [1000, -1000]
    assert frames[1].counts.tolist() == [32767, -32767, 100]
    assert bytes(buf) == FRAME_I32[:5]  # the incomplete frame waits for more bytes


def test_decode_rejects_bad_crc_and_resyncs() -> None:
    corrupt = bytearray(FRAME_I32)
    corrupt[9] ^= 0x10
    buf = bytearray(b"\x00\x13" + corrupt + FRAME_I16)
    frames, bad, skipped = decode_frames(buf)
    assert bad == 1
    assert [f.seq for f in frames] == [1]
    assert skipped == 2 + len(FRAME_I32) - 1  # leading garbage + the rest of the bad frame


def test_decode_stops_after_end_of_stream() -> None:
    buf = bytearray(FRAME_END + b"OK\n")
    frames, _, _ = decode_frames(buf)
    assert frames[0].end and frames[0].counts.size == 0
    assert bytes(buf) == b"OK\n"


def test_open_sends_literal_configuration(scripted) -> None:
    dev = scripted(OPEN_SCRIPT)
    with SerialHammer("hammer", dev.path, [force_channel()], fs=4096) as hammer:
        assert hammer.identity == "INSITU,HD-1,0042,1.3"
        assert hammer.state is DeviceState.OPEN
    dev.check()
    assert hammer.state is DeviceState.SHUT_DOWN
    hammer.shutdown()  # idempotent


def test_stream_converts_counts_to_newtons(scripted) -> None:
    dev = scripted([*OPEN_SCRIPT, (b"START\n", b"OK\n" + FRAME_I32),
                    (b"STOP\n", FRAME_END + b"OK\n")])
    hammer = SerialHammer("hammer", dev.path, [force_channel()], fs=4096)
    with hammer:
        hammer.start()
        block = hammer.read_block(2, timeout=2.0)
        hammer.stop()
    dev.check()
    newton_per_count = 5.0 / 8388607 * 1000 / 2.25
    assert_allclose(block.data, [[1000 * newton_per_count, -1000 * newton_per_count]], rtol=1e-12)
    assert block.first_sample == 0 and block.missing == 0 and block.overloaded == ()
    assert block.channels[0].unit == "N"


def test_sequence_gap_is_filled_with_nan(scripted) -> None:
    frame_seq3 = bytearray(FRAME_I32)
    frame_seq3[4] = 3
    body = bytes(frame_seq3[2:-2])
    frame_seq3[-2:] = binascii.crc_hqx(body, 0xFFFF).to_bytes(2, "little")
    dev = scripted([*OPEN_SCRIPT, (b"START\n", b"OK\n" + FRAME_I32 + bytes(frame_seq3)),
                    (b"STOP\n", FRAME_END + b"OK\n")])
    with SerialHammer("hammer", dev.path, [force_channel()], fs=4096) as hammer:
        hammer.start()
        block = hammer.read_block(8, timeout=2.0)
        assert hammer.health.gaps == 1 and hammer.health.lost_samples == 4
        assert block.missing == 4
        assert np.isnan(block.data[0, 2:6]).all() and np.isfinite(block.data[0, 6:]).all()
    dev.check()


def test_refused_setting_raises(scripted) -> None:
    dev = scripted([*OPEN_SCRIPT[:2], (b"RATE 4096\n", b"ERR 2 bad value\n")])
    hammer = SerialHammer("hammer", dev.path, [force_channel()], fs=4096)
    with pytest.raises(DeviceInitializationError, match=r"RATE 4096.*ERR 2"):
        hammer.open()
    hammer.shutdown()


def test_wrong_identity_raises(scripted) -> None:
    dev = scripted([OPEN_SCRIPT[0], (b"ID?\n", b"ID ACME,SCOPE,1,1\n")])
    with pytest.raises(DeviceInitializationError, match="not an HD-1"):
        SerialHammer("hammer", dev.path, [force_channel()], fs=4096).open()


def test_silent_device_times_out_quickly(scripted) -> None:
    dev = scripted([(b"STOP\n", b""), (b"ID?\n", b"")])
    hammer = SerialHammer("hammer", dev.path, [force_channel()], fs=4096, reply_timeout=0.3)
    with pytest.raises(DeviceTimeoutError, match=r"no reply within 0\.3 s"):  # reply_timeout
        hammer.open()
    hammer.shutdown()


def test_missing_port_is_not_available() -> None:
    from drivers.errors import DeviceNotAvailableError

    with pytest.raises(DeviceNotAvailableError, match="cannot open serial port"):
        SerialHammer("hammer", "/dev/does-not-exist", [force_channel()], fs=4096).open()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"fs": 5000}, "not supported"), ({"range_v": 3.0}, "range 3.0 V not supported")],
)
def test_bad_settings_rejected_before_opening(kwargs: dict[str, float], match: str) -> None:
    ch = force_channel(kwargs.get("range_v", 5.0))
    with pytest.raises(ValueError, match=match):
        SerialHammer("hammer", "loop://", [ch], fs=kwargs.get("fs", 4096))
