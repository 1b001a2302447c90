"""Run files stay readable by any HDF5 tool: after a writer's crash, and after ``insitu repair``."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from app.cli.main import main
from app.io.runfile import RunFileError, RunWriter, read_run, repair
from drivers.base import ChannelConfig
from processing.data import Geometry


def new_writer(path: Path) -> RunWriter:
    chans = [ChannelConfig("F", 0, "force", 2.25)] + [
        ChannelConfig(f"a{k}", k, "acceleration", 10.0, node=1, direction=d)
        for k, d in ((1, (1, 0, 0)), (2, (0, 1, 0)))]
    return RunWriter.create(path, plan_data={"x": 1}, station_data={}, channels=chans,
                            devices=["fe"] * 3, geometry=Geometry(np.array([1]), np.zeros((1, 3))),
                            fs=1024.0, n_samples=64, method="hammer")


def _plain_open(p: Path) -> None:
    with h5py.File(p, "r") as f:  # what an outside HDF5 tool does: no SWMR flag
        assert f.attrs["format"] == "insitu-run"


def test_file_is_closed_between_records(tmp_path: Path) -> None:
    w = new_writer(tmp_path / "run.h5")
    for k in range(3):
        w.add_record(k, np.full((3, 64), float(k)), time=float(k), peak_force=1.0,
                     auto_accepted=True, reason="")
        _plain_open(w.path)  # the writer holds no handle between records
    w.add_note("a note", 3.0)
    w.set_override(1, "reject")
    _plain_open(w.path)
    run = read_run(w.path)
    assert run.state == "interrupted" and len(run.records) == 3
    assert run.records.override[1] == "reject"
    assert np.array_equal(run.records.data[2], np.full((3, 64), 2.0))
    w.finish("stopped", "by the operator")
    with pytest.raises(RunFileError, match="closed"):
        w.add_note("too late", 4.0)
    assert read_run(w.path).state == "stopped"


def test_repair_mends_a_writer_killed_mid_write(tmp_path: Path) -> None:
    p = tmp_path / "run.h5"
    w = new_writer(p)
    w.add_record(0, np.ones((3, 64)), time=0.0, peak_force=1.0, auto_accepted=True, reason="")
    # another process opens the file to write and dies with it open (kill -9 mid-write)
    child = textwrap.dedent(f"""
        import os, h5py
        f = h5py.File({str(p)!r}, "a", libver="latest")
        f.swmr_mode = True
        f.flush()
        os._exit(0)
    """)
    subprocess.run([sys.executable, "-c", child], check=True, timeout=60)
    with pytest.raises(OSError, match="already open for write"):
        _plain_open(p)
    assert len(read_run(p).records) == 1  # insitu reads it as it is
    assert main(["repair", str(p)]) == 0
    _plain_open(p)
    run = read_run(p)
    assert len(run.records) == 1 and np.array_equal(run.records.data[0], np.ones((3, 64)))
    assert repair(p) is False  # nothing left to mend


def test_repair_refuses_a_file_that_is_no_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                              ) -> None:
    p = tmp_path / "x.h5"
    p.write_bytes(b"not hdf5 at all")
    assert main(["repair", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a readable HDF5 run file" in err[0]


def test_repair_clears_the_mark_of_a_writer_killed_without_swmr(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """kill -9 while the writer holds the file (as it does for each record's few ms): HDF5
    refuses every open, SWMR too; the reader says so in one line and ``insitu repair``
    clears the mark (HDF5's h5clear -s), every record whole."""
    p = tmp_path / "run.h5"
    w = new_writer(p)
    for k in range(2):
        w.add_record(k, np.full((3, 64), float(k)), time=float(k), peak_force=1.0,
                     auto_accepted=True, reason="")
    child = textwrap.dedent(f"""
        import os
        from pathlib import Path
        from app.io.runfile import _append
        f = _append(Path({str(p)!r}))  # the writer's own open, for a record
        f.flush()
        os.kill(os.getpid(), 9)
    """)
    subprocess.run([sys.executable, "-c", child], timeout=60,
                   cwd=Path(__file__).resolve().parents[2])
    for swmr in (False, True):
        with pytest.raises(OSError, match=r"already open for (SWMR )?writ"):
            h5py.File(p, "r", swmr=swmr)
    with pytest.raises(RunFileError, match=r"marked open for writing\): mend it with insitu "
                                           r"repair"):
        read_run(p)
    assert main(["replay", str(p)]) == 2  # one line naming the repair
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"insitu repair {p}" in err[0]
    assert main(["repair", str(p)]) == 0
    _plain_open(p)
    run = read_run(p)
    assert len(run.records) == 2 and np.array_equal(run.records.data[1], np.ones((3, 64)))
    assert repair(p) is False


def test_the_checksum_is_hdf5_s(tmp_path: Path) -> None:
    """lookup3 as HDF5 computes it: the stored checksum of superblocks HDF5 wrote."""
    from app.io._hdf5_mark import lookup3

    for n in range(3):
        p = tmp_path / f"f{n}.h5"
        with h5py.File(p, "w", libver="latest") as f:
            f.attrs["n"] = "x" * n
            f["d"] = np.arange(n + 1)
        head = p.read_bytes()[:48]
        end = 12 + 4 * head[9]
        assert int.from_bytes(head[end:end + 4], "little") == lookup3(head[:end])
    assert lookup3(b"") == 0xDEADBEEF
    assert lookup3(b"Four score and seven years ago") == 0x17770551  # Jenkins' own check
