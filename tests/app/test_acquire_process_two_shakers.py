"""Two shakers on the bench process: ``insitu mock-bench --shakers 2`` and ``insitu acquire
--mock-operator`` of docs/shaker_pair_plan.toml in another process, then ``insitu identify``.

The acquisition knows only the printed station file (two SG-1s on their own
pseudo-terminals, each force sensor on its own front-end input read over socketcand);
its simulated operator attaches each shaker of a drive to its point through the
bench's control channel. The identified mass and CoG must match the bench's model
within the in-process two-shaker test's tolerances (tests/app/test_two_shakers.py).
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from app.acquire import load_plan
from app.cli.main import main
from app.io.runfile import read_run
from hardware_mocks.bench_process import MockBench
from hardware_mocks.benches import get_bench
from tests.app.bench_checks import SIX, assert_identifies, cut_plan
from tests.app.test_acquire_process import _insitu, _stop, running_bench

ROOT = Path(__file__).resolve().parents[2]
PAIR = ROOT / "docs" / "shaker_pair_plan.toml"
ONE = ROOT / "docs" / "shaker_plan.toml"
BENCH = "engine-rigid"


@pytest.fixture
def pair_bench(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Path]]:
    fs = load_plan(PAIR).record.fs  # the front end runs at the plan's rate
    yield from running_bench(tmp_path, "--shakers", "2", "--bench", BENCH, "--fe-rate", f"{fs:g}")


@pytest.mark.slow
def test_pair_plan_acquired_from_another_process_identifies_the_bench(
        pair_bench: tuple[subprocess.Popen[str], Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    bench_proc, station = pair_bench
    # three of the documented plan's five drives: six points, the least that identifies
    six = cut_plan(PAIR, SIX, tmp_path / "pair.toml")
    plan = load_plan(six)
    assert plan.n_references == 2 and plan.shaker == load_plan(PAIR).shaker
    out, result = tmp_path / "run.h5", tmp_path / "run.json"
    acq = subprocess.run(_insitu("acquire", "--station", str(station), "--plan", str(six),
                                 "--out", str(out), "--mock-operator"),
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert acq.returncode == 0, acq.stderr + acq.stdout[-2000:]
    n_blocks = len(plan.drives) * plan.shaker.averages
    assert f"{n_blocks} records, run written to" in acq.stdout

    run = read_run(out)
    assert run.state == "finished" and run.records.accepted.all()
    assert [c.name for c in run.channels[:2]] == ["F1", "F2"]
    assert run.records.data.shape == (n_blocks, 14, plan.shaker.nperseg)
    assert run.records.point.tolist() == [d for d in range(len(plan.drives))
                                          for _ in range(plan.shaker.averages)]
    assert (run.records.missing == 0).all() and (run.records.bad_frames == 0).all()
    # both shakers pushed, each with its own signal, at the two points of every drive
    f1, f2 = run.records.data[:, 0], run.records.data[:, 1]
    assert (np.abs(f1).max(axis=1) > 20).all() and (np.abs(f2).max(axis=1) > 20).all()
    assert abs(np.corrcoef(f1.ravel(), f2.ravel())[0, 1]) < 0.2

    capsys.readouterr()
    assert main(["identify", str(out), "--out", str(result)]) == 0
    res = json.loads(result.read_text())
    model = get_bench(BENCH).model
    # measured: mass -0.005 %, CoG within 0.009 mm, inertia 0.009 % of the largest, K 0.03 %
    # of the largest; the tolerances are the in-process two-shaker test's
    assert_identifies(res, model)

    # the operator detached both shakers at the end
    from hardware_mocks.bench_control import BenchControl

    with BenchControl.from_station(station) as control:
        status = control.status()
    assert [s["exc"] for s in status["shakers"]] == [None, None]
    assert not any(s["output"] for s in status["shakers"])

    # a one-shaker plan on this bench: one line naming the fix, before any device opens
    one = tmp_path / "one.h5"
    assert main(["acquire", "--station", str(station), "--plan", str(ONE), "--out", str(one),
                 "--mock-operator"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "drives 1 shaker at once but the mock bench runs 2: " \
        "restart it with insitu mock-bench --shakers 1" in err
    assert not one.exists()
    _, err = _stop(bench_proc)
    assert bench_proc.returncode == 0 and "running with 2 shakers" in err


def test_shaker_counts_the_bench_cannot_run_are_refused_in_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for bad in ("3", "0", "two"):
        assert main(["mock-bench", "--shakers", bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--shakers {bad}: the mock bench has 1 or 2" in err
    # the pair plan on a one-shaker bench, and a hammer plan on a two-shaker one
    out = tmp_path / "run.h5"
    for shakers, plan, fix in ((1, PAIR, "drives 2 shakers at once but the mock bench runs 1: "
                                         "restart it with insitu mock-bench --shakers 2"),
                               (2, ROOT / "docs" / "mock_bench_plan.toml",
                                "a hammer plan, but the mock bench runs 2 shakers (its front "
                                "end records their forces, not the hammer's): restart it "
                                "without --shakers")):
        with MockBench(BENCH, shakers=shakers) as bench:
            station = tmp_path / f"bench{shakers}.toml"
            station.write_text(bench.station_toml())
            assert main(["acquire", "--station", str(station), "--plan", str(plan), "--out",
                         str(out), "--mock-operator"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and fix in err, err
        assert not out.exists()
