"""The simulated FE-16 front end: raw frames, the model's accelerations, and each fault."""

from __future__ import annotations

import struct
import time
from collections.abc import Iterator

import can
import numpy as np
import pytest
from scipy.signal import find_peaks

from drivers.base import ChannelConfig
from drivers.errors import DeviceTimeoutError
from drivers.frontend_can import CanFrontEnd, load_dbc
from hardware_mocks.frontend_device import FrontEndDevice
from hardware_mocks.physics import STALL_TIMEOUT, BenchPhysics
from hardware_mocks.shaker_device import ShakerDevice


def bench_channels(physics: BenchPhysics, accel_range: float = 1.0,
                   accel_sens: float = 10.2) -> list[ChannelConfig]:
    b = physics.bench
    chans = [ChannelConfig(f"a{i}", i, "acceleration", accel_sens, range_v=accel_range,
                           node=int(b.resp_nodes[i]), direction=tuple(b.resp_dirs[i]))
             for i in range(12)]
    chans.append(ChannelConfig("F", 12, "force", 2.25, range_v=5.0))
    return chans


@pytest.fixture
def channel_name(request: pytest.FixtureRequest) -> str:
    return f"fe-{request.node.name}"


def rig(physics: BenchPhysics, channel: str, frame: str = "fd", fs: float = 1024,
        accel_range: float = 1.0, accel_sens: float = 10.2, **dev_kwargs: object
        ) -> tuple[FrontEndDevice, CanFrontEnd]:
    sens = [accel_sens] * 12 + [2.25]
    dev = FrontEndDevice(physics, channel=channel, sensitivity=sens,
                         **dev_kwargs)
    fe = CanFrontEnd("fe", bench_channels(physics, accel_range, accel_sens), fs=fs, frame=frame,
                     stall_timeout=STALL_TIMEOUT,
                     bus_kwargs={"interface": "virtual", "channel": channel})
    fe.open()
    fe.start()
    return dev, fe


@pytest.fixture
def fd_rig(engine_physics_factory, channel_name: str
           ) -> Iterator[tuple[FrontEndDevice, CanFrontEnd]]:
    dev, fe = rig(engine_physics_factory(), channel_name)
    yield dev, fe
    fe.shutdown()
    dev.shutdown()


def test_raw_identify_and_first_frame(engine_physics_factory, channel_name: str) -> None:
    with FrontEndDevice(engine_physics_factory(), channel=channel_name) as dev, \
            can.Bus(interface="virtual", channel=channel_name) as bus:
        def ask(data: str) -> can.Message:
            bus.send(can.Message(arbitration_id=0x100, data=bytes.fromhex(data),
                                 is_extended_id=False))
            msg = bus.recv(1.0)
            while msg is not None and msg.arbitration_id in (0x200, 0x201):
                msg = bus.recv(1.0)  # sample frames already on their way while streaming
            assert msg is not None
            return msg
        info = ask("06 00 00 00 00 00 00 00")
        assert (info.arbitration_id, bytes(info.data)) == (0x102, bytes.fromhex(
            "92 10 00 00 02 04 10 00"))
        ack = ask("01 00 02 00 01 00 00 00")  # 512 Hz, classic, group 0
        assert bytes(ack.data[:2]) == b"\x01\x00"
        assert bytes(ask("01 00 02 07 01 00 00 00").data[:2]) == b"\x01\x01"  # bad format
        assert bytes(ask("09 00 00 00 00 00 00 00").data[:2]) == b"\x09\x03"  # unknown
        assert bytes(ask("03 00 00 00 00 00 00 00").data[:2]) == b"\x03\x00"  # START
        frame = bus.recv(1.0)
        assert frame is not None and frame.arbitration_id == 0x201 and not frame.is_fd
        assert bytes(frame.data) == bytes.fromhex("00 00 00 00 00 00 00 00")  # seq 0, group 0
        assert bytes(ask("01 00 04 01 0f 00 00 00").data[:2]) == b"\x01\x02"  # busy
        assert dev.running


def test_mock_frames_decode_with_the_dbc(engine_physics_factory, channel_name: str) -> None:
    """Cross-check: the mock's own packing agrees with the DBC, read by cantools."""
    db = load_dbc()
    physics = engine_physics_factory()
    with FrontEndDevice(physics, channel=channel_name, accel_noise=5.0) as dev, \
            can.Bus(interface="virtual", channel=channel_name) as bus:
        dev.range_mv[:] = 1000
        bus.send(can.Message(arbitration_id=0x100, data=bytes.fromhex("03" + "00" * 7),
                             is_extended_id=False))
        frames = []
        deadline = time.monotonic() + 30.0  # only guards against a hang
        while len(frames) < 40 and time.monotonic() < deadline:
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x200:
                frames.append(msg)
        for msg in frames:
            sig = db.decode_message(0x200, msg.data, scaling=False)
            raw = [int.from_bytes(msg.data[4 + 3 * i: 7 + 3 * i], "little", signed=True)
                   for i in range(20)]
            assert [sig[f"S{k}C{j}"] for k in range(5) for j in range(4)] == raw
            assert (sig["SEQ"], sig["GROUP"]) == struct.unpack_from("<HB", msg.data)
        values = [db.decode_message(0x200, m.data, scaling=False)["S2C1"] for m in frames]
        assert len(frames) == 40 and min(values) < 0 < max(values)


@pytest.mark.parametrize(("frame", "fs"), [("fd", 1024), ("classic", 256)])
def test_hit_gives_the_models_accelerations(engine_physics_factory, channel_name: str,
                                            frame: str, fs: float) -> None:
    physics = engine_physics_factory()
    dev, fe = rig(physics, channel_name, frame=frame, fs=fs)
    try:
        physics.hit(exc=4, peak=150.0, duration=0.005)
        block = fe.read_block(int(fs), timeout=3.0)
        assert block.complete and fe.health.ok()
        force = block.channel("F")
        assert force.sum() / fs == pytest.approx(2 * 150.0 * 0.005 / np.pi, rel=1e-3)
        padded = np.concatenate([force, np.zeros(int(8 * fs))])
        expected = physics.response(padded, 4, fs)[:, : int(fs)]
        err = np.abs(block.data[:12] - expected).max() / np.abs(expected).max()
        # at 256 Hz the 118.5 Hz elastic mode sits near Nyquist, where time_response's
        # discrete system depends a little on the record length (its Nyquist bin)
        assert err < (1e-4 if fs > 512 else 2e-3)
    finally:
        fe.shutdown()
        dev.shutdown()


def test_double_hit(fd_rig: tuple[FrontEndDevice, CanFrontEnd]) -> None:
    dev, fe = fd_rig
    dev.physics.hit(exc=0, peak=200.0, duration=0.004, double=(0.03, 0.5))
    force = fe.read_block(512, timeout=2.0).channel("F")
    peaks, _ = find_peaks(force, height=40.0)
    assert len(peaks) == 2 and (peaks[1] - peaks[0]) / 1024 == pytest.approx(0.03, abs=2e-3)


def test_dropped_frames(fd_rig: tuple[FrontEndDevice, CanFrontEnd]) -> None:
    dev, fe = fd_rig
    dev.faults.drop_every = 7
    block = fe.read_block(1024, timeout=2.0)
    dev.faults.drop_every = 0
    # the reader may already have counted losses in frames beyond this block
    assert fe.health.gaps > 0 and 0 < block.missing <= fe.health.lost_samples
    assert np.isnan(block.data).any() and not block.complete


def test_undecodable_frames(fd_rig: tuple[FrontEndDevice, CanFrontEnd]) -> None:
    dev, fe = fd_rig
    dev.faults.bad_frame_every = 9
    block = fe.read_block(1024, timeout=2.0)
    dev.faults.bad_frame_every = 0
    assert fe.health.bad_frames > 10 and block.missing > 0


def test_sequence_jump(fd_rig: tuple[FrontEndDevice, CanFrontEnd]) -> None:
    dev, fe = fd_rig
    fe.read_block(100, timeout=2.0)
    dev.faults.seq_jump = 4
    block = fe.read_block(500, timeout=2.0)
    assert (fe.health.gaps, fe.health.lost_samples, block.missing) == (1, 20, 20)


def test_buffer_overflow(fd_rig: tuple[FrontEndDevice, CanFrontEnd]) -> None:
    dev, fe = fd_rig
    fe.read_block(100, timeout=2.0)
    dev.faults.overflow = 50
    fe.read_block(600, timeout=2.0)
    assert fe.request_status() is not None
    assert fe.health.buffer_overflows == 1 and fe.health.lost_samples == 50


def test_overload(engine_physics_factory, channel_name: str) -> None:
    physics = engine_physics_factory()
    dev, fe = rig(physics, channel_name, accel_range=1.0, accel_sens=100.0)
    try:
        physics.hit(exc=0, peak=1000.0, duration=0.004)  # ~ 15 m/s^2 at a0: 1.5 V on 1 V
        block = fe.read_block(1024, timeout=2.0)
        assert "a0" in block.overloaded and "F" not in block.overloaded
        assert np.nanmax(np.abs(block.channel("a0"))) == pytest.approx(1000 / 100.0, rel=1e-6)
        assert fe.health.overloaded >= {"a0"}
    finally:
        fe.shutdown()
        dev.shutdown()


def test_sensor_noise(engine_physics_factory, channel_name: str) -> None:
    dev, fe = rig(engine_physics_factory(), channel_name, accel_noise=0.02, force_noise=0.1)
    try:
        block = fe.read_block(1024, timeout=2.0)
        assert np.std(block.data[:12], axis=1) == pytest.approx(np.full(12, 0.02), rel=0.15)
        assert np.std(block.channel("F")) == pytest.approx(0.1, rel=0.15)
    finally:
        fe.shutdown()
        dev.shutdown()


@pytest.mark.parametrize("fault", ["silent", "unplug"])
def test_device_gone_times_out(fd_rig: tuple[FrontEndDevice, CanFrontEnd], fault: str) -> None:
    dev, fe = fd_rig
    fe.read_block(100, timeout=2.0)
    if fault == "silent":
        dev.faults.silent = True
    else:
        dev.unplug()
    # the stall timeout ends the read ("no data for"), not the 30 s read timeout
    with pytest.raises(DeviceTimeoutError, match=r"no data for \d+\.\d\d s \(device stopped"):
        fe.read_block(100000, timeout=30.0)
    with pytest.raises(DeviceTimeoutError, match="no answer to STOP"):
        fe.stop()


def test_no_sample_is_sent_before_its_shaker_force_is_simulated(
        engine_physics_factory, channel_name: str) -> None:
    """A loaded host: simulating the shaker's force takes longer (0.3 s a call) than the
    0.1 s it simulates. Every sample sent carries the force, none is sent empty."""
    physics = engine_physics_factory()
    simulate_forces = physics.source_forces

    def slow(t: np.ndarray) -> list:
        time.sleep(0.3)  # the scenario: the device's thread gets the CPU late
        return simulate_forces(t)

    physics.source_forces = slow  # type: ignore[method-assign]
    with ShakerDevice(physics, exc=2, force_per_volt=50.0) as shaker:
        shaker.level, shaker.ramp, shaker.output = 1.0, 0.0, True
        shaker.function, shaker.frequency = "SIN", 50.0  # 50 N peak at 50 Hz
        dev, fe = rig(physics, channel_name)
        try:
            force = fe.read_block(2048, timeout=60.0).channel("F")  # (a hang guard)
        finally:
            fe.shutdown()
            dev.shutdown()
    # a sine sampled at 1024 Hz is never within 1 mN of zero: such a sample was sent empty
    assert np.count_nonzero(np.abs(force) < 1e-3) == 0
    assert np.sqrt(np.mean(force**2)) == pytest.approx(50.0 / np.sqrt(2), rel=0.01)
