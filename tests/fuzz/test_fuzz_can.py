"""The CAN front end's frame decoder (DBC through cantools) on any frames: the stream lives on.

Any identifier, any length, any bytes, between the device's own frame types: a malformed
frame is counted as bad and skipped; the reader thread never dies of it.
"""

from __future__ import annotations

from typing import Any

import can
import numpy as np
from _fuzz import FUZZ
from hypothesis import given
from hypothesis import strategies as st

from drivers.base import ChannelConfig
from drivers.frontend_can import (
    ID_ACK,
    ID_CLASSIC,
    ID_FD,
    ID_INFO,
    ID_STATUS,
    CanFrontEnd,
    load_dbc,
)

CHANNELS = [ChannelConfig("F", 12, "force", 2.25), *(
    ChannelConfig(f"a{i}", i, "acceleration", 10.2, node=1, direction=(1, 0, 0))
    for i in range(3))]


class _Feed:
    """Stands in for the CAN link: hands the frames to the reader, then asks it to stop."""

    def __init__(self, frames: list[can.Message], fe: CanFrontEnd) -> None:
        self.frames, self.fe = frames, fe

    def recv(self, timeout: float) -> can.Message | None:
        if self.frames:
            return self.frames.pop(0)
        self.fe._reader._stop.set()
        return None


frame_ids = st.sampled_from([ID_ACK, ID_STATUS, ID_INFO, ID_FD, ID_CLASSIC]) | st.integers(
    0, 0x7FF)
frames = st.lists(st.tuples(frame_ids, st.binary(max_size=64)), max_size=40)


def _front_end(fd: bool) -> CanFrontEnd:
    return CanFrontEnd("fe", CHANNELS, 1024.0, bus=can.Bus(interface="virtual",
                                                          channel="fuzz-unused"),
                       frame="fd" if fd else "classic")


def _valid(fe: CanFrontEnd, seq: int) -> list[can.Message]:
    """One whole block of sample frames, encoded with cantools from the DBC."""
    msg = load_dbc().get_message_by_frame_id(fe.layout.frame_id)
    out = []
    for group in sorted({c.input // fe.layout.per_group for c in CHANNELS}):
        values: dict[str, Any] = {s.name: 0 for s in msg.signals}
        values.update({"GROUP": group, "SEQ": seq})
        out.append(can.Message(arbitration_id=fe.layout.frame_id, data=msg.encode(values),
                               is_fd=fe.layout.fd, is_extended_id=False))
    return out


@FUZZ
@given(frames, st.booleans())
def test_any_frames_leave_the_stream_alive(spec: list[tuple[int, bytes]], fd: bool) -> None:
    fe = _front_end(fd)
    try:
        garbage = [can.Message(arbitration_id=i, data=d[: 64 if fd else 8], is_fd=fd,
                               is_extended_id=False) for i, d in spec]
        feed = _valid(fe, 1) + garbage + _valid(fe, 2)
        fe._link = _Feed(feed, fe)  # type: ignore[assignment]
        fe._read_loop()
        assert fe._buffer._error is None, fe._buffer._error
        assert fe.health.frames >= 2 * len(_valid(fe, 0))  # the good blocks went through
        assert np.isfinite(fe.health.bad_frames)
    finally:
        fe._link.close = lambda: None  # type: ignore[method-assign, union-attr]
