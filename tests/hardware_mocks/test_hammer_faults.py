"""Hammer driver against the simulated digitiser: hits, and each injected fault detected."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from scipy.signal import find_peaks

from drivers.base import ChannelConfig
from drivers.errors import DeviceNotAvailableError, DeviceTimeoutError
from drivers.hammer_serial import SerialHammer
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.physics import STALL_TIMEOUT

FS = 4096


def channel(range_v: float = 5.0) -> ChannelConfig:
    return ChannelConfig("F", 0, "force", sensitivity=2.25, range_v=range_v)


@pytest.fixture
def rig(engine_physics_factory) -> Iterator[tuple[HammerDevice, SerialHammer]]:
    dev = HammerDevice(engine_physics_factory(), frame_len=64)
    hammer = SerialHammer("hammer", dev.path, [channel()], fs=FS,
                          stall_timeout=STALL_TIMEOUT)
    hammer.open()
    hammer.start()
    yield dev, hammer
    hammer.shutdown()
    dev.shutdown()


def test_hit_is_measured_as_a_half_sine(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    dev.hit(exc=3, peak=300.0, duration=0.004, delay=0.05)
    f = hammer.read_block(FS // 2, timeout=2.0).data[0]
    assert f.max() == pytest.approx(300.0, rel=0.01)
    assert f.sum() / FS == pytest.approx(2 * 300.0 * 0.004 / np.pi, rel=1e-3)  # impulse, N s
    assert hammer.health.ok()


def test_double_hit_shows_two_pulses(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    # a 4 ms pulse spans 16 samples: its sampled peaks are its peaks to 1 %
    dev.hit(exc=0, peak=300.0, duration=0.004, double=(0.012, 0.4))
    f = hammer.read_block(FS // 2, timeout=2.0).data[0]
    peaks, _ = find_peaks(f, height=50.0)
    assert len(peaks) == 2
    assert (peaks[1] - peaks[0]) / FS == pytest.approx(0.012, abs=2 / FS)
    assert f[peaks[1]] / f[peaks[0]] == pytest.approx(0.4, rel=0.02)


def test_dropped_frames_are_counted_and_nan(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    dev.faults.drop_every = 5
    block = hammer.read_block(FS // 2, timeout=2.0)
    dev.faults.drop_every = 0
    assert hammer.health.gaps >= 4
    assert hammer.health.lost_samples == 64 * hammer.health.gaps
    assert block.missing > 0 and block.missing % 64 == 0
    assert np.isnan(block.data).sum() == block.missing and not block.complete


def test_corrupted_frames_fail_the_crc(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    dev.faults.corrupt_every = 4
    block = hammer.read_block(FS // 2, timeout=2.0)
    dev.faults.corrupt_every = 0
    assert hammer.health.bad_frames >= 5
    assert hammer.health.gaps == hammer.health.bad_frames  # each bad frame is a lost frame
    assert block.missing == 64 * hammer.health.gaps


def test_sequence_jump_is_a_gap(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    hammer.read_block(256, timeout=2.0)
    dev.faults.seq_jump = 3
    block = hammer.read_block(1024, timeout=2.0)
    assert (hammer.health.gaps, hammer.health.lost_samples) == (1, 192)
    assert block.missing == 192


def test_line_noise_is_skipped(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    hammer.read_block(256, timeout=2.0)
    dev.faults.garbage = b"\x00\xff\xa5\x13noise"
    block = hammer.read_block(1024, timeout=2.0)
    assert hammer.health.resync_bytes == 9 and block.complete


def test_device_that_stops_answering_times_out(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    hammer.read_block(256, timeout=2.0)
    dev.faults.silent = True
    # the stall timeout ends the read ("no data for"), not the 20 s read timeout ("only ...
    # samples within 20 s")
    with pytest.raises(DeviceTimeoutError, match=r"no data for \d+\.\d\d s \(device stopped"):
        hammer.read_block(FS * 10, timeout=20.0)
    with pytest.raises(DeviceTimeoutError):
        hammer.stop()


def test_unplugged_mid_run_is_not_available(rig: tuple[HammerDevice, SerialHammer]) -> None:
    dev, hammer = rig
    hammer.read_block(256, timeout=2.0)
    dev.unplug()
    with pytest.raises(DeviceNotAvailableError, match="unplugged"):  # not the read timeout
        hammer.read_block(FS * 10, timeout=20.0)


def test_overload_is_flagged(engine_physics_factory) -> None:
    with HammerDevice(engine_physics_factory()) as dev, \
            SerialHammer("hammer", dev.path, [channel(range_v=1.0)], fs=FS) as hammer:
        hammer.start()
        dev.hit(exc=0, peak=1000.0)  # 2.25 V at 2.25 mV/N on the 1 V range
        block = hammer.read_block(FS // 2, timeout=2.0)
        assert block.overloaded == ("F",) and hammer.health.overloaded == {"F"}
        assert np.nanmax(block.data) == pytest.approx(1000.0 / 2.25, rel=1e-6)  # clipped


def test_sensor_noise_has_the_set_rms(engine_physics_factory) -> None:
    with HammerDevice(engine_physics_factory(), noise=0.5, seed=3) as dev, \
            SerialHammer("hammer", dev.path, [channel()], fs=FS) as hammer:
        hammer.start()
        f = hammer.read_block(FS // 2, timeout=2.0).data[0]
        assert np.std(f) == pytest.approx(0.5, rel=0.1)
