"""``insitu acquire`` on the NI-DAQmx station of docs/ni_station.toml, its NI-DAQmx simulated.

The documented station's ``[simulation]`` table makes the command inject the simulated
NI-DAQmx (hardware_mocks/nidaqmx_sim.py) into the real driver, on the engine-rigid bench,
with a simulated operator hitting. Failure paths: one line, exit status 2, what was
acquired kept.
"""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from app.acquire import HammerProcedure, Listener, RunState
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import plan_for_bench
from app.mockbench.simulated import SimulatedStation
from drivers.station import load_station
from hardware_mocks.benches import get_bench
from tests.app.bench_checks import SIX, assert_identifies, cut_plan
from tests.app.cli_lines import one_error_line

DOCS = Path(__file__).parents[2] / "docs"
SIMULATION = '[simulation]\nbench = "engine-rigid"\n'
MODULES = '["cDAQ1Mod1", "cDAQ1Mod2", "cDAQ1Mod3", "cDAQ1Mod4"]'


def _plan(tmp_path: Path, keep: list[int] | None = None) -> Path:
    """The documented plan with one hit a point (9 points, 1.5 s records), or at its
    points ``keep`` only (positions)."""
    text = (DOCS / "mock_bench_plan.toml").read_text()
    assert "\nhits = 3\n" in text
    path = tmp_path / "plan.toml"
    path.write_text(text.replace("\nhits = 3\n", "\nhits = 1\n"))
    return path if keep is None else cut_plan(path, keep, path)


def _station(tmp_path: Path, simulation: str | None = SIMULATION, *,
             old: str = "", new: str = "") -> Path:
    """docs/ni_station.toml with its [simulation] table replaced (None: removed), and
    ``old`` replaced by ``new``."""
    text = (DOCS / "ni_station.toml").read_text()
    assert SIMULATION in text and old in text
    text = text.replace(SIMULATION, simulation or "")
    if old:
        text = text.replace(old, new)
    path = tmp_path / "station.toml"
    path.write_text(text)
    return path


def _acquire(station: Path, tmp_path: Path) -> int:
    return main(["acquire", "--station", str(station), "--plan", str(_plan(tmp_path)),
                 "--out", str(tmp_path / "run.h5")])


@pytest.mark.slow
def test_documented_station_identifies_the_bench(tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    assert main(["acquire", "--station", str(DOCS / "ni_station.toml"), "--plan",
                 str(_plan(tmp_path, SIX)), "--out", str(out)]) == 0
    run = read_run(out, with_data=False)
    assert run.state == "finished" and len(run.records) == len(SIX)
    assert run.records.accepted.all()
    assert run.station_data["simulation"] == {"bench": "engine-rigid"}
    assert run.station_data["devices"]["frontend"]["backend"] == "frontend-nidaqmx"
    res = tmp_path / "result.json"
    assert main(["replay", str(out), "--out", str(res)]) == 0
    assert_identifies(json.loads(res.read_text()), get_bench("engine-rigid").model)


@pytest.mark.slow
def test_documented_shaker_plan_through_the_simulated_generator(tmp_path: Path) -> None:
    """docs/ni_shaker_plan.toml (one block a point, shorter settling, six of its nine
    points) on the documented station: the 33500 (generator-visa through pyvisa-py) drives
    the shaker, the cDAQ reads its force and the responses; the bench is identified, the
    output off at the end."""
    plan = _short_shaker_plan(tmp_path, SIX)
    out = tmp_path / "run.h5"
    assert main(["acquire", "--station", str(DOCS / "ni_station.toml"), "--plan", str(plan),
                 "--out", str(out)]) == 0
    run = read_run(out, with_data=False)
    assert run.method == "shaker" and run.state == "finished" and len(run.records) == len(SIX)
    assert run.station_data["devices"]["shaker"]["backend"] == "generator-visa"
    assert_identifies(json.loads(json.dumps(run.result)), get_bench("engine-rigid").model)


def _short_shaker_plan(tmp_path: Path, keep: list[int] | None = None) -> Path:
    """docs/ni_shaker_plan.toml with one block a point and 0.5 s settling, at its points
    ``keep`` only (positions) if given."""
    text = (DOCS / "ni_shaker_plan.toml").read_text()
    assert "\naverages = 3\n" in text and "\nsettle = 1.0\n" in text
    plan = tmp_path / "plan.toml"
    plan.write_text(text.replace("\naverages = 3\n", "\naverages = 1\n")
                    .replace("\nsettle = 1.0\n", "\nsettle = 0.5\n"))
    return plan if keep is None else cut_plan(plan, keep, plan)


def test_documented_shaker_plan_through_the_ao_module(tmp_path: Path) -> None:
    """docs/ni_shaker_plan.toml (one block a point, shorter settling, six of its nine
    points) on docs/ni_ao_station.toml: an NI 9263 output of the simulated chassis (shaker-nidaqmx)
    drives the shaker's amplifier, the cDAQ's inputs read its force and the responses; the
    bench is identified."""
    out = tmp_path / "run.h5"
    assert main(["acquire", "--station", str(DOCS / "ni_ao_station.toml"), "--plan",
                 str(_short_shaker_plan(tmp_path, SIX)), "--out", str(out)]) == 0
    run = read_run(out, with_data=False)
    assert run.method == "shaker" and run.state == "finished" and len(run.records) == len(SIX)
    assert run.records.accepted.all()
    assert run.station_data["devices"]["shaker"]["backend"] == "shaker-nidaqmx"
    assert_identifies(json.loads(json.dumps(run.result)), get_bench("engine-rigid").model)


def test_ao_module_removed_mid_run_keeps_the_blocks(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # pulled out 0.3 s after the shaker is at the third point: the block in progress then
    # is kept (NaN-padded), not used; the two before are in
    text = (DOCS / "ni_ao_station.toml").read_text()
    assert SIMULATION in text
    station = tmp_path / "station.toml"
    station.write_text(text.replace(SIMULATION, SIMULATION + 'remove_module = { module = '
                                    '"cDAQ1Mod5", point = 3, seconds = 0.3 }\n'))
    out = tmp_path / "run.h5"
    assert main(["acquire", "--station", str(station), "--plan",
                 str(_short_shaker_plan(tmp_path)), "--out", str(out)]) == 2
    line = one_error_line(capsys)
    # found by the ramp's last write (0.3 s is within its first period) or by the check
    assert "Device cannot be accessed. Device: cDAQ1Mod5 (NI-DAQmx error -201003): a " \
           "module of cDAQ1Mod5 was removed" in line
    assert "output turned off" in line and f"records are in {out}" in line
    run = read_run(out)
    assert run.state == "stopped" and len(run.records) == 3
    assert run.records.accepted.tolist() == [True, True, False]
    assert np.isfinite(run.records.data[:2]).all()


def test_without_the_nidaqmx_package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "nidaqmx", None)
    assert _acquire(_station(tmp_path, None), tmp_path) == 2
    line = one_error_line(capsys)
    assert "frontend: backend frontend-nidaqmx needs the nidaqmx package, which is not " \
           "installed: pip install 'insitu[ni]'" in line
    assert "; no record was acquired and no run file was written" in line


def test_without_the_ni_driver(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    station = _station(tmp_path, SIMULATION + "nidaqmx_driver = false\n")
    assert _acquire(station, tmp_path) == 2
    line = one_error_line(capsys)
    assert "frontend: the NI-DAQmx driver is not installed" in line
    assert not (tmp_path / "run.h5").exists()


def test_unknown_device_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    station = _station(tmp_path, SIMULATION + f"nidaqmx_modules = {MODULES}\n",
                       old=f"transport = {{ nidaqmx = {MODULES} }}",
                       new=f"transport = {{ nidaqmx = {MODULES.replace('Mod4', 'Mod5')} }}")
    assert _acquire(station, tmp_path) == 2
    line = one_error_line(capsys)
    assert "frontend: channel F (cDAQ1Mod5/ai0): NI-DAQmx has no such device (Device " \
           "identifier is invalid. Device Specified: cDAQ1Mod5" in line
    assert "error -200220" in line


def test_range_beyond_the_module(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    station = _station(tmp_path, old="range = 5.0                # +/- V: full scale 2222 N",
                       new="range = 10.0")
    assert _acquire(station, tmp_path) == 2
    line = one_error_line(capsys)
    assert "frontend: channel F (cDAQ1Mod4/ai0): Requested value is not a supported value" \
           in line and "+/-5 V) (NI-DAQmx error -200077)" in line


def test_module_removed_mid_run_keeps_the_records(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    # pulled out 2.5 s after the second hit: its 1.5 s record is in, the third hit's is not
    station = _station(tmp_path, SIMULATION + 'remove_module = { module = "cDAQ1Mod2", '
                                              'hit = 2, seconds = 2.5 }\n')
    assert _acquire(station, tmp_path) == 2
    line = one_error_line(capsys)
    assert "Device cannot be accessed. Device: cDAQ1Mod2 (NI-DAQmx error -201003): a module " \
           "of cDAQ1Mod1, cDAQ1Mod2, cDAQ1Mod3, cDAQ1Mod4 was removed" in line
    run_h5 = tmp_path / "run.h5"
    assert f"its 2 records are in {run_h5} (continue with --resume {run_h5} --station " \
           f"{station})" in line
    run = read_run(run_h5)
    assert len(run.records) == 2 and run.records.accepted.all()
    assert np.isfinite(run.records.data).all()


class _Hits(Listener):
    def __init__(self) -> None:
        self.hits: list = []
        self.done = threading.Event()

    def on_hit(self, hit: object) -> None:
        self.hits.append(hit)

    def on_finished(self, state: RunState) -> None:
        self.done.set()


def test_overloaded_hit_is_rejected_and_hit_again(tmp_path: Path) -> None:
    """A 3000 N hit clips the force channel at its 2222 N range: the block is marked
    overloaded by the driver, the hit rejected, the operator hits again."""
    station = load_station(DOCS / "ni_station.toml")
    plan = plan_for_bench("engine-rigid", points=[0], length=0.5)
    ev = _Hits()
    with SimulatedStation(station, operator={"faults": {0: "overload"}}) as sim:
        proc = HammerProcedure(plan, station, tmp_path / "run.h5", partial=True,
                               listeners=[sim.operator, ev], device_options=sim.device_options)
        proc.start()
        assert ev.done.wait(120), "the run did not end"  # only guards against a hang
    assert proc.state is RunState.FINISHED, proc.message
    assert [h.auto_accepted for h in ev.hits] == [False, True]
    assert "overload on F" in ev.hits[0].reason
    assert ev.hits[0].peak_force == pytest.approx(5000 / 2.25, rel=1e-9)
