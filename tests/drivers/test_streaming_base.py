"""``StreamingFrontEnd``: the base owns the sample buffer, reads blocks out of it and gives
the clock pairs (the CAN front end and the serial hammer share it)."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from drivers.base import ChannelConfig, StreamingFrontEnd
from drivers.errors import DeviceTimeoutError
from drivers.frontend_can import CanFrontEnd
from drivers.hammer_serial import SerialHammer
from drivers.stream import SampleBuffer


class _Streamer(StreamingFrontEnd):
    """Two inputs; starting it "receives" two frames of 3 samples, one at host time 10 s,
    one at 10.5 s."""

    n_inputs = 2

    @classmethod
    def from_config(cls, config: Any, **overrides: Any) -> _Streamer:
        raise NotImplementedError

    def _shutdown_internal(self) -> None:
        pass

    def _open_internal(self) -> None:
        pass

    def _start_internal(self) -> None:
        self._buffer.reset()
        self._buffer.append(np.array([[1.0, 2, 3], [4, 5, 6]]), host_time=10.0)
        self._buffer.append(np.array([[7.0, 8, 9], [10, 11, 12]]), host_time=10.5,
                            overloaded=frozenset({1}))

    def _stop_internal(self) -> None:
        pass


def test_blocks_and_clock_pairs_come_from_the_base() -> None:
    dev = _Streamer("s", [ChannelConfig("F", 0, "force", 2.25),
                          ChannelConfig("a", 1, "acceleration", 10.2)], 1024.0,
                    stall_timeout=0.05)
    with dev:
        dev.open()
        dev.start()
        first = dev.read_block(4)
        assert_array_equal(first.data, [[1, 2, 3, 7], [4, 5, 6, 10]])
        assert first.first_sample == 0 and first.overloaded == ("a",)
        second = dev.read_block(2)
        assert second.first_sample == 4 and second.overloaded == ("a",)
        # taken by: the earliest bound the frames give (the second frame came late)
        assert first.host_time == pytest.approx(10.0 - 2 / 1024.0, abs=1e-12)
        assert second.host_time == pytest.approx(10.0 + 2 / 1024.0, abs=1e-12)
        assert dev.clock_pairs() == [(10.0, 3), (10.5, 6)]
        # nothing more arrives, and this reader never says it polled: the silence counts
        # up to now, and the stall timeout (not the read's 30 s) ends the read
        with pytest.raises(DeviceTimeoutError, match=r"no data for \d"):
            dev.read_block(1, timeout=30.0)


def test_a_reader_that_listens_and_hears_nothing_is_a_stall() -> None:
    buf = SampleBuffer(1, "dev")
    stop = threading.Event()

    def listen() -> None:  # a reader polling an empty transport
        while not stop.is_set():
            started = time.monotonic()
            stop.wait(0.01)
            buf.polled(started)

    reader = threading.Thread(target=listen)
    reader.start()
    try:
        with pytest.raises(DeviceTimeoutError, match=r"dev: no data for 0\.[2-9]\d* s"):
            buf.take(1, timeout=30.0, stall_timeout=0.2)
    finally:
        stop.set()
        reader.join()


def test_a_reader_that_did_not_run_is_not_a_silent_device() -> None:
    """A loaded host, a stopped process: the reader polls no more for three stall times,
    then finds what arrived meanwhile. The silence counts only while it listened."""
    buf = SampleBuffer(1, "dev")
    started = time.monotonic()
    buf.append(np.array([[1.0]]))
    buf.polled(started)  # the poll that brought the first sample

    def starved_reader() -> None:
        time.sleep(0.6)  # the reader gets no time (the scenario, not a wait for it)
        buf.append(np.array([[2.0, 3.0]]))

    reader = threading.Thread(target=starved_reader)
    reader.start()
    try:
        data, first, missing, _ = buf.take(3, timeout=30.0, stall_timeout=0.2)
    finally:
        reader.join()
    assert_array_equal(data, [[1.0, 2.0, 3.0]])
    assert (first, missing) == (0, 0)


def test_both_streaming_drivers_are_streaming_front_ends() -> None:
    assert issubclass(CanFrontEnd, StreamingFrontEnd)
    assert issubclass(SerialHammer, StreamingFrontEnd)
    for cls in (CanFrontEnd, SerialHammer):
        assert "clock_pairs" not in vars(cls) and "_read_block_internal" not in vars(cls)
