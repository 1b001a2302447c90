"""The NI-DAQmx front end on the simulated NI-DAQmx (hardware_mocks/nidaqmx_sim.py).

The simulated system has nidaqmx's surface and raises nidaqmx's own errors; its modules sit
on the engine bench's physics, so a hit shows on the force channel exactly as
``sampled_pulse`` gives it on the task's sample clock.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from drivers.base import ChannelConfig
from drivers.errors import DeviceInitializationError, DeviceNotAvailableError, DeviceTimeoutError
from drivers.frontend_nidaqmx import NiDaqFrontEnd, accel_sensitivity_mv_per_g
from drivers.registry import get_backend
from drivers.station import parse_station
from hardware_mocks.benches import get_bench
from hardware_mocks.input_signals import FORCE
from hardware_mocks.nidaqmx_api import constants
from hardware_mocks.nidaqmx_sim import NI9234_RATES, SimModule, SimulatedNiDaqmx
from hardware_mocks.physics import TIP_DURATION, BenchPhysics, sampled_pulse

MODULES = ["cDAQ1Mod1", "cDAQ1Mod2"]
#: a1x 10.2 mV/(m/s^2) on Mod1/ai0, a2y (no IEPE) on Mod1/ai1, the force 2.25 mV/N on Mod2/ai0
CHANNELS = (
    ChannelConfig("a1x", 0, "acceleration", 10.2, True, 5.0, 1, (1.0, 0.0, 0.0)),
    ChannelConfig("a2y", 1, "acceleration", 10.0, False, 5.0, 2, (0.0, 1.0, 0.0)),
    ChannelConfig("F", 4, "force", 2.25, True, 5.0),
)


def _system(physics: BenchPhysics, **kw: object) -> SimulatedNiDaqmx:
    mods = [SimModule(n, **kw) for n in MODULES]  # type: ignore[arg-type]
    return SimulatedNiDaqmx(
        physics, mods, wiring={"cDAQ1Mod1/ai0": 0, "cDAQ1Mod1/ai1": 4, "cDAQ1Mod2/ai0": FORCE},
        sensors={"cDAQ1Mod1/ai0": 10.2 * 9.80665, "cDAQ1Mod1/ai1": 10.0 * 9.80665,
                 "cDAQ1Mod2/ai0": 2.25})


@pytest.fixture
def physics() -> BenchPhysics:
    return BenchPhysics(get_bench("engine-rigid"))


@pytest.fixture
def fe(physics: BenchPhysics) -> Iterator[NiDaqFrontEnd]:
    dev = NiDaqFrontEnd("fe", CHANNELS, 1024.0, devices=MODULES, api=_system(physics),
                        stall_timeout=2.0)
    yield dev
    dev.shutdown()


def test_sensitivity_in_mv_per_g_by_hand() -> None:
    # 10.2 mV per m/s^2 and 1 g = 9.80665 m/s^2: 10.2 x 9.80665 = 100.027830 mV/g
    assert accel_sensitivity_mv_per_g(10.2) == pytest.approx(100.027830, rel=1e-12)


def test_channels_are_created_as_the_station_says(fe: NiDaqFrontEnd) -> None:
    fe.open()
    task = fe._task
    a1x, a2y, force = list(task.ai_channels)
    assert [c.name for c in task.ai_channels] == ["a1x", "a2y", "F"]
    assert [c.physical_channel for c in task.ai_channels] == [
        "cDAQ1Mod1/ai0", "cDAQ1Mod1/ai1", "cDAQ1Mod2/ai0"]
    assert a1x.ai_accel_units == constants.AccelUnits.METERS_PER_SECOND_SQUARED
    assert a1x.ai_accel_sensitivity_units == constants.AccelSensitivityUnits.MILLIVOLTS_PER_G
    assert a1x.ai_accel_sensitivity == pytest.approx(100.027830, rel=1e-12)
    assert (a1x.ai_min, a1x.ai_max) == pytest.approx((-5000 / 10.2, 5000 / 10.2))  # 490 m/s^2
    assert (a1x.ai_excit_src, a1x.ai_excit_val) == (constants.ExcitationSource.INTERNAL, 0.002)
    assert (a2y.ai_excit_src, a2y.ai_excit_val) == (constants.ExcitationSource.NONE, 0.0)
    assert force.ai_force_units == constants.ForceUnits.NEWTONS
    assert force.ai_force_iepe_sensor_sensitivity == 2.25
    assert (force.ai_min, force.ai_max) == pytest.approx((-5000 / 2.25, 5000 / 2.25))
    assert {c.ai_coupling for c in task.ai_channels} == {constants.Coupling.AC}
    assert task.timing.samp_clk_rate == 1024.0
    assert task.timing.samp_quant_samp_mode == constants.AcquisitionType.CONTINUOUS
    assert task.timing.samp_quant_samp_per_chan == 10240  # 10 s of buffer
    assert task._n_event == 102  # ten events a second
    assert fe.identity.startswith("NI-DAQmx cDAQ1Mod1, cDAQ1Mod2")


def test_contiguous_blocks_carry_the_hit_exactly(fe: NiDaqFrontEnd,
                                                 physics: BenchPhysics) -> None:
    fe.open()
    fe.start()
    hit = physics.hit(exc=0, peak=320.0, delay=0.3)[0]
    blocks = []
    clock = fe._task.clock
    while True:  # odd block sizes across the event boundaries (102 samples)
        blocks.append(fe.read_block(37))
        if clock.instants(blocks[-1].first_sample + 36, 1)[0] > hit.t0 + 0.1:
            break
    assert [b.first_sample for b in blocks] == [37 * k for k in range(len(blocks))]
    assert all(b.missing == 0 and not b.overloaded for b in blocks)
    force = np.concatenate([b.channel("F") for b in blocks])
    truth = sampled_pulse(clock.instants(0, force.size), 1 / 1024.0, [hit])
    # the whole pulse is in: its impulse (a 320 N half-sine of 2.5 ms), and a peak that
    # averaging over one sample lowers by at most 23 % whatever the hit's phase (245.9 N)
    assert truth.sum() / 1024.0 == pytest.approx(2 * 320.0 * TIP_DURATION / np.pi, rel=1e-6)
    assert truth.max() > 240.0
    assert_allclose(force, truth, rtol=1e-12, atol=1e-9)
    a1x = np.concatenate([b.channel("a1x") for b in blocks])
    assert np.abs(a1x).max() > 1.0  # the bench answered on the accelerometer
    assert fe.health.frames >= 1 and fe.clock_pairs()


def test_overload_at_the_range_marks_the_block(fe: NiDaqFrontEnd,
                                               physics: BenchPhysics) -> None:
    fe.open()
    fe.start()
    hit = physics.hit(exc=0, peak=3000.0, delay=0.2)[0]  # beyond the 2222 N full scale
    seen = []
    clock = fe._task.clock
    while not seen or clock.instants(seen[-1].first_sample, 1)[0] < hit.t0 + 0.05:
        seen.append(fe.read_block(102))
    over = [b for b in seen if b.overloaded]
    assert [b.overloaded for b in over] == [("F",)]
    assert over[0].channel("F").max() == pytest.approx(5000 / 2.25, rel=1e-12)  # clipped
    assert fe.health.overloaded == {"F"}


def test_restart_begins_a_new_stream(fe: NiDaqFrontEnd) -> None:
    fe.open()
    fe.start()
    fe.read_block(200)
    fe.stop()
    fe.start()
    assert fe.read_block(10).first_sample == 0


def test_a_rate_the_modules_do_not_run_is_refused(physics: BenchPhysics) -> None:
    api = _system(physics, rates=NI9234_RATES)
    dev = NiDaqFrontEnd("fe", CHANNELS, 1024.0, devices=MODULES, api=api)
    with pytest.raises(DeviceInitializationError) as err:
        dev.open()
    msg = str(err.value)
    assert "\n" not in msg
    assert "at 1651.61 Hz, not the 1024 Hz asked" in msg and "51200 / n" in msg
    assert api.tasks == []  # the task was closed
    ok = NiDaqFrontEnd("fe", CHANNELS, 2048.0, devices=MODULES, api=_system(physics,
                                                                              rates=NI9234_RATES))
    ok.open()
    assert ok.actual_rate == 2048.0  # 51200 / 25
    ok.shutdown()


def test_unknown_device_is_one_line(physics: BenchPhysics) -> None:
    dev = NiDaqFrontEnd("fe", CHANNELS, 1024.0, devices=["cDAQ1Mod1", "cDAQ1Mod7"],
                        api=_system(physics))
    with pytest.raises(DeviceNotAvailableError) as err:
        dev.open()
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith("fe: channel F (cDAQ1Mod7/ai0): NI-DAQmx has no such device "
                          "(Device identifier is invalid")
    assert "error -200220" in msg and "NI MAX" in msg


def test_range_beyond_the_module_is_refused(physics: BenchPhysics) -> None:
    chans = (CHANNELS[0], ChannelConfig("F", 4, "force", 2.25, True, 10.0))
    dev = NiDaqFrontEnd("fe", chans, 1024.0, devices=MODULES, api=_system(physics))
    with pytest.raises(DeviceInitializationError, match=r"channel F \(cDAQ1Mod2/ai0\): "
                       r"Requested value is not a supported value.*error -200077\)$"):
        dev.open()


def test_driver_missing_is_one_line(physics: BenchPhysics) -> None:
    api = _system(physics)
    api.driver_installed = False
    dev = NiDaqFrontEnd("fe", CHANNELS, 1024.0, devices=MODULES, api=api)
    with pytest.raises(DeviceNotAvailableError, match=r"^fe: the NI-DAQmx driver is not "
                       r"installed .*install NI-DAQmx from ni.com"):
        dev.open()


def test_real_nidaqmx_without_ni_driver() -> None:
    """nidaqmx imports without NI's driver and Task() raises DaqNotFoundError (PITFALLS.md)."""
    nidaqmx = pytest.importorskip("nidaqmx")
    try:
        nidaqmx.Task().close()
    except nidaqmx.errors.DaqNotFoundError:
        pass
    else:
        pytest.skip("NI-DAQmx is installed on this machine")
    dev = NiDaqFrontEnd("fe", CHANNELS, 2048.0, devices=MODULES)
    with pytest.raises(DeviceNotAvailableError, match=r"^fe: the NI-DAQmx driver is not"):
        dev.open()


def test_missing_package_names_the_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "nidaqmx", None)
    dev = NiDaqFrontEnd("fe", CHANNELS, 2048.0, devices=MODULES)
    with pytest.raises(DeviceNotAvailableError) as err:
        dev.open()
    assert str(err.value) == ("fe: backend frontend-nidaqmx needs the nidaqmx package, which "
                              "is not installed: pip install 'insitu[ni]'")


def test_module_removed_mid_stream(fe: NiDaqFrontEnd) -> None:
    fe.open()
    fe.start()
    fe.read_block(300)
    fe._api.remove("cDAQ1Mod2")
    with pytest.raises(DeviceNotAvailableError) as err:
        while True:
            fe.read_block(102)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith("fe: streaming: Device cannot be accessed. Device: cDAQ1Mod2 "
                          "(NI-DAQmx error -201003): a module of cDAQ1Mod1, cDAQ1Mod2 was "
                          "removed")
    assert not isinstance(err.value, DeviceTimeoutError)


def test_teds_sensitivity_is_checked(physics: BenchPhysics) -> None:
    api = _system(physics)
    api.modules["cDAQ1Mod1"].teds = {0: 10.2 * 9.80665}
    dev = NiDaqFrontEnd("fe", CHANNELS, 1024.0, devices=MODULES, api=api, teds=["a1x"])
    dev.open()
    a1x = dev._task.ai_channels[0]
    assert a1x.ai_teds_is_teds and a1x.ai_accel_sensitivity == pytest.approx(100.02783)
    dev.shutdown()
    api.modules["cDAQ1Mod1"].teds = {0: 98.0}  # 2 % below the station's
    dev = NiDaqFrontEnd("fe", CHANNELS, 1024.0, devices=MODULES, api=api, teds=["a1x"])
    with pytest.raises(DeviceInitializationError, match=r"a1x: the sensor's TEDS gives 9\.9932 "
                       r"mV/\(m/s\^2\), the station file 10\.2: put the TEDS value"):
        dev.open()
    dev = NiDaqFrontEnd("fe", CHANNELS, 1024.0, devices=MODULES, api=api, teds=["F"])
    with pytest.raises(DeviceInitializationError, match=r"TEDS sensor not detected.*-200709"):
        dev.open()


def test_station_file_entry() -> None:
    data = {"devices": {"fe": {
        "backend": "frontend-nidaqmx", "fs": 2048, "transport": {"nidaqmx": MODULES},
        "options": {"coupling": "DC", "teds": ["F"]},
        "channels": [{"name": "F", "input": 4, "quantity": "force", "sensitivity": 2.25}]}}}
    cfg = parse_station(data).devices["fe"]
    assert get_backend("frontend-nidaqmx") is NiDaqFrontEnd
    dev = NiDaqFrontEnd.from_config(cfg)
    assert (dev.devices, dev.coupling, dev.teds, dev.fs) == (tuple(MODULES), "DC",
                                                              frozenset({"F"}), 2048.0)
    with pytest.raises(ValueError, match="unknown option 'gain'; allowed: channels_per_module"):
        NiDaqFrontEnd.from_config(cfg, gain=2)
    data["devices"]["fe"]["channels"][0]["input"] = 8
    with pytest.raises(ValueError, match=r"input 8, but 2 module\(s\) of 4 inputs have 8 "
                       r"\(0\.\.7\): add its module"):
        NiDaqFrontEnd.from_config(parse_station(data).devices["fe"])


def test_simulation_runs_without_the_nidaqmx_package(tmp_path: Path) -> None:
    """The core install has no nidaqmx: the simulated system's stand-in constants and errors
    (nidaqmx 1.7's names and values) carry the driver through a stream and a refusal."""
    script = tmp_path / "run.py"
    script.write_text(
        "import sys\n"
        "sys.modules['nidaqmx'] = None\n"
        "from tests.drivers.test_frontend_nidaqmx import CHANNELS, MODULES, _system\n"
        "from hardware_mocks.nidaqmx_api import REAL\n"
        "from hardware_mocks.benches import get_bench\n"
        "from hardware_mocks.physics import BenchPhysics\n"
        "from drivers.frontend_nidaqmx import NiDaqFrontEnd\n"
        "from drivers.errors import DeviceNotAvailableError\n"
        "assert not REAL\n"
        "phys = BenchPhysics(get_bench('engine-rigid'))\n"
        "fe = NiDaqFrontEnd('fe', CHANNELS, 1024.0, devices=MODULES, api=_system(phys))\n"
        "fe.open(); fe.start(); b = fe.read_block(300); fe.shutdown()\n"
        "assert b.first_sample == 0 and b.missing == 0\n"
        "bad = NiDaqFrontEnd('fe', CHANNELS, 1024.0, devices=['X', 'Y'], api=_system(phys))\n"
        "try:\n"
        "    bad.open()\n"
        "except DeviceNotAvailableError as err:\n"
        "    print(err)\n")
    root = Path(__file__).parents[2]
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         cwd=root, env={**os.environ, "PYTHONPATH": str(root)}, timeout=120,
                         check=False)
    assert out.returncode == 0, out.stderr
    assert "NI-DAQmx has no such device (Device identifier is invalid" in out.stdout
