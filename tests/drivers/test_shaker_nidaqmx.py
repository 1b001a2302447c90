"""The AO shaker drive (shaker-nidaqmx) on the simulated NI-DAQmx's output module.

The simulated NI 9263 (hardware_mocks/nidaqmx_ao.py) keeps every buffer the driver writes
and plays them on its own clock, so the voltage it generates, sample by sample, is compared
with the waveform processing.excitation synthesises, scaled and ramped.
"""

from __future__ import annotations

import atexit
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from drivers.base import DeviceState
from drivers.errors import DeviceInitializationError, DeviceNotAvailableError
from drivers.registry import get_backend
from drivers.shaker_nidaqmx import NiDaqShaker
from drivers.station import parse_station
from hardware_mocks.benches import get_bench
from hardware_mocks.nidaqmx_ao import OutputLine
from hardware_mocks.nidaqmx_api import constants
from hardware_mocks.nidaqmx_sim import SimModule, SimulatedNiDaqmx
from hardware_mocks.physics import BenchPhysics
from processing.excitation import burst_random, periodic_chirp, periodic_random

MODULE = "cDAQ1Mod5"
RATE = 1000.0


def _system(driver: bool = True, **module: Any) -> SimulatedNiDaqmx:
    ao = SimModule(MODULE, "NI 9263", n_inputs=0, n_outputs=4, **module)
    return SimulatedNiDaqmx(BenchPhysics(get_bench("engine-rigid")), [ao], wiring={},
                            sensors={}, driver_installed=driver)


@pytest.fixture
def ni() -> SimulatedNiDaqmx:
    return _system()


@pytest.fixture
def make(ni: SimulatedNiDaqmx) -> Iterator[Callable[..., NiDaqShaker]]:
    made: list[NiDaqShaker] = []

    def build(**kw: Any) -> NiDaqShaker:
        sh = NiDaqShaker("shaker", MODULE, **{"api": ni, "rate": RATE, "ramp": 0.0, **kw})
        made.append(sh)
        return sh

    yield build
    for sh in made:
        sh.shutdown()


def _generated(sh: NiDaqShaker, first: int, n: int) -> np.ndarray:
    """Volts the simulated output plays at samples ``first .. first + n - 1`` of the
    generation (mid-sample instants on its clock)."""
    stream = sh._task.out_stream
    clock = stream._clock
    t = clock.instants(first, n) + 0.5 / clock.true_rate
    return sh._task.ao_channels[0].line.voltage(t)


def test_backend_is_registered() -> None:
    assert get_backend("shaker-nidaqmx") is NiDaqShaker


def test_task_is_created_as_the_station_says(make: Callable[..., NiDaqShaker],
                                             ni: SimulatedNiDaqmx) -> None:
    sh = make(channel="ao2", output_range=5.0)
    sh.open()
    (chan,) = list(sh._task.ao_channels)
    assert (chan.physical_channel, chan.name) == ("cDAQ1Mod5/ao2", "shaker")
    assert (chan.ao_min, chan.ao_max) == (-5.0, 5.0)
    assert chan.ao_voltage_units == constants.VoltageUnits.VOLTS
    assert sh._task.timing.samp_clk_rate == RATE
    # open leaves the output at 0 V, written on demand
    assert sh._task.timing.samp_timing_type == constants.SampleTimingType.ON_DEMAND
    assert ni.output_line("cDAQ1Mod5/ao2").held == 0.0
    assert sh.identity == "NI-DAQmx cDAQ1Mod5/ao2 at 1000 Sa/s"


def test_chirp_buffer_is_the_synthesised_one_at_the_level(
        make: Callable[..., NiDaqShaker]) -> None:
    sh = make()
    sh.open()
    sh.set_waveform("chirp", f_start=2.0, f_stop=100.0, period=0.5)
    sh.set_level(0.5)
    sh.start()
    stream = sh._task.out_stream
    assert stream.regen_mode == constants.RegenerationMode.ALLOW_REGENERATION
    assert sh._task.timing.samp_quant_samp_mode == constants.AcquisitionType.CONTINUOUS
    assert stream.output_buf_size == 500  # one period
    want = 0.5 * periodic_chirp(1, 500, RATE, band=(2.0, 100.0))
    assert_array_equal(stream.writes[0][1], want)
    # regenerated: three periods played are the buffer three times, sample for sample
    assert_array_equal(_generated(sh, 0, 1500), np.tile(want, 3))


def test_random_and_burst_levels_are_rms(make: Callable[..., NiDaqShaker]) -> None:
    sh = make(random_period=2.0, seed=3, bursts=2)
    sh.open()
    sh.set_waveform("random", f_start=5.0, f_stop=200.0)
    sh.set_level(0.4)
    sh.start()
    buf = sh._task.out_stream.writes[0][1]
    assert_array_equal(buf, 0.4 * periodic_random(2000, RATE, band=(5.0, 200.0), seed=3))
    assert np.sqrt(np.mean(buf**2)) == pytest.approx(0.4, rel=1e-12)  # V RMS
    sh.stop()
    sh.set_waveform("burst-random", f_start=5.0, f_stop=200.0, period=0.25, burst=0.5)
    sh.start()
    buf = sh._task.out_stream.writes[0][1]
    assert_array_equal(buf, 0.4 * burst_random(2, 250, RATE, burst_fraction=0.5,
                                               band=(5.0, 200.0), seed=3)[0])


def test_sine_buffer_holds_whole_cycles(make: Callable[..., NiDaqShaker]) -> None:
    sh = make()
    sh.open()
    with pytest.raises(ValueError, match=r"a sine of 0\.3183 Hz has no whole number of "
                                         r"cycles in 10 s at 1000 Sa/s"):
        sh.set_waveform("sine", frequency=0.3183)  # 3183 cycles would take 1e7 samples
    sh.set_waveform("sine", frequency=30.0)  # 100 samples hold 3 cycles at 1000 Sa/s
    sh.set_level(2.0)
    sh.start()
    buf = sh._task.out_stream.writes[0][1]
    assert_allclose(buf, 2.0 * np.sin(2 * np.pi * 30.0 * np.arange(100) / RATE), atol=1e-15)


def test_ramp_up_and_down_are_whole_buffers_under_a_linear_envelope(
        make: Callable[..., NiDaqShaker], ni: SimulatedNiDaqmx) -> None:
    sh = make(ramp=0.3)
    sh.open()
    sh.set_waveform("chirp", f_start=2.0, f_stop=100.0, period=0.25)
    sh.set_level(0.8)
    sh.start()  # returns at once: the ramp's later buffers are written as room frees
    assert sh._ramp_writer is not None
    sh._ramp_writer.join()
    wave = periodic_chirp(1, 250, RATE, band=(2.0, 100.0))
    writes = sh._task.out_stream.writes
    assert [first for first, _ in writes] == [0, 250, 500]  # each a period after the last
    t = np.arange(750) / RATE
    want = np.tile(wave, 3) * 0.8 * np.minimum(t / 0.3, 1.0)
    assert_allclose(np.concatenate([buf for _, buf in writes]), want, rtol=1e-12, atol=1e-15)
    # from then on the steady buffer plays, period after period
    assert_allclose(_generated(sh, 1000, 500), 0.8 * np.tile(wave, 2), rtol=1e-12)
    line = ni.output_line("cDAQ1Mod5/ao0")
    done = threading.Event()
    threading.Thread(target=lambda: (sh.stop(), done.set()), daemon=True).start()
    assert done.wait(30)  # only guards against a hang
    # the fall starts at the next buffer boundary after the steady buffer, 0.3 s long
    down = [(first, buf) for first, buf in sh._task.out_stream.writes if first >= 750]
    assert [first for first, _ in down] == [750, 1000]
    fall = np.concatenate([buf for _, buf in down])
    env = 0.8 * np.clip(1.0 - np.arange(500) / RATE / 0.3, 0.0, 1.0)
    assert_allclose(fall, np.tile(wave, 2) * env, rtol=1e-12, atol=1e-15)
    assert line.held == 0.0 and line.generation is None  # stopped, 0 V on demand
    assert sh._task.timing.samp_timing_type == constants.SampleTimingType.ON_DEMAND
    assert sh.state is DeviceState.OPEN


def test_level_changed_while_on_ramps_to_it(make: Callable[..., NiDaqShaker]) -> None:
    sh = make()
    sh.open()
    sh.set_waveform("chirp", f_start=2.0, f_stop=100.0, period=0.25)
    sh.set_level(0.2)
    sh.start()
    sh.set_level(0.6)  # no ramp: the next buffer is at the new level
    (f0, b0), (f1, b1) = sh._task.out_stream.writes
    assert (f0, f1) == (0, 250)
    assert_allclose(b1, 3.0 * b0, rtol=1e-12)


def test_shutdown_turns_the_output_off_and_leaves_atexit(
        make: Callable[..., NiDaqShaker], ni: SimulatedNiDaqmx,
        monkeypatch: pytest.MonkeyPatch) -> None:
    registered: list[Callable[[], None]] = []
    monkeypatch.setattr(atexit, "register", registered.append)
    monkeypatch.setattr(atexit, "unregister", registered.remove)
    sh = make()
    sh.open()
    assert registered == [sh.shutdown]
    sh.set_waveform("sine", frequency=10.0)
    sh.set_level(1.0)
    sh.start()
    line = ni.output_line("cDAQ1Mod5/ao0")
    assert line.generation is not None
    sh.shutdown()
    assert line.held == 0.0 and line.generation is None
    assert registered == [] and not ni.tasks  # closed
    sh.shutdown()  # idempotent


def test_output_off_never_waits_on_a_stuck_call(make: Callable[..., NiDaqShaker],
                                                caplog: pytest.LogCaptureFixture) -> None:
    sh = make(timeout=0.05)
    sh.open()
    sh.set_waveform("sine", frequency=10.0)
    sh.set_level(1.0)
    sh.start()
    release = threading.Event()
    task = sh._task
    stop = task.stop
    task.stop = lambda: (release.wait(), stop())  # NI-DAQmx stuck in the stop call
    sh.shutdown()  # returns: the off waits 2 timeouts, then says so
    assert "did not stop the output within 0.1 s: turn the amplifier off by hand" in caplog.text
    release.set()


def test_module_removed_mid_run_turns_the_output_off_in_one_line(
        make: Callable[..., NiDaqShaker], ni: SimulatedNiDaqmx) -> None:
    sh = make()
    sh.open()
    sh.set_waveform("chirp", f_start=2.0, f_stop=100.0, period=0.25)
    sh.set_level(0.5)
    sh.start()
    assert sh.output_problem() == ""
    ni.remove(MODULE)
    problem = sh.output_problem()
    assert problem == ("shaker: generating: Device cannot be accessed. Device: cDAQ1Mod5 "
                       "(NI-DAQmx error -201003): a module of cDAQ1Mod5 was removed, or the "
                       "chassis lost power or its connection: check it, then resume; output "
                       "turned off")
    assert sh.state is DeviceState.OPEN
    line: OutputLine = sh._task.ao_channels[0].line
    assert_array_equal(line.voltage(np.array([0.0, 1e9])), 0.0)
    with pytest.raises(DeviceNotAvailableError, match=r"^shaker: starting the output: Device "
                       r"cannot be accessed"):
        sh.start()


def test_limits_from_the_station_entry() -> None:
    station = parse_station({"devices": {"shaker": {
        "backend": "shaker-nidaqmx", "transport": {"nidaqmx": MODULE},
        "options": {"rate": 10240, "max_level": 1.5}}}})
    cfg = station.devices["shaker"]
    limits = NiDaqShaker.setting_limits(cfg)
    assert limits["level"] == (0.0, 1.5)
    assert limits["f_stop"] == (0.0, 5120.0)
    assert "ramp" in limits  # the shaker procedure hands it the plan's ramp
    sh = NiDaqShaker.from_config(cfg, ramp=0.1)
    assert (sh.device, sh.channel, sh.rate, sh.max_level, sh.ramp) == (
        MODULE, "ao0", 10240.0, 1.5, 0.1)
    with pytest.raises(ValueError, match=r"^device 'shaker': unknown option 'gain'; allowed: "
                                         r"channel, rate, max_level"):
        NiDaqShaker.from_config(cfg, gain=2.0)
    two = parse_station({"devices": {"shaker": {
        "backend": "shaker-nidaqmx", "transport": {"nidaqmx": [MODULE, "cDAQ1Mod6"]}}}})
    with pytest.raises(ValueError, match=r"needs its output module, transport = "):
        NiDaqShaker.from_config(two.devices["shaker"])


def test_levels_and_settings_beyond_the_limits_are_refused(
        make: Callable[..., NiDaqShaker]) -> None:
    sh = make(max_level=20.0)
    sh.open()
    sh.set_waveform("chirp", f_start=2.0, f_stop=100.0, period=0.25)
    with pytest.raises(ValueError, match=r"^shaker: level 12 V peaks at 12 V with this "
                                         r"waveform, beyond the module's \+/-10 V"):
        sh.set_level(12.0)
    with pytest.raises(ValueError, match=r"f_stop 600 Hz above half the output rate \(500 Hz\)"):
        sh.set_waveform("chirp", f_start=2.0, f_stop=600.0, period=0.25)
    with pytest.raises(ValueError, match=r"period of 0\.2505 s is not a whole number of "
                                         r"samples at 1000 Sa/s"):
        sh.set_waveform("chirp", f_start=2.0, f_stop=100.0, period=0.2505)
    low = make(max_level=1.0)
    low.open()
    low.set_waveform("sine", frequency=10.0)
    with pytest.raises(ValueError, match=r"level 1\.5 V above the station's limit 1 V "
                                         r"\(option max_level\)"):
        low.set_level(1.5)


def test_a_rate_the_module_does_not_run_is_refused(make: Callable[..., NiDaqShaker]) -> None:
    ni = _system(rates=(10000.0, 20000.0))
    sh = NiDaqShaker("shaker", MODULE, api=ni, rate=9000.0)
    with pytest.raises(DeviceInitializationError, match=r"runs cDAQ1Mod5/ao0 at 10000 Sa/s, "
                                                        r"not the 9000 asked"):
        sh.open()
    assert not ni.tasks  # closed


def test_unknown_device_driver_and_package_missing_are_one_line(
        monkeypatch: pytest.MonkeyPatch) -> None:
    sh = NiDaqShaker("shaker", "cDAQ1Mod7", api=_system())
    with pytest.raises(DeviceNotAvailableError, match=r"^shaker: output cDAQ1Mod7/ao0: NI-DAQmx "
                       r"has no such device \(Device identifier is invalid\. Device Specified: "
                       r"cDAQ1Mod7, error -200220\): check the module names NI MAX shows"):
        sh.open()
    with pytest.raises(DeviceNotAvailableError, match=r"^shaker: the NI-DAQmx driver is not "
                                                      r"installed"):
        NiDaqShaker("shaker", MODULE, api=_system(driver=False)).open()
    monkeypatch.setitem(sys.modules, "nidaqmx", None)
    with pytest.raises(DeviceNotAvailableError) as info:
        NiDaqShaker("shaker", MODULE).open()
    assert str(info.value) == ("shaker: backend shaker-nidaqmx needs the nidaqmx package, "
                               "which is not installed: pip install 'insitu[ni]'")
