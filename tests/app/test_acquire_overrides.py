"""Operator overrides: during a hammer run (file column, averaged FRF, revisit, replay) and on
a finished run from the command line."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.acquire import HammerProcedure, Listener, RunState
from app.acquire.analysis import run_measurement
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench


class Overrider(Listener):
    """Accepts the rejected double hit 0, then rejects clean hit 1 once the run has moved on
    to point 1."""

    def __init__(self) -> None:
        self.proc: HammerProcedure | None = None
        self.hits: list = []
        self.frfs: list = []
        self.done: set[str] = set()

    def on_hit(self, hit) -> None:
        self.hits.append(hit)
        assert self.proc is not None
        if hit.hit_id == 0 and not hit.override and "accept" not in self.done:
            self.done.add("accept")
            self.proc.accept_hit(0)

    def on_next_point(self, point) -> None:
        assert self.proc is not None
        if point.index == 1 and "reject" not in self.done:
            self.done.add("reject")
            self.proc.reject_hit(1)

    def on_frf(self, frf) -> None:
        self.frfs.append(frf)


def test_overrides_during_a_run_and_from_the_command_line(tmp_path: Path, capsys) -> None:
    path = tmp_path / "run.h5"
    plan = plan_for_bench("engine-rigid", points=[0, 1], hits=2, length=0.5)
    ov = Overrider()
    with InProcessBench("engine-rigid", operator={"faults": {0: "double"}}) as bench:
        proc = HammerProcedure(plan, bench.station, path, partial=True,
                               listeners=[bench.operator, ov])
        ov.proc = proc
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
        points_visited = list(bench.operator.points)
    overridden = [h for h in ov.hits if h.override]
    assert [(h.hit_id, h.override) for h in overridden] == [(0, "accept"), (1, "reject")]
    assert not overridden[0].auto_accepted and "double hit" in overridden[0].reason
    assert overridden[0].accepted and not overridden[1].accepted
    # each override re-averaged the point: n_averages of point 0 went 1 (the accepted
    # double hit) ... and down again when hit 1 was rejected
    counts = [f.n_averages for f in ov.frfs if f.point == 0]
    assert 2 in counts and counts.index(2) < len(counts) - 1 and counts[-1] == 2
    # rejecting hit 1 left point 0 short after point 1: the run went back to it
    assert points_visited == [0, 1, 0]
    run = read_run(path)
    rec = run.records
    assert rec.override[:2] == ("accept", "reject")
    assert list(rec.accepted) == [h.accepted for h in proc.hits]
    assert rec.point.tolist().count(0) == 3 and rec.accepted[rec.point == 0].sum() == 2
    # replay honours the overrides: the same FRFs as the live run, bit for bit
    m = run_measurement(run)[0]
    frf = m.frf
    assert run.measurement is not None and np.array_equal(frf.H, run.measurement.frf.H)
    assert np.array_equal(frf.H, proc.frf.H)
    assert m.provenance.n_averages == (2, 2)

    # on the finished file: clear the reject of record 2 (printed numbers are 1-based)
    capsys.readouterr()
    assert main(["acquire", "--resume", "--out", str(path), "--override", "2=clear"]) == 0
    out = capsys.readouterr().out
    assert "record 2: override reject -> none" in out and "recomputed and stored" in out
    after = read_run(path)
    assert after.records.override[:2] == ("accept", "") and after.state == "finished"
    assert after.measurement is not None and after.measurement.provenance.n_averages == (3, 2)
    frf2 = run_measurement(after)[0].frf
    assert np.array_equal(frf2.H, after.measurement.frf.H) and not np.array_equal(frf2.H, frf.H)
    assert np.array_equal(after.records.data, rec.data)  # raw records untouched

    # mistakes are one line each, and change nothing
    for args, msg in ((["--override", "2=reject"], "give --resume"),
                      (["--resume", "--override", "2=maybe"], "HIT=accept"),
                      (["--resume", "--override", "99=accept"], "no record 99")):
        assert main(["acquire", "--out", str(path), *args]) == 2
        err = capsys.readouterr().err
        assert msg in err and len(err.strip().splitlines()) == 1
    assert read_run(path).records.override == after.records.override


def test_accepting_a_record_with_lost_samples_is_refused(tmp_path: Path, capsys) -> None:
    plan = plan_for_bench("engine-rigid", points=[0], hits=1, length=0.5)
    with InProcessBench("engine-rigid") as bench:
        bench.frontend.faults.drop_every = 7  # frames lost until the first hit is in
        orig = bench.operator.on_hit

        def heal(hit: object) -> None:
            bench.frontend.faults.drop_every = 0
            orig(hit)

        bench.operator.on_hit = heal  # type: ignore[method-assign]
        proc = HammerProcedure(plan, bench.station, tmp_path / "run.h5", partial=True,
                               listeners=[bench.operator])
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
    run = read_run(tmp_path / "run.h5")
    assert not run.records.accepted[0] and run.records.missing[0] > 0
    assert main(["acquire", "--resume", "--out", str(tmp_path / "run.h5"),
                 "--override", "1=accept"]) == 2
    err = capsys.readouterr().err
    assert "record 1 lost samples" in err and "cannot be used" in err
    assert read_run(tmp_path / "run.h5").records.override[0] == ""  # the file is unchanged


class ReopenThenClose(Listener):
    """Rejects hit 0 once point 1 is announced, and clears that reject when hit 1 is
    reported: the two overrides reach the run together, as two quick clicks do."""

    def __init__(self) -> None:
        self.proc: HammerProcedure | None = None

    def on_next_point(self, point) -> None:
        assert self.proc is not None
        if point.index == 1:
            self.proc.reject_hit(0)

    def on_hit(self, hit) -> None:
        assert self.proc is not None
        if hit.hit_id == 1 and not hit.override:
            self.proc.clear_override(0)


def test_an_override_undone_before_the_last_point_returns_asks_for_no_revisit(
        tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    plan = plan_for_bench("engine-rigid", points=[0, 1], hits=1, length=0.5)
    lis = ReopenThenClose()
    with InProcessBench("engine-rigid") as bench:
        proc = HammerProcedure(plan, bench.station, path, partial=True,
                               listeners=[lis, bench.operator])
        lis.proc = proc
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
        visited, made = list(bench.operator.points), bench.operator.hits_made
    # point 0 was short only while the clear waited in the queue: the run handled it
    # before choosing what was left, so the operator was not sent back to hit in vain
    assert visited == [0, 1] and made == 2
    rec = read_run(path, with_data=False).records
    assert rec.override == ("", "") and list(rec.accepted) == [True, True]
