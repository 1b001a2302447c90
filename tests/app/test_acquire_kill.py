"""``kill -9`` mid-run leaves a readable file with every hit; ``--resume`` completes it."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

import app.cli.acquire as cli_acquire
from app.cli.main import main
from app.io.runfile import read_run, repair
from app.mockbench.bench import InProcessBench
from tests.app.test_acquire_process import running_bench

POINTS = "0,1,3,4,6,8"
ROOT = Path(__file__).resolve().parents[2]


def test_kill_9_then_resume(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "run.h5"
    cmd = [sys.executable, "-m", "app.cli.main", "acquire", "--mock", "--bench", "engine-rigid",
           "--points", POINTS, "--length", "0.5", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300  # only guards against a hang
        n = 0
        while time.monotonic() < deadline and n < 3 and proc.poll() is None:
            time.sleep(0.1)
            if out.exists():
                os.kill(proc.pid, signal.SIGSTOP)  # held while counting: killed at that count
                try:
                    n = len(read_run(out, with_data=False).records)
                except ValueError:
                    n = 0  # file being created, or a record being written
                if n < 3:
                    os.kill(proc.pid, signal.SIGCONT)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(300)
    assert n >= 3
    repair(out)  # a no-op unless the kill struck mid-write
    with h5py.File(out, "r") as f:  # an outside HDF5 tool opens it (no SWMR flag)
        assert f["records/point"].shape[0] >= 3
    run = read_run(out)
    assert run.state == "interrupted"
    assert 3 <= len(run.records) < 6 and run.records.accepted.all()
    kept = run.records.data.copy()
    benches: list[str] = []
    made = cli_acquire._in_process_bench

    def bench(name: str, fs: float, shakers: int = 1) -> InProcessBench:
        benches.append(name)
        return made(name, fs, shakers)

    monkeypatch.setattr(cli_acquire, "_in_process_bench", bench)
    # the plain command: the run goes on on the bench its records came from
    assert main(["acquire", "--resume", str(out)]) == 0
    assert benches == ["engine-rigid"]
    done = read_run(out)
    assert done.state == "finished" and len(done.records) == 6
    assert (done.records.data[: len(kept)] == kept).all()  # nothing lost or rewritten
    assert sorted(done.records.point.tolist()) == list(range(6))
    assert done.measurement is not None and done.measurement.frf.H.shape == (12, 6, 257)
    # 0.5 s records are too short for this bench: the run says so instead of failing
    assert done.result is None, done.result
    assert done.message.startswith("identification failed"), done.message


def _kill_at(cmd: list[str], out: Path, n: int) -> None:
    """Run ``cmd`` and ``kill -9`` it once ``out`` holds ``n`` records or more."""
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300  # only guards against a hang
        while time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
            try:
                if out.exists() and len(read_run(out, with_data=False).records) >= n:
                    break
            except ValueError:
                pass  # file being created, or a record being written
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(300)


@pytest.mark.slow
def test_kill_9_on_a_station_then_the_command_the_refusal_gives(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A run on a station file (the mock bench process), killed: the plain ``--resume`` says
    in one line, before any device opens, what it needs; that command completes the run."""
    plan = tmp_path / "plan.toml"
    plan.write_text((ROOT / "docs" / "mock_bench_plan.toml").read_text()
                    .replace("length = 1.5", "length = 0.5").replace("hits = 3", "hits = 1"))
    with contextlib.contextmanager(running_bench)(tmp_path, "--bench", "engine-rigid") as (
            _, station):
        out = tmp_path / "run.h5"
        _kill_at([sys.executable, "-m", "app.cli.main", "acquire", "--station", str(station),
                  "--plan", str(plan), "--out", str(out), "--mock-operator"], out, 2)
        repair(out)
        before = read_run(out)
        assert before.state == "interrupted" and len(before.records) >= 2
        assert main(["acquire", "--resume", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "Traceback" not in err[0], err
        assert err[0] == (f"insitu acquire: error: {out} was acquired on station {station}: "
                          f"resume it with --station {station} (and --mock-operator for the "
                          "simulated operator)")
        assert read_run(out, with_data=False).state == "interrupted"  # untouched
        assert main(["acquire", "--resume", str(out), "--station", str(station),
                     "--mock-operator"]) == 0
        done = read_run(out)
        assert done.state == "finished" and len(done.records) == 9
        assert (done.records.data[: len(before.records)] == before.records.data).all()
