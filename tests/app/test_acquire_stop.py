"""Ctrl-C (SIGINT) stops ``insitu acquire`` within seconds, its records kept, the run ``stopped``.

The acquisition runs in its own process against ``insitu mock-bench`` (another process),
as at a real bench; the signal comes while it acquires, and while a resumed run reads
back a long run's records (the point averages are rebuilt before acquiring again).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pytest

from app.io.runfile import iter_record_data, read_run

ROOT = Path(__file__).resolve().parents[2]
BENCH = "engine-rigid"
#: seconds from SIGINT to the process's exit that the test allows
BOUND = 5.0


def _insitu(*args: str) -> list[str]:
    return [sys.executable, "-m", "app.cli.main", *args]


#: the acquisition's environment: faulthandler on, so that a hang can be shown (SIGABRT
#: prints every thread's stack to stderr)
ENV = {**os.environ, "PYTHONFAULTHANDLER": "1"}


def _end(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[Path]:
    """A mock bench process; yields its station file."""
    station = tmp_path / "bench.toml"
    proc = subprocess.Popen(_insitu("mock-bench", "--bench", BENCH, "--station", str(station)),
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    try:
        # the bench writes its station file at once, when all its devices are up
        deadline = time.monotonic() + 120.0  # only guards against a hang
        while not (station.exists() and "[devices.frontend]" in station.read_text()):
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail("mock-bench did not start")
            time.sleep(0.05)
        yield station
    finally:
        _end(proc)


@pytest.fixture
def plan(tmp_path: Path) -> Path:
    """The mock-bench plan with records of 0.5 s and hits enough never to finish."""
    text = (ROOT / "docs" / "mock_bench_plan.toml").read_text()
    out = tmp_path / "plan.toml"
    out.write_text(text.replace("hits = 3", "hits = 500").replace("length = 1.5",
                                                                      "length = 0.5"))
    return out


def _records(path: Path) -> int:
    try:
        return len(read_run(path, with_data=False).records) if path.exists() else 0
    except ValueError:  # being written this very moment
        return 0


def _interrupt(proc: subprocess.Popen[str], when: float) -> tuple[float, str]:
    """SIGINT; returns the seconds to the exit (fails past BOUND) and stderr."""
    assert proc.poll() is None, proc.communicate()[1]
    assert not _ignores_sigint(proc.pid), "the acquisition was started with SIGINT ignored"
    proc.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    try:
        _, err = proc.communicate(timeout=BOUND)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)  # faulthandler: every thread's stack on stderr
        try:
            _, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
        pytest.fail(f"insitu acquire did not exit within {BOUND:g} s of SIGINT "
                    f"({when:.1f} s after it started); its threads then: {err[-6000:]}")
    return time.monotonic() - t0, err


def _check_stopped(path: Path, at_least: int, err: str) -> int:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert not any("Traceback" in ln or "internal error" in ln for ln in lines), err
    run = read_run(path, with_data=False)
    assert run.state == "stopped", (run.state, run.message, err)
    n = len(run.records)
    assert n >= at_least
    for _, data in iter_record_data(path):  # every record is whole
        assert data.shape == (len(run.channels), run.records.data.shape[2])
    return n


@pytest.mark.slow
def test_sigint_while_acquiring(bench: Path, plan: Path, tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    t_start = time.monotonic()
    proc = subprocess.Popen(_insitu("acquire", "--station", str(bench), "--plan", str(plan),
                                    "--out", str(out), "--mock-operator"),
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=ENV)
    try:
        deadline = time.monotonic() + 120.0
        while _records(out) < 3:
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "no record within 120 s"
            time.sleep(0.2)
        took, err = _interrupt(proc, time.monotonic() - t_start)
    finally:
        _end(proc)
    n = _check_stopped(out, 3, err)
    assert proc.returncode == 2
    assert f"run stopped: stopped by the operator; its {n} records are in {out}" in err
    assert took < BOUND


def _grow(path: Path, n: int) -> None:
    """Append copies of the stored records until the run holds ``n``.

    Written in bulk with h5py: the writer's flush and fsync per record would take
    seconds, and only the number of records matters here.
    """
    with h5py.File(path, "a") as f:
        rec = f["records"]
        k = rec["point"].shape[0]
        idx = np.arange(n) % k
        for name in rec:
            ds = rec[name]
            if isinstance(ds, h5py.Dataset) and ds.shape and ds.shape[0] == k:
                values = ds[()]
                ds.resize(n, axis=0)
                ds[k:] = values[idx[k:]]


@pytest.mark.slow
def test_sigint_while_resuming_a_long_run(bench: Path, plan: Path, tmp_path: Path) -> None:
    """A resume reads every stored record back; Ctrl-C then must not wait for the end."""
    out = tmp_path / "run.h5"
    proc = subprocess.Popen(_insitu("acquire", "--station", str(bench), "--plan", str(plan),
                                    "--out", str(out), "--mock-operator"),
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=ENV)
    try:
        deadline = time.monotonic() + 120.0
        while _records(out) < 2:
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "no record within 120 s"
            time.sleep(0.2)
        _interrupt(proc, 0.0)
    finally:
        _end(proc)
    n0 = 2000  # a long run: reading it back takes far longer than BOUND
    _grow(out, n0)
    assert _records(out) == n0

    t_start = time.monotonic()
    proc = subprocess.Popen(_insitu("acquire", "--resume", str(out), "--station", str(bench),
                                    "--mock-operator"),
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=ENV)
    try:
        # the read-back keeps the run file open (other reads take milliseconds): once it
        # has been open for 0.5 s running, the process is reading the records back
        deadline = time.monotonic() + 120.0
        since = None
        while since is None or time.monotonic() - since < 0.5:
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "the resume never read the run file back"
            held = _holds(proc.pid, out)
            since = (since or time.monotonic()) if held else None
            time.sleep(0.01)
        took, err = _interrupt(proc, time.monotonic() - t_start)
    finally:
        _end(proc)
    assert _check_stopped(out, n0, err) >= n0
    assert took < BOUND


def _ignores_sigint(pid: int) -> bool:
    """True if process ``pid`` ignores SIGINT (its SigIgn mask in /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigIgn:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGINT - 1) & 1)
    return False


def _holds(pid: int, path: Path) -> bool:
    """True while process ``pid`` has ``path`` open."""
    fds = Path(f"/proc/{pid}/fd")
    try:
        return any(os.readlink(fds / fd) == str(path) for fd in os.listdir(fds))
    except OSError:
        return False
