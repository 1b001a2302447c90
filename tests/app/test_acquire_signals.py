"""SIGTERM and SIGHUP stop ``insitu acquire`` as Ctrl-C does (one line, records kept, the run
``stopped`` and resumable); a pause is one line."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import app.cli.acquire as cli_acquire
from app.cli.main import main
from app.io.runfile import iter_record_data, read_run
from app.mockbench.bench import InProcessBench
from tests.app.test_acquire_stop import BOUND, ENV

ROOT = Path(__file__).resolve().parents[2]


def _end(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.communicate()


def _records(path: Path) -> int:
    try:
        return len(read_run(path, with_data=False).records) if path.exists() else 0
    except ValueError:  # being written this very moment
        return 0


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_stop_the_run_keeping_its_records(
        sig: signal.Signals, tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli.main", "acquire", "--mock", "--bench", "engine-rigid",
         "--points", "0,1,3,4,6,8", "--length", "0.5", "--hits", "500", "--out", str(out)],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        deadline = time.monotonic() + 120.0  # only guards against a hang
        while _records(out) < 2:
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "no record within 120 s"
            time.sleep(0.1)
        proc.send_signal(sig)
        try:
            _, err = proc.communicate(timeout=BOUND + 15.0)  # the stop is bounded (STOP_WAIT)
        except subprocess.TimeoutExpired:
            pytest.fail(f"insitu acquire did not exit after {sig.name}")
    finally:
        _end(proc)
    assert proc.returncode == 2, (proc.returncode, err)  # as for Ctrl-C
    lines = err.strip().splitlines()
    run = read_run(out, with_data=False)
    n = len(run.records)
    assert lines == [f"insitu acquire: error: run stopped: stopped by {sig.name}; its {n} "
                     f"records are in {out} (continue with --resume {out})"], err
    assert run.state == "stopped" and run.message == f"stopped by {sig.name}"
    assert n >= 2
    for _, data in iter_record_data(out):  # every record whole
        assert data.shape == (len(run.channels), run.records.data.shape[2])


def test_a_pause_is_one_line(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    """The front end stops answering after the first hit: the mock bench's run stops at the
    pause, and the operator reads one line about it (no warnings around it)."""
    made = cli_acquire._in_process_bench

    def silent_after_the_first_hit(name: str, fs: float, shakers: int = 1) -> InProcessBench:
        bench = made(name, fs, shakers)
        orig = bench.operator.on_hit

        def go_silent(hit: object) -> None:
            bench.frontend.faults.silent = True
            orig(hit)

        bench.operator.on_hit = go_silent  # type: ignore[method-assign]
        return bench

    monkeypatch.setattr(cli_acquire, "_in_process_bench", silent_after_the_first_hit)
    out = tmp_path / "run.h5"
    assert main(["acquire", "--mock", "--bench", "engine-rigid", "--points", "0,1,3,4,6,8",
                 "--length", "0.5", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    text = captured.out + captured.err
    about = [ln for ln in text.splitlines()
             if "pause" in ln or "answer" in ln or "WARNING" in ln]
    assert len(about) == 1, about
    assert about[0].startswith("insitu acquire: error: run paused: frontend: no data for")
    assert f"its 1 records are in {out} (continue with --resume {out})" in about[0]
    assert captured.err.count("\n") == 1
    assert read_run(out, with_data=False).state == "stopped"
