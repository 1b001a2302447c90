"""``insitu acquire --resume``: the run goes on with its own plan and bench, and counts what
the file holds (points done before the resume, every record)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

import app.acquire.hammer as hammer_module
import app.acquire.shaker as shaker_module
import app.cli.acquire as cli_acquire
from app.acquire import HammerProcedure, RunState, ShakerProcedure, load_plan
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench
from tests.app.cli_lines import one_error_line

ROOT = Path(__file__).resolve().parents[2]
POINTS = [0, 1, 3, 4, 6, 8]  # six forces spanning the rigid-body motions


class StopAfter:
    """Stops its procedure once ``n`` records are in (at the first point when 0)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.proc: HammerProcedure | ShakerProcedure | None = None

    def _maybe_stop(self, count: int) -> None:
        if count >= self.n and self.proc is not None:
            self.proc.stop()

    def on_next_point(self, point: object) -> None:
        self._maybe_stop(0 if self.proc is None else len(self.proc.hits))

    def on_hit(self, hit: Any) -> None:
        self._maybe_stop(hit.hit_id + 1)


def _stopped_hammer_run(path: Path, n: int, length: float = 0.5) -> None:
    plan = plan_for_bench("engine-rigid", points=POINTS, length=length)
    stop = StopAfter(n)
    with InProcessBench("engine-rigid") as bench:
        stop.proc = HammerProcedure(plan, bench.station, path, listeners=[bench.operator, stop])
        stop.proc.start()
        assert stop.proc.wait(120) is RunState.STOPPED, stop.proc.message
    assert len(read_run(path, with_data=False).records) == n


def _no_device(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Benches started and devices created from here on, recorded."""
    made: list[str] = []
    for module in (hammer_module, shaker_module):
        real = module.create_device

        def spy(config: Any, _real: Any = real, **kw: Any) -> Any:
            made.append(config.name)
            return _real(config, **kw)

        monkeypatch.setattr(module, "create_device", spy)
    real_bench = cli_acquire._in_process_bench

    def bench(name: str, fs: float, shakers: int = 1) -> InProcessBench:
        made.append(f"bench {name}")
        return real_bench(name, fs, shakers)

    monkeypatch.setattr(cli_acquire, "_in_process_bench", bench)
    return made


def test_a_different_record_length_is_refused_before_any_device(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run.h5"
    _stopped_hammer_run(out, 1, length=1.5)
    size, before = out.stat().st_size, read_run(out)
    plan = tmp_path / "plan.toml"
    plan.write_text((ROOT / "docs" / "mock_bench_plan.toml").read_text()
                    .replace("length = 1.5", "length = 2.0"))
    made = _no_device(monkeypatch)
    assert main(["acquire", "--resume", str(out), "--plan", str(plan)]) == 2
    line = one_error_line(capsys)
    assert line.startswith("insitu acquire: error: ")
    assert "record.length 1.5 s in run.h5, 2 s in plan.toml; " in line
    assert line.endswith(": resume with the stored plan (omit --plan) or start a new run")
    assert made == []  # no bench started, no device created
    after = read_run(out)
    assert out.stat().st_size == size and after.state == before.state == "stopped"
    assert (after.records.data == before.records.data).all()


def test_a_different_shaker_level_is_refused_before_any_device(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    shaker_plan = ROOT / "docs" / "shaker_plan.toml"
    out = tmp_path / "run.h5"
    stop = StopAfter(0)
    with InProcessBench("engine-rigid", fs_frontend=512.0) as bench:
        stop.proc = ShakerProcedure(load_plan(shaker_plan), bench.station, out,
                                    listeners=[bench.shaker_operator, stop])
        stop.proc.start()
        assert stop.proc.wait(120) is RunState.STOPPED, stop.proc.message
    size = out.stat().st_size
    plan = tmp_path / "plan.toml"
    plan.write_text(shaker_plan.read_text().replace("level = 0.5", "level = 1.5"))
    made = _no_device(monkeypatch)
    assert main(["acquire", "--resume", str(out), "--plan", str(plan)]) == 2
    line = one_error_line(capsys)
    assert ("error: shaker.level 0.5 V in run.h5, 1.5 V in plan.toml: resume with the stored "
            "plan (omit --plan) or start a new run") in line
    assert made == [] and out.stat().st_size == size
    assert read_run(out, with_data=False).state == "stopped"


def test_counters_count_the_records_and_points_done_before_the_resume(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "200")  # lines unwrapped, whatever the host's width
    out = tmp_path / "run.h5"
    _stopped_hammer_run(out, 3)
    n = len(POINTS)
    assert main(["acquire", "--resume", str(out)]) == 0  # stdout captured: one line a point
    text = capsys.readouterr().out
    lines = [ln for ln in text.splitlines() if re.search(r"of \d+ done\)$", ln)]
    assert lines[0].startswith("point 4 ") and lines[0].endswith(f"(3 of {n} done)"), lines
    assert [ln.rsplit("(", 1)[1] for ln in lines] == [f"{k} of {n} done)"
                                                       for k in range(3, n)]
    assert re.search(rf"^points .* {n}/{n} ", text, re.M), text
    assert f"{n} records, run written to {out}" in text
    assert len(read_run(out, with_data=False).records) == n

    # an override that leaves the first point short: acquired again, counted over the file
    assert main(["acquire", "--resume", str(out), "--override", "1=reject"]) == 0
    text = capsys.readouterr().out
    assert f"point 1 (node 101, dir +1+0+0) ({n - 1} of {n} done)" in text
    assert re.search(rf"^points .* {n}/{n} ", text, re.M), text
    assert f"{n + 1} records, run written to {out}" in text
    run = read_run(out, with_data=False)
    assert run.state == "finished" and len(run.records) == n + 1
