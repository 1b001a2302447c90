"""Every plan setting is checked before any work: one line, exit 2, no device opened and no
run file written (``f_stop`` above Nyquist, a shaker level the station does not allow)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import h5py
import pytest

import app.acquire.shaker as shaker_module
from app.acquire import PlanError, RunState, ShakerProcedure, load_plan
from app.acquire.plan import plan_differences
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench
from tests.app.cli_lines import one_error_line

ROOT = Path(__file__).resolve().parents[2]
SHAKER_PLAN = ROOT / "docs" / "shaker_plan.toml"  # fs 512 Hz, f_stop 200 Hz, level 0.5 V


def _plan(tmp_path: Path, old: str, new: str) -> Path:
    text = SHAKER_PLAN.read_text()
    assert old in text
    path = tmp_path / "plan.toml"
    path.write_text(text.replace(old, new))
    return path


def _no_device(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Devices the shaker procedure would create, recorded (none should be)."""
    made: list[str] = []
    real = shaker_module.create_device

    def spy(config: Any, **kw: Any) -> Any:
        made.append(config.name)
        return real(config, **kw)

    monkeypatch.setattr(shaker_module, "create_device", spy)
    return made


def test_f_stop_above_nyquist_is_refused_before_the_run_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _plan(tmp_path, "f_stop = 200.0", "f_stop = 2000.0")
    with pytest.raises(PlanError, match=r"shaker\.f_stop: 2000 Hz is above the Nyquist "
                                        r"frequency of record\.fs = 512 Hz \(256 Hz\)"):
        load_plan(path)
    out = tmp_path / "run.h5"
    assert main(["acquire", "--mock", "--bench", "engine-rigid", "--plan", str(path),
                 "--out", str(out)]) == 2
    line = one_error_line(capsys)
    assert "shaker.f_stop: 2000 Hz is above the Nyquist frequency" in line
    assert "lower shaker.f_stop or raise record.fs" in line
    assert not out.exists()
    # at Nyquist it is a plan (the chirp sweeps up to fs / 2)
    load_plan(_plan(tmp_path, "f_stop = 200.0", "f_stop = 256.0"))


def test_a_level_the_station_does_not_allow_is_refused_before_the_run_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    made = _no_device(monkeypatch)
    path = _plan(tmp_path, "level = 0.5", "level = 50")
    out = tmp_path / "run.h5"
    assert main(["acquire", "--mock", "--bench", "engine-rigid", "--plan", str(path),
                 "--out", str(out)]) == 2
    line = one_error_line(capsys)
    assert line == (f"insitu acquire: error: {path}: shaker.level 50 V is above the 2 V that "
                    "in-process mock station allows for shaker 'shaker': lower shaker.level")
    assert not out.exists() and made == []


def test_a_stored_level_the_station_does_not_allow_is_refused_on_resume(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A run file with a level over the limit (written before the limit was checked up
    front) is refused at once, untouched, and the line does not send the operator back to
    ``--resume``."""
    out = tmp_path / "run.h5"
    plan = plan_for_bench("engine-rigid", fs=512.0, method="shaker", shaker={
        "waveform": "chirp", "nperseg": 512, "averages": 1, "f_stop": 200.0, "ramp": 0.1})

    class StopAtFirstPoint:
        proc: ShakerProcedure

        def on_next_point(self, point: object) -> None:
            self.proc.stop()

    stopper = StopAtFirstPoint()
    with InProcessBench("engine-rigid", fs_frontend=512.0) as bench:
        stopper.proc = ShakerProcedure(plan, bench.station, out, listeners=[stopper])
        stopper.proc.start()
        assert stopper.proc.wait(120) is RunState.STOPPED, stopper.proc.message
    with h5py.File(out, "a") as f:  # as an older insitu wrote it
        text = f["plan"][()].decode().replace('"level": 0.5', '"level": 50.0')
        del f["plan"]
        f["plan"] = text
    size, before = out.stat().st_size, read_run(out, with_data=False)
    made = _no_device(monkeypatch)
    assert main(["acquire", "--resume", str(out)]) == 2
    line = one_error_line(capsys)
    assert f"{out}:/plan: shaker.level 50 V is above the 2 V" in line
    assert line.endswith("the stored plan cannot run: start a new run")
    assert "--resume" not in line and made == []
    after = read_run(out, with_data=False)
    assert out.stat().st_size == size and after.state == before.state == "stopped"


def test_plan_differences_name_the_keys_in_the_plan_words() -> None:
    old = plan_for_bench("engine-rigid", points=[0, 1, 3], length=1.5)
    new = plan_for_bench("engine-rigid", points=[0, 1, 3], length=2.0, trigger_level=30.0)
    assert plan_differences(old, new, "run.h5", "plan.toml") == [
        "record.length 1.5 s in run.h5, 2 s in plan.toml",
        "record.trigger_level 20 N in run.h5, 30 N in plan.toml"]
    fewer = plan_for_bench("engine-rigid", points=[0, 1], length=1.5)
    assert plan_differences(old, fewer, "run.h5", "plan.toml") == [
        "excitation 3 points in run.h5, 2 in plan.toml"]
    moved = plan_for_bench("engine-rigid", points=[0, 1, 4], length=1.5)
    assert plan_differences(old, moved, "run.h5", "plan.toml") == [
        "excitation[2].node 104 in run.h5, 105 in plan.toml",
        "excitation[2].direction [-1, 0, 0] in run.h5, [0, 1, 0] in plan.toml"]
    # the name, and a hammer plan's [shaker] table, change nothing a run records
    renamed = replace(plan_for_bench("engine-rigid", points=[0, 1, 3], length=1.5,
                                     shaker={"level": 1.0}), name="another name")
    assert plan_differences(old, renamed, "run.h5", "plan.toml") == []
