"""``insitu batch`` and the Monte Carlo map on Dask: a local cluster of 2 workers, and a
scheduler and workers started apart as ``dask scheduler`` and ``dask worker`` processes."""

from __future__ import annotations

import csv
import re
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from distributed import Client

from app.batch import cluster
from app.batch.montecarlo import MassLineDraw, chunk_draws, map_draws
from app.cli.main import main
from app.io.frf_h5 import write_frf_h5
from app.io.uff import write_frf_uff
from hardware_mocks.benches import get_bench
from processing.data import FRFSet
from processing.identify import IdentificationResult, identify
from processing.inertia import inertia_properties

MODEL = get_bench("engine-rigid").model


def _frf(seed: int) -> FRFSet:
    """The engine bench's FRFs with 1 % noise, on every 4th line (256 lines: a quick test)."""
    f = get_bench("engine-rigid").frfset(noise=0.01, seed=seed)
    return replace(f, freq=f.freq[::4], H=f.H[:, :, ::4])


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """A UFF file, a bad file, an HDF5 FRF file: two benches' FRFs and a broken one between."""
    d = tmp_path_factory.mktemp("campaign")
    a, b, bad = d / "a.uff", d / "b.h5", d / "bad.uff"
    write_frf_uff(a, _frf(1))
    write_frf_h5(b, _frf(2), source="test")
    bad.write_text("not a universal file\n")
    return [a, bad, b]


@pytest.fixture(scope="module")
def reference() -> dict[int, IdentificationResult]:
    """What ``insitu identify`` finds for the two good files' FRFs, by seed."""
    return {seed: identify(_frf(seed)) for seed in (1, 2)}


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "campaign.csv").open(newline="") as fh:
        return list(csv.DictReader(fh))


def _check_tables(out: Path, files: list[Path], reference: dict[int, IdentificationResult]
                  ) -> None:
    rows = _rows(out)
    assert [r["file"] for r in rows] == [str(f) for f in files]
    assert [r["status"] for r in rows] == ["ok", "error", "ok"]
    assert "is it a universal file?" in rows[1]["error"] and rows[1]["mass_kg"] == ""
    for r, seed in ((rows[0], 1), (rows[2], 2)):
        # the row holds what `insitu identify` finds for the same FRFs
        ref = reference[seed]
        assert float(r["mass_kg"]) == pytest.approx(ref.properties.mass, rel=1e-9)
        assert float(r["mass_kg"]) == pytest.approx(MODEL.mass, rel=2e-3)
        np.testing.assert_allclose([float(r[f"cog_{a}_m"]) for a in "xyz"], MODEL.cog,
                                   atol=1e-3)
        assert float(r["Jxy_cog_kgm2"]) == pytest.approx(-ref.properties.inertia_cog[0, 1],
                                                         rel=1e-9)
        assert float(r["last_rigid_mode_hz"]) == pytest.approx(ref.rigid_modes_hz[5], rel=1e-9)
        assert r["error"] == "" and r["checks_pass"] == "True"
    table = pq.read_table(out / "campaign.parquet").to_pylist()
    assert [t["status"] for t in table] == ["ok", "error", "ok"]
    assert table[0]["mass_kg"] == pytest.approx(float(rows[0]["mass_kg"]), rel=1e-12)
    assert table[1]["mass_kg"] is None
    page = (out / "campaign.html").read_text()
    assert "3 files: 2 identified, 1 failed" in page
    assert f"<td>{float(rows[2]['mass_kg']):.3f} ± " in page  # the fit's covariance, by default


def test_batch_local_cluster(files: list[Path], reference: dict[int, IdentificationResult],
                             tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    # Dask's usual HTTP port taken (a second batch, another test, a notebook): no collision
    with _holding_port(8787):
        assert main(["batch", *map(str, files), "--out", str(out), "--workers", "2"]) == 2
    text = capsys.readouterr().out
    assert "3 files on a local cluster: 2 workers, 2 threads" in text
    assert re.search(r"3 files: 2 identified, 1 failed, in [\d.]+ s on 2 workers", text)
    assert f"error {files[1]}: " in text
    _check_tables(out, files, reference)


@contextmanager
def _holding_port(port: int) -> Iterator[None]:
    """Listen on ``port`` for the block (already taken by another process: the same)."""
    with socket.socket() as s:
        try:
            s.bind(("0.0.0.0", port))
            s.listen()
        except OSError:
            pass
        yield


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A ``dask scheduler`` and two one-thread ``dask worker`` processes, started apart;
    yields the scheduler's address; both processes are ended after the module."""
    log = tmp_path_factory.mktemp("dask") / "scheduler.log"
    procs: list[subprocess.Popen[bytes]] = []
    address = ""
    try:
        with log.open("wb") as fh:
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                 "127.0.0.1", "--port", "0", "--no-dashboard"],
                stdout=subprocess.DEVNULL, stderr=fh))
        deadline = time.monotonic() + 120
        while not address and time.monotonic() < deadline:
            assert procs[0].poll() is None, log.read_text()
            m = re.search(r"Scheduler at:\s+(tcp://\S+)", log.read_text())
            address = m.group(1) if m else ""
            time.sleep(0.2)
        assert address, "dask scheduler did not say its address within 120 s"
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2",
             "--nthreads", "1", "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout=30) as c:
            c.wait_for_workers(2, timeout=120)
        yield address
    finally:
        if address:  # the cluster closed by its scheduler: a SIGTERM'd worker takes 8 s
            with suppress(OSError), Client(address, timeout=10) as c:
                c.shutdown()
        for p in reversed(procs):  # the workers first, while their scheduler still answers
            if p is not procs[0]:
                with suppress(subprocess.TimeoutExpired):
                    p.wait(timeout=15)  # gone of themselves once the scheduler closed them
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()


def test_batch_on_a_running_scheduler(files: list[Path], scheduler: str,
                                      reference: dict[int, IdentificationResult], tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["batch", *map(str, files), "--out", str(out), "--scheduler", scheduler]) == 2
    text = capsys.readouterr().out
    assert f"3 files on {scheduler}: 2 workers, 2 threads" in text
    _check_tables(out, files, reference)


def _draw(sigma: float) -> MassLineDraw:
    frf = get_bench("engine-rigid").frfset()
    k = np.flatnonzero((frf.freq >= 60) & (frf.freq <= 120))[::4]
    return MassLineDraw(frf.freq[k], frf.H[:, :, k], frf.resp_xyz, frf.resp_dirs,
                        frf.exc_xyz, frf.exc_dirs, sigma)


def test_monte_carlo_on_the_cluster_is_the_serial_map(scheduler: str) -> None:
    draw = _draw(0.003)
    done: list[int] = []
    with cluster.open_client(scheduler) as client:
        out = map_draws(client, draw, 101, first_seed=7, chunk=10, progress=done.append)
        # no location error: every draw is the unperturbed estimate
        still = map_draws(client, _draw(0.0), 8)
    np.testing.assert_array_equal(out, chunk_draws(draw, np.arange(7, 108)))
    assert out.shape == (101, 10) and done[-1] == 101 and len(done) == 11
    assert np.ptp(out, axis=0).min() > 0  # each draw moved the points differently
    np.testing.assert_allclose(still, np.tile(still[0], (8, 1)), rtol=1e-12)
    # 3 mm of location error moves the CoG by millimetres, not metres: the mass line's
    # estimate follows the points (std of x_c, y_c, z_c between 0.1 and 10 mm)
    cog = np.array([inertia_properties(t).cog for t in out])
    assert np.all((cog.std(axis=0) > 1e-4) & (cog.std(axis=0) < 1e-2))
    assert inertia_properties(still[0]).mass == pytest.approx(MODEL.mass, rel=0.06)


def test_a_failing_draw_is_raised(scheduler: str) -> None:
    # a negative standard deviation: numpy refuses it inside the draw, on a worker
    with cluster.open_client(scheduler) as client, pytest.raises(ValueError, match="scale"):
        map_draws(client, _draw(-1.0), 4)


def test_unreachable_scheduler_is_one_line(tmp_path: Path, files: list[Path],
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT", 2.0)
    address = f"tcp://127.0.0.1:{_free_port()}"
    assert main(["batch", str(files[0]), "--out", str(tmp_path), "--scheduler", address]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"insitu batch: error: no Dask scheduler answered at {address} "
                             "within 2 s")
    assert "dask scheduler" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "campaign.csv").exists()


@pytest.mark.parametrize(("extra", "message"), [
    (["--refine-points", "-1"], "--refine-points must be from 0 to 20 rounds, got -1"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers sizes the local"),
    (["--workers", "0"], "--workers must be from 1 to 256 worker processes, got 0"),
    (["--overlap", "1.5"], "--overlap must be at least 0 and below 1"),
])
def test_bad_options_are_one_line(files: list[Path], tmp_path: Path, extra: list[str],
                                  message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["batch", str(files[0]), "--out", str(tmp_path), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_missing_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["batch", str(tmp_path / "none.uff"), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip() == (
        f"insitu batch: error: no such file: {tmp_path / 'none.uff'}")
