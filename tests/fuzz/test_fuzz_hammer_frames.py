"""The serial hammer's frame decoder on any bytes: no exception, every byte accounted for."""

from __future__ import annotations

import binascii
import struct

import numpy as np
from _fuzz import FUZZ
from hypothesis import given
from hypothesis import strategies as st

from drivers.hammer_serial import FLAG_END, FLAG_INT32, HEADER, MAX_SAMPLES, SYNC, decode_frames


def frame(seq: int, samples: list[int], flags: int = 0) -> bytes:
    width = 4 if flags & FLAG_INT32 else 2
    body = HEADER.pack(SYNC, flags, 0, seq, len(samples)) + struct.pack(
        f"<{len(samples)}{'i' if width == 4 else 'h'}", *samples)
    return body + struct.pack("<H", binascii.crc_hqx(body[2:], 0xFFFF))


frames_st = st.lists(st.tuples(st.integers(0, 0xFFFF),
                               st.lists(st.integers(-32768, 32767), min_size=1, max_size=64),
                               st.sampled_from([0, FLAG_INT32, 0x02])), max_size=6)
no_sync = st.binary(max_size=64).filter(lambda b: SYNC[:1] not in b)


@FUZZ
@given(st.binary(max_size=4096))
def test_any_bytes_decode_without_exception(data: bytes) -> None:
    buf = bytearray(data)
    frames, bad, skipped = decode_frames(buf)
    assert bad >= 0 and skipped >= 0 and len(buf) <= len(data)
    for f in frames:
        assert 0 < f.counts.size <= MAX_SAMPLES


@FUZZ
@given(frames_st, st.lists(no_sync, min_size=7, max_size=7))
def test_frames_between_garbage_are_all_recovered(spec: list[tuple[int, list[int], int]],
                                                  garbage: list[bytes]) -> None:
    stream = garbage[0]
    for k, (seq, samples, flags) in enumerate(spec):
        stream += frame(seq, samples, flags) + garbage[k + 1]
    buf = bytearray(stream)
    frames, bad, skipped = decode_frames(buf)
    assert [(f.seq, f.counts.tolist()) for f in frames] == [(s, x) for s, x, _ in spec]
    assert bad == 0 and not buf
    assert skipped == sum(len(g) for g in garbage[: len(spec) + 1])


@FUZZ
@given(frames_st, st.integers(0, 10_000), st.integers(0, 255))
def test_a_corrupted_byte_costs_at_most_its_frame(spec: list[tuple[int, list[int], int]],
                                                  where: int, value: int) -> None:
    head = b"".join(frame(s, x, f) for s, x, f in spec)
    # the stream goes on: a corrupted length field may hold the decoder for up to one
    # largest frame, never longer
    tail = b"".join(frame(9, [7] * 256, FLAG_INT32) for _ in range(5)) + frame(0, [0], FLAG_END)
    stream = bytearray(head + tail)
    i = where % max(1, len(head))
    stream[i] = (stream[i] + 1 + value % 255) % 256  # a different byte
    frames, _, _ = decode_frames(stream)
    got = [(f.seq, f.counts.tolist()) for f in frames]
    sent = [(s, x) for s, x, _ in spec]
    lost = [f for f in sent if f not in got]
    assert (0, [0]) in got  # the end of the stream is always reached
    assert len(lost) <= 2  # the frame hit (and one whose header it may swallow)
    assert all(np.isfinite(f.counts).all() for f in frames)
