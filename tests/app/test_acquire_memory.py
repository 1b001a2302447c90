"""A run's analysis keeps running spectral sums per point, not the records: memory stays flat.

The hammer procedure folds each used hit into its point's averaged spectra
(:class:`app.acquire.analysis.RunAnalysis`); a verdict changed on an older hit rebuilds the
point from the stored records, read one at a time. Both must give what averaging the
point's used hits at once gives (:func:`app.acquire.analysis.point_result`), bit for bit.
"""

from __future__ import annotations

import gc
import tracemalloc
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from numpy.typing import NDArray

from app.acquire import HammerProcedure, RunState, load_plan
from app.acquire.analysis import (
    RunAnalysis,
    hit_result,
    margin_samples,
    point_result,
    run_measurement,
)
from app.acquire.blocks import BlockAnalysis
from app.acquire.plan import TestPlan
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench
from processing.impact import ImpactResult
from processing.spectral import frf

ROOT = Path(__file__).resolve().parents[2]
NAMES = ["F", *(f"a{i}" for i in range(12))]


@pytest.fixture(scope="module")
def plan() -> TestPlan:
    return load_plan(ROOT / "docs" / "mock_bench_plan.toml")


def _record(plan: TestPlan, seed: int) -> NDArray[np.float64]:
    """One stored hit record: a 4-sample half-sine force (about 180 N) at the trigger
    position, 12 responses of decaying modes (30-41 Hz) plus noise, all seeded."""
    rec = plan.record
    m = margin_samples(rec.fs)
    n = rec.n_samples + 2 * m
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rec.fs
    f = np.zeros(n)
    i0 = m + rec.n_pretrigger
    f[i0:i0 + 4] = (190 + 10 * rng.random()) * np.sin(np.pi * (np.arange(4) + 0.5) / 4)
    h = np.exp(-8 * t) * np.sin(2 * np.pi * (30 + np.arange(12))[:, None] * t)
    x = np.array([np.convolve(f, hj)[:n] for hj in h]) + 1e-2 * rng.standard_normal((12, n))
    return np.vstack([f, x])


def _results(plan: TestPlan, records: Sequence[NDArray[np.float64]],
             overrides: Sequence[str] | None = None) -> list[ImpactResult]:
    return [hit_result(d, plan.record, NAMES, None, o)
            for d, o in zip(records, overrides or [""] * len(records), strict=True)]


def _assert_same(a: ImpactResult | None, b: ImpactResult | None) -> None:
    assert a is not None and b is not None
    assert a.H is not None and b.H is not None and a.coherence is not None
    assert_array_equal(a.H, b.H)  # bit for bit: the same sums in the same order
    assert_array_equal(a.coherence, b.coherence)
    assert a.n_accepted == b.n_accepted


def test_memory_does_not_grow_with_the_records(plan: TestPlan) -> None:
    """220 hits at one point: the analysis holds their average, not their spectra.

    Holding each hit's result (spectra, H, coherence of 12 responses on 769 lines) costs
    about 450 kB a hit; the running sums cost the hit's verdict and book-keeping only.
    """
    ana = RunAnalysis(plan, NAMES, None)
    warm, more = 20, 200
    base = _record(plan, 0)
    noise = np.random.default_rng(1)

    def add(i: int) -> None:
        # the same hit with fresh sensor noise: records differ, the tracing stays cheap
        data = base.copy()
        data[1:] += 1e-2 * noise.standard_normal(data[1:].shape)
        res = ana.add(i, 0, data)
        ana.set_used(i, res is not None and res.verdicts[0].accepted)
        assert ana.point(0) is not None

    for i in range(warm):
        add(i)
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i in range(warm, warm + more):
            add(i)
        gc.collect()
        after = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    growth = after - before
    assert ana.n_used(0) == warm + more
    point = ana.point(0)
    assert point is not None and point.n_accepted == warm + more
    assert growth < more * 4096, f"{growth / more:.0f} bytes a hit"


def test_running_sums_equal_averaging_at_once(plan: TestPlan) -> None:
    records = [_record(plan, s) for s in range(8)]
    points = [0, 1, 0, 0, 1, 0, 1, 0]
    loads: list[list[int]] = []

    def loader(ids: Sequence[int]) -> Iterator[tuple[int, NDArray[np.float64]]]:
        loads.append(list(ids))
        return ((i, records[i]) for i in ids)

    ana = RunAnalysis(plan, NAMES, None, loader=loader)
    for i, (d, p) in enumerate(zip(records, points, strict=True)):
        res = ana.add(i, p, d)
        ana.set_used(i, res is not None and res.verdicts[0].accepted)
    res_all = _results(plan, records)
    for p in (0, 1):
        _assert_same(ana.point(p), point_result([r for r, q in zip(res_all, points,
                                                                   strict=True) if q == p]))
    assert loads == []  # hits in order: folded in, nothing read back
    assert [ana.point_of(i) for i in range(8)] == points
    assert (ana.n_used(0), ana.n_used(1)) == (5, 3)

    # the operator rejects an older hit of point 0: its average is rebuilt without it
    ana.add(2, 0, records[2], "reject")
    ana.set_used(2, False)
    assert ana.n_used(0) == 4
    _assert_same(ana.point(0), point_result([res_all[i] for i in (0, 3, 5, 7)]))
    assert loads == [[0, 3, 5, 7]]
    # ... and accepts it again: back in, in acquisition order
    ana.add(2, 0, records[2], "accept")
    ana.set_used(2, True)
    _assert_same(ana.point(0), point_result(
        _results(plan, [records[i] for i in (0, 2, 3, 5, 7)], ["", "accept", "", "", ""])))
    # the first averages only
    _assert_same(ana.point(1, max_averages=2), point_result([res_all[1], res_all[4]]))
    _assert_same(ana.point(1), point_result([res_all[i] for i in (1, 4, 6)]))
    # a point with no used hit has no column
    for i in (1, 4, 6):
        ana.add(i, 1, records[i], "reject")
        ana.set_used(i, False)
    assert ana.point(1) is None and ana.n_used(1) == 0


def test_a_rebuild_needs_the_stored_records(plan: TestPlan) -> None:
    ana = RunAnalysis(plan, NAMES, None)
    for i in range(2):
        ana.add(i, 0, _record(plan, i))
        ana.set_used(i, True)
    ana.add(0, 0, _record(plan, 0), "reject")
    ana.set_used(0, False)
    with pytest.raises(RuntimeError, match="loader"):
        ana.point(0)


def test_the_procedure_keeps_no_samples(tmp_path: Path) -> None:
    """The listeners get each hit's samples; the procedure keeps its verdicts only (the
    samples are in the run file, where an override reads them back)."""
    seen: list[bool] = []

    class Listener:
        def on_hit(self, hit: object) -> None:
            seen.append(getattr(hit, "data", None) is not None)

    plan = plan_for_bench("engine-rigid", points=[0, 1], hits=3, length=0.5)
    path = tmp_path / "run.h5"
    with InProcessBench("engine-rigid") as bench:
        # patient replies: the machine may be loaded (this is no test of timeouts)
        proc = HammerProcedure(plan, bench.station, path, partial=True,
                               listeners=[bench.operator, Listener()], device_options={
                                   "frontend": {"reply_timeout": 5.0, "stall_timeout": 5.0}})
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
    run = read_run(path)
    assert len(proc.hits) == len(run.records) >= 3
    assert seen and all(seen)
    assert all(h.data is None for h in proc.hits)
    # the running sums give the replay's FRFs (all records at once), bit for bit
    replay = run_measurement(run)[0].frf
    assert proc.frf is not None and run.measurement is not None
    assert_array_equal(replay.H, proc.frf.H)
    assert_array_equal(replay.H, run.measurement.frf.H)


def _shaker_plan() -> TestPlan:
    return plan_for_bench("engine-rigid", points=[0, 1], fs=1024.0, method="shaker", shaker={
        "waveform": "random", "nperseg": 256, "averages": 4, "f_start": 2.0,
        "f_stop": 400.0, "ramp": 0.2, "settle": 1.5})


def _block(seed: int) -> NDArray[np.float64]:
    """A block of 13 rows (force, 12 responses) of seeded noise, 256 samples."""
    rng = np.random.default_rng(seed)
    f = rng.standard_normal(256)
    return np.vstack([f, f * np.arange(1, 13)[:, None] + 0.1 * rng.standard_normal((12, 256))])


def test_shaker_blocks_memory_does_not_grow() -> None:
    """200 blocks: the analysis holds each point's accumulator, not the blocks (26 kB each)."""
    ana = BlockAnalysis(_shaker_plan(), NAMES, None)
    blocks = [_block(s) for s in range(8)]
    for i in range(20):
        ana.add(i, 0, blocks[i % 8])
        ana.set_used(i, True)
        assert ana.point(0) is not None
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i in range(20, 220):
            ana.add(i, 0, blocks[i % 8].copy())
            ana.set_used(i, True)
            assert ana.point(0) is not None
        gc.collect()
        after = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert ana.n_used(0) == 220
    assert after - before < 200 * 4096, f"{(after - before) / 200:.0f} bytes a block"


def test_shaker_blocks_rebuild_equals_feeding_at_once() -> None:
    plan = _shaker_plan()
    blocks = [_block(s) for s in range(7)]
    blocks[3][2, 10] = np.nan  # lost samples: never used
    points = [0, 1, 0, 0, 1, 0, 0]
    ana = BlockAnalysis(plan, NAMES, None, loader=lambda ids: ((i, blocks[i]) for i in ids))

    def expected(ids: Sequence[int]) -> NDArray[np.complex128]:
        acc = ana._accumulator()
        for i in ids:
            acc.update(blocks[i])
        return frf(acc.spectra(), plan.record.estimator)[0]

    for i, p in enumerate(points):
        v = ana.add(i, p, blocks[i])
        ana.set_used(i, v is not None and v[0])
    assert (ana.n_used(0), ana.n_used(1)) == (4, 2)
    col = ana.point(0)
    assert col is not None and col.n_accepted == 4
    assert_array_equal(col.H, expected([0, 2, 5, 6]))
    ana.add(2, 0, blocks[2], "reject")  # an older block rejected: rebuilt without it
    ana.set_used(2, False)
    col = ana.point(0)
    assert col is not None and col.n_accepted == 3
    assert_array_equal(col.H, expected([0, 5, 6]))
    col = ana.point(0, max_averages=2)
    assert col is not None
    assert_array_equal(col.H, expected([0, 5]))
