"""Clock drift and start offset between the hammer digitiser and the front end."""

from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.base import ChannelConfig
from drivers.errors import SyncError
from drivers.frontend_can import CanFrontEnd
from drivers.hammer_serial import SerialHammer
from drivers.sync import align, check_alignment, fit_clock
from hardware_mocks.frontend_device import FrontEndDevice
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.physics import REPLY_TIMEOUT, STALL_TIMEOUT

#: the drivers of the in-process mocks: the mock benches' times (the mocks share this host)
PATIENT = {"stall_timeout": STALL_TIMEOUT, "reply_timeout": REPLY_TIMEOUT}
#: seconds a read may take: only guards against a hang
HANG = 30.0


def run(physics, channel: str, hammer_ppm: float, hammer_offset: float):
    fe_dev = FrontEndDevice(physics, channel=channel, wiring=[-1], sensitivity=[2.25])
    ham_dev = HammerDevice(physics, ppm=hammer_ppm, offset=hammer_offset, frame_len=32)
    fe = CanFrontEnd("fe", [ChannelConfig("F_fe", 0, "force", 2.25)], fs=1024,
                     bus_kwargs={"interface": "virtual", "channel": channel}, **PATIENT)
    hammer = SerialHammer("hammer", ham_dev.path, [ChannelConfig("F", 0, "force", 2.25)],
                          fs=2048, **PATIENT)
    try:
        for dev in (fe, hammer):
            dev.open()
        fe.start()
        hammer.start()  # the common start: one after the other, clocks measured below
        t_hit = time.monotonic() + 0.9
        physics.hit(exc=0, peak=200.0, duration=0.006, delay=0.9)
        fe.read_block(256, timeout=HANG)  # before the hammer started
        ref = fe.read_block(1536, timeout=HANG)
        other = hammer.read_block(4096, timeout=HANG)
        fits = {"fe": fit_clock(fe.clock_pairs(), 1024), "hammer": fit_clock(
            hammer.clock_pairs(), 2048)}
        # the truth: when each device took its sample 0, on the host's clock
        started = ham_dev.clock.t_first - fe_dev.clock.t_first
        return ref, other, fits, t_hit, started
    finally:
        for d in (fe, hammer, fe_dev, ham_dev):
            d.shutdown()


def test_drift_and_offset_are_measured_and_corrected(engine_physics_factory) -> None:
    physics = engine_physics_factory()
    ref, other, fits, _, started = run(physics, "sync-1", hammer_ppm=5000.0,
                                       hammer_offset=0.05)
    fe_fit, ham_fit = fits["fe"], fits["hammer"]
    assert abs(fe_fit.ppm) < 1000
    assert ham_fit.ppm == pytest.approx(5000.0, abs=1000.0)
    # the hammer's sample 0 came 50 ms after the front end's, plus the start sequence
    # (the two START commands, one after the other: longer on a loaded host)
    assert started >= 0.05
    assert ham_fit.t0 - fe_fit.t0 == pytest.approx(started, abs=0.02)
    check_alignment(fits)
    aligned = align(ref, fe_fit, other, ham_fit, "hammer")
    peak_ref = np.argmax(ref.data[0])
    # without correction, the same sample index points elsewhere in the hammer's record
    naive = np.argmax(other.data[0]) / 2 - ref.first_sample
    assert abs(naive - peak_ref) > 40
    assert abs(np.argmax(aligned.data[0]) - peak_ref) <= 3  # within 3 ms at 1024 Hz
    assert aligned.data.shape == ref.data.shape and aligned.channels[0].name == "F"


def test_refused_when_streams_cannot_be_aligned(engine_physics_factory) -> None:
    physics = engine_physics_factory()
    ref, other, fits, _, _ = run(physics, "sync-2", hammer_ppm=30000.0, hammer_offset=0.0)
    # the rate alone (the timing's scatter, which a loaded host raises, is
    # tests/drivers/test_sync_clock.py's)
    with pytest.raises(SyncError, match="hammer: clock off by"):
        check_alignment(fits, max_ppm=10000, max_residual=np.inf)
    with pytest.raises(SyncError, match="streams do not overlap"):
        align(ref, fits["fe"], other, fits["hammer"].__class__(
            **{**fits["hammer"].__dict__, "t0": fits["hammer"].t0 + 5.0}), "hammer")
    gappy = other.__class__(**{**other.__dict__, "missing": 3})
    with pytest.raises(SyncError, match="3 samples lost"):
        align(ref, fits["fe"], gappy, fits["hammer"], "hammer")
    with pytest.raises(SyncError, match="too short"):
        fit_clock([(0.0, 1)] * 5, 1024)
