"""The shaker mock as a force on the bench: through its SCPI driver to the front end's H1."""

from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.base import ChannelConfig
from drivers.frontend_can import CanFrontEnd
from drivers.shaker_scpi import ScpiShaker
from hardware_mocks.frontend_device import FORCE, FrontEndDevice, shaker_force
from hardware_mocks.physics import HEARTBEAT, REPLY_TIMEOUT, BenchPhysics
from hardware_mocks.shaker_device import ShakerDevice
from processing.spectral import coherence, h1, welch_spectra

FS = 512.0
#: the drivers of the mock shakers: a mock bench's watchdog and answer times (the mocks are
#: threads of this loaded process)
PATIENT = {"heartbeat": HEARTBEAT, "reply_timeout": REPLY_TIMEOUT}


def test_random_excitation_gives_the_models_frf(engine_physics_factory,
                                                request: pytest.FixtureRequest) -> None:
    physics: BenchPhysics = engine_physics_factory()
    exc, channel = 2, f"shk-{request.node.name}"
    chans = [ChannelConfig(f"a{i}", i, "acceleration", 10.2, range_v=1.0) for i in range(12)]
    chans.append(ChannelConfig("F", 12, "force", 2.25, range_v=5.0))
    with ShakerDevice(physics, exc=exc, force_per_volt=50.0) as shaker_dev, \
            FrontEndDevice(physics, channel=channel) as fe_dev:
        shaker = ScpiShaker("shaker", shaker_dev.path, ramp=0.1, **PATIENT)
        # the mock simulates the shaker's past (one impulse response long) when it starts:
        # allow it more than the default 0.5 s of silence on a loaded machine
        fe = CanFrontEnd("fe", chans, fs=FS, stall_timeout=5.0,
                         bus_kwargs={"interface": "virtual", "channel": channel})
        try:
            shaker.open()
            shaker.set_waveform("random", f_start=2.0, f_stop=FS / 2.56)
            shaker.set_level(0.5)
            shaker.start()
            shaker.wait_ramp()
            fe.open()
            fe.start()
            block = fe.read_block(int(8 * FS), timeout=15.0)
        finally:
            fe.shutdown()
            shaker.shutdown()
        deadline = time.monotonic() + 30.0  # only guards against a hang
        while shaker_dev.output and time.monotonic() < deadline:  # OUTP OFF on its way
            time.sleep(0.01)
        assert fe_dev.frames_sent > 0 and not shaker_dev.output
        assert not shaker_dev.errors  # driven all along (its watchdog never fired)
    assert block.complete and fe.health.ok()
    force = block.channel("F")
    assert force.std() == pytest.approx(0.5 * 50.0, rel=0.05)  # level 0.5 V RMS x 50 N/V
    sp = welch_spectra(np.vstack([force, block.data[:12]]), FS, 512)
    H, coh = h1(sp)[:, 0], coherence(sp)
    f = np.fft.rfftfreq(512, 1 / FS)
    b = physics.bench
    exact = b.model.frf(f, physics.resp_xyz, b.resp_dirs, physics.exc_xyz[exc : exc + 1],
                        b.exc_dirs[exc : exc + 1])[:, 0]
    band = (f >= 3.0) & (f <= FS / 2.56 - 2.0)
    rel = np.abs(H - exact)[:, band] / np.abs(exact)[:, band]
    coh = coh[:, band]
    # no sensor noise: coherence below 1 and the H1 error both come from leakage (Hann
    # window, 1 Hz lines), largest at the resonances
    # measured over runs: 44-67 % of lines above 0.999, where the error is at most
    # 1.4-1.5 %; median error 0.2-0.5 % where coherence > 0.99 (up to 5 % at single lines)
    assert np.mean(coh > 0.999) > 0.3
    assert rel[coh > 0.999].max() < 0.03
    assert np.median(rel[coh > 0.99]) < 0.01


def test_waveforms_ramp_and_attachment(engine_physics_factory) -> None:
    physics: BenchPhysics = engine_physics_factory()
    with ShakerDevice(physics, force_per_volt=10.0) as dev:
        t = time.monotonic() + np.arange(4096) / 4096.0
        assert physics.continuous_force(t) == {}  # not attached
        dev.attach(3)
        assert not np.any(physics.continuous_force(t)[3])  # output off
        with pytest.raises(ValueError, match="out of range"):
            dev.attach(18)
        dev.level, dev.ramp, dev.output = 1.0, 0.0, True
        dev.function, dev.frequency = "SIN", 50.0
        time.sleep(0.05)
        f = physics.continuous_force(t)[3]
        assert np.abs(f).max() == pytest.approx(10.0, rel=1e-3)
        spectrum = np.abs(np.fft.rfft(f))
        assert np.argmax(spectrum) == 50
        dev.function, dev.f_start, dev.f_stop, dev.period, dev.duty = "BRAN", 5, 100, 0.5, 0.5
        f = dev.force(t)
        on = np.mod(t - dev._t_origin, 0.5) < 0.25
        assert not np.any(f[~on]) and np.std(f[on]) == pytest.approx(10.0, rel=0.1)
        dev.ramp, dev.output = 1.0, False  # ramps down at 1 V/s
        f = dev.force(time.monotonic() + np.array([0.5, 2.0]))
        assert f[1] == 0.0
        dev.attach(None)
        assert physics.continuous_force(t) == {}


def test_no_force_before_the_output_came_on(engine_physics_factory, monkeypatch) -> None:
    """A front end started as the output comes on simulates the shaker's past, one impulse
    response long (8 s at 1024 Hz): the force is 0 before the output left 0 V, and the
    multisine (4096 lines a sample) is evaluated only after. Taken as on all along, two
    shakers' past held the mock front end's thread for 2.2-3.7 s on a loaded machine (its
    first loop ran after the output came on), and its driver took the device for silent."""
    physics: BenchPhysics = engine_physics_factory()
    with ShakerDevice(physics, force_per_volt=10.0) as dev:
        dev.function, dev.f_start, dev.f_stop = "RAND", 4.0, 400.0
        dev.level, dev.ramp, dev.output = 1.0, 0.5, True
        deadline = time.monotonic() + 30.0  # only guards against a hang
        while dev.level_now == 0.0 and time.monotonic() < deadline:
            time.sleep(0.005)
        on = dev._rest_until  # the ramp's start, as the device saw it
        t = on - 8.0 + np.arange(int(8.2 * 1024)) / 1024.0
        asked: list[int] = []
        whole = dev.multisine

        def counted(tau: np.ndarray, f0: float, f1: float) -> np.ndarray:
            asked.append(tau.size)
            return whole(tau, f0, f1)

        monkeypatch.setattr(dev, "multisine", counted)
        f = dev.force(t)
    after = t >= on
    assert asked == [np.count_nonzero(after)]
    assert not np.any(f[~after]) and np.all(f[after] != 0.0)


@pytest.mark.slow
def test_two_shakers_each_on_its_own_force_input(engine_physics_factory,
                                                 request: pytest.FixtureRequest) -> None:
    """Two shakers driven at once (different random signals), each force sensor on its own
    front-end input: the two-reference H1 gives both excitations' FRFs of the model."""
    physics: BenchPhysics = engine_physics_factory()
    excs, channel = (2, 5), f"shk2-{request.node.name}"
    chans = [ChannelConfig(f"a{i}", i, "acceleration", 10.2, range_v=1.0) for i in range(12)]
    chans += [ChannelConfig(f"F{k + 1}", 12 + k, "force", 2.25, range_v=5.0) for k in (0, 1)]
    chans.append(ChannelConfig("Fsum", 14, "force", 2.25, range_v=5.0))
    wiring = [*range(12), shaker_force(0), shaker_force(1), FORCE]
    with ShakerDevice(physics, exc=excs[0], seed=0, sensor=0) as dev1, \
            ShakerDevice(physics, exc=excs[1], seed=1, sensor=1) as dev2, \
            FrontEndDevice(physics, channel=channel, wiring=wiring) as fe_dev:
        shakers = [ScpiShaker(f"shaker{k}", d.path, ramp=0.1, **PATIENT)
                   for k, d in enumerate((dev1, dev2))]
        # the mock simulates both shakers' past (one impulse response long) when it starts:
        # allow it more than the default 0.5 s of silence on a loaded machine
        fe = CanFrontEnd("fe", chans, fs=FS, stall_timeout=5.0,
                         bus_kwargs={"interface": "virtual", "channel": channel})
        try:
            for s in shakers:
                s.open()
                s.set_waveform("random", f_start=2.0, f_stop=FS / 2.56)
                s.set_level(0.5)
                s.start()
            for s in shakers:
                s.wait_ramp()
            fe.open()
            fe.start()
            block = fe.read_block(int(16 * FS), timeout=30.0)
        finally:
            fe.shutdown()
            for s in shakers:
                s.shutdown()
        assert fe_dev.frames_sent > 0
        assert not dev1.errors and not dev2.errors  # driven all along
    assert block.complete and fe.health.ok()
    f1, f2 = block.channel("F1"), block.channel("F2")
    # 0.5 V RMS x 50 N/V each (23.7 N seen once on a loaded machine)
    assert f1.std() == pytest.approx(25.0, rel=0.1) and f2.std() == pytest.approx(25.0, rel=0.1)
    # each input shows its own shaker: the sum input is their sum (to the 24-bit step)
    assert np.abs(block.channel("Fsum") - f1 - f2).max() < 1e-3 * f1.std()
    assert abs(np.corrcoef(f1, f2)[0, 1]) < 0.1  # two seeds: two signals
    sp = welch_spectra(np.vstack([f1, f2, block.data[:12]]), FS, 512, references=(0, 1))
    H, coh = h1(sp), coherence(sp)
    f = np.fft.rfftfreq(512, 1 / FS)
    b = physics.bench
    exact = b.model.frf(f, physics.resp_xyz, b.resp_dirs, physics.exc_xyz[list(excs)],
                        b.exc_dirs[list(excs)])
    band = (f >= 3.0) & (f <= FS / 2.56 - 2.0)
    good = coh[:, band] > 0.99
    for k in (0, 1):
        rel = np.abs(H[:, k] - exact[:, k])[:, band] / np.abs(exact[:, k])[:, band]
        # leakage (Hann, 1 Hz lines) as with one shaker; the second force is solved for.
        # Measured: median 0.2 % on both columns, 84 % of the lines coherent above 0.99
        assert np.median(rel[good]) < 0.02, (k, np.median(rel[good]))
