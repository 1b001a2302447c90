"""A full disk: a plan the disk cannot hold is refused before the run; a disk that fills
during the run stops it with every record before kept, the file whole and its state
honest, in one line and exit status 2; ``insitu repair``, ``replay`` and ``--resume`` take
the file."""

from __future__ import annotations

import errno
import re
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from app.acquire.hammer import HammerProcedure
from app.cli.main import main
from app.io import runfile
from app.io.runfile import read_run, reserve_path
from app.pipeline import RUN_FILE, load
from drivers.base import ChannelConfig
from processing.data import Geometry

#: six well-conditioned points of the rigid bench, short records: a run of a few seconds (too
#: short for the mass line: the FRFs are checked as replay does, not the identification)
ACQUIRE = ["acquire", "--mock", "--bench", "engine-rigid", "--points", "0,1,3,4,6,8",
           "--length", "0.5"]


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 4 MB tmpfs (skipped where mounting is not permitted: not root, no mount)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(disk)],
                              capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as err:
        pytest.skip(f"cannot mount a tmpfs here: {err}")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield disk
    finally:
        if subprocess.run(["umount", str(disk)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def test_a_plan_the_disk_cannot_hold_is_refused_before_the_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
        ) -> None:
    out = tmp_path / "run.h5"
    free = 1_200_000  # the report's 1.2 MB
    seen: list[Path] = []

    def disk_usage(path: Any) -> Any:
        seen.append(Path(path))
        return shutil._ntuple_diskusage(10**9, 10**9 - free, free)  # type: ignore[attr-defined]

    monkeypatch.setattr(shutil, "disk_usage", disk_usage)
    opened: list[object] = []
    monkeypatch.setattr(HammerProcedure, "_open_devices", lambda self: opened.append(self))
    assert main([*ACQUIRE, "--hits", "20", "--out", str(out)]) == 2
    line = _one_line(capsys.readouterr().err)
    m = re.search(r"needs about ([\d.]+) MB .* has ([\d.]+) MB free", line)
    assert m is not None, line
    # 120 hits of 13 x 532 samples (8 bytes each), 6.6 MB, before the margin and the FRFs
    assert float(m.group(1)) > 120 * 13 * 532 * 8 / 1e6 and m.group(2) == "1.2"
    assert "free space" in line
    assert seen and all(p == tmp_path for p in seen)  # the output's folder
    assert opened == [] and not out.exists() and not reserve_path(out).exists()


@pytest.mark.slow
def test_a_disk_that_fills_mid_run_keeps_the_records_then_resume_completes_it(
        small_disk: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = small_disk / "run.h5"
    filler = small_disk / "filler"
    # another program fills the disk once the second record is written; the run goes on in
    # its own process (it crashed with exit 139 when HDF5 wrote on a full disk)
    child = textwrap.dedent(f"""
        import os, sys
        from app.io import runfile
        from app.cli.main import main
        add = runfile.RunWriter.add_record
        def add_record(self, *args, **kwargs):
            i = add(self, *args, **kwargs)
            if i == 1:
                st = os.statvfs({str(small_disk)!r})
                with open({str(filler)!r}, "wb") as f:
                    f.write(bytes(st.f_bavail * st.f_frsize))
            return i
        runfile.RunWriter.add_record = add_record
        sys.exit(main({[*ACQUIRE, "--out", str(out)]!r}))
    """)
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True,
                          timeout=300)  # only guards against a hang
    assert done.returncode == 2, done.stderr[-2000:]
    line = _one_line(done.stderr)
    assert "disk full" in line and "free space" in line, line
    assert f"its 2 records are in {out}" in line and f"--resume {out}" in line, line
    assert "no record was acquired" not in line
    with h5py.File(out, "r") as f:  # any HDF5 tool opens it as it is
        assert f.attrs["state"] == "failed"
    run = read_run(out)
    assert run.state == "failed" and "disk full" in run.message
    assert len(run.records) == 2 and list(run.records.point) == [0, 1]
    assert np.all(np.isfinite(run.records.data)) and np.all(run.records.peak_force > 0)
    assert not reserve_path(out).exists()
    kept = run.records.data.copy()

    assert main(["repair", str(out)]) == 0
    assert "2 records (failed)" in capsys.readouterr().out
    filler.unlink()  # the operator frees space and continues
    assert main(["acquire", "--mock", "--bench", "engine-rigid", "--resume", str(out)]) == 0
    run = read_run(out)
    assert run.state == "finished" and len(run.records) == 6
    assert np.array_equal(run.records.data[:2], kept)
    assert run.measurement is not None
    replayed = load(out, fmt=RUN_FILE).frf  # as insitu replay and identify load it
    stored = run.measurement.frf.select_lines(replayed.freq[-1])
    assert np.array_equal(stored.H, replayed.H)  # replay: "identical to the live run"


def test_a_disk_full_while_storing_the_frfs_fails_the_run_keeping_every_record(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
        ) -> None:
    out = tmp_path / "run.h5"
    array = runfile._array
    live: dict[str, Any] = {}

    def full_at_the_frfs(group: h5py.Group, name: str, data: Any, units: str) -> Any:
        live[name] = np.asarray(data)
        if name == "H":  # h5py's error for a write on a full disk
            raise OSError(errno.ENOSPC, "Can't synchronously write data (file write failed: "
                          "errno = 28, error message = 'No space left on device')")
        return array(group, name, data, units)

    monkeypatch.setattr(runfile, "_array", full_at_the_frfs)
    assert main([*ACQUIRE, "--out", str(out)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "disk full" in line and "FRFs" in line and f"--resume {out}" in line, line
    assert "its 6 records are in" in line and "no record was acquired" not in line, line
    run = read_run(out)
    assert run.state == "failed" and "disk full" in run.message  # never "finished"
    assert len(run.records) == 6 and run.measurement is None and run.result is None
    assert not reserve_path(out).exists()
    monkeypatch.undo()
    assert main(["repair", str(out)]) == 0
    # every record is there: replay and identify recompute the FRFs the run could not store
    replayed = load(out, fmt=RUN_FILE).frf
    lines = np.isin(live["freq"], replayed.freq)  # replay's lines: 0 Hz and the top left out
    assert np.count_nonzero(lines) == replayed.freq.size
    assert np.array_equal(live["H"][:, :, lines], replayed.H)


def test_the_writer_holds_a_reserve_that_repair_deletes_after_a_crash(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run.h5"
    chans = [ChannelConfig("F", 0, "force", 2.25), ChannelConfig("a1", 1, "acceleration", 10.0,
                                                                  node=1, direction=(1, 0, 0))]
    w = runfile.RunWriter.create(out, plan_data={}, station_data={}, channels=chans,
                                 devices=["fe"] * 2, geometry=Geometry(np.array([1]),
                                                                       np.zeros((1, 3))),
                                 fs=1024.0, n_samples=64, method="hammer")
    w.add_record(0, np.ones((2, 64)), time=0.0, peak_force=1.0, auto_accepted=True, reason="")
    assert reserve_path(out).stat().st_size == runfile.RESERVE_BYTES  # the room to close on
    # the writer's process dies here (never closed): the reserve stays beside the file
    assert main(["repair", str(out)]) == 0
    assert not reserve_path(out).exists()
    assert "1 records (interrupted)" in capsys.readouterr().out
    w.finish("stopped")
    assert not reserve_path(out).exists() and read_run(out).state == "stopped"
