"""Injected faults during a hammer run: double hit, overload, corrupted frames, silent device."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from app.acquire import HammerProcedure, Listener, RunState
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench

POINTS = [0, 1]


class Events(Listener):
    def __init__(self) -> None:
        self.hits: list = []
        self.paused: list[str] = []
        self.paused_evt = threading.Event()

    def on_hit(self, hit: object) -> None:
        self.hits.append(hit)

    def on_paused(self, reason: str) -> None:
        self.paused.append(reason)
        self.paused_evt.set()


def _run(tmp_path: Path, faults: dict[int, str], **kw: object):
    plan = plan_for_bench("engine-rigid", points=POINTS, length=0.5)
    ev = Events()
    with InProcessBench("engine-rigid", operator={"faults": faults}) as bench:
        proc = HammerProcedure(plan, bench.station, tmp_path / "run.h5",
                               listeners=[bench.operator, ev], partial=True, **kw)
        proc.start()
        state = proc.wait(120)  # only guards against a hang
    return state, ev, read_run(tmp_path / "run.h5")


def test_double_hit_and_overload_are_rejected_and_replaced(tmp_path: Path) -> None:
    state, ev, run = _run(tmp_path, {0: "double", 2: "overload"})
    assert state is RunState.FINISHED
    assert [h.auto_accepted for h in ev.hits] == [False, True, False, True]
    assert "double hit" in ev.hits[0].reason
    assert "overload on F_fe" in ev.hits[2].reason
    assert list(run.records.auto_accepted) == [False, True, False, True]
    assert run.records.reason[0] == ev.hits[0].reason
    assert list(run.records.point) == [0, 0, 1, 1]


@pytest.mark.slow
def test_corrupted_hammer_frames_are_counted_and_the_hit_rejected(tmp_path: Path) -> None:
    plan = plan_for_bench("engine-rigid", points=POINTS, length=0.5)
    ev = Events()
    with InProcessBench("engine-rigid") as bench:
        bench.hammer.faults.corrupt_every = 3  # until the first hit is in
        orig = bench.operator.on_hit

        def heal(hit: object) -> None:
            bench.hammer.faults.corrupt_every = 0
            orig(hit)

        bench.operator.on_hit = heal  # type: ignore[method-assign]
        proc = HammerProcedure(plan, bench.station, tmp_path / "run.h5",
                               listeners=[bench.operator, ev], partial=True,
                               force_channel="F")  # the hammer's own digitiser, over serial
        proc.start()
        assert proc.wait(120) is RunState.FINISHED, proc.message
    first = ev.hits[0]
    assert not first.accepted and first.bad_frames > 0 and first.missing > 0
    assert "samples lost" in first.reason and "corrupted frames" in first.reason
    assert all(h.accepted for h in ev.hits[1:]) and len(ev.hits) == 3
    run = read_run(tmp_path / "run.h5")
    assert run.records.bad_frames[0] == first.bad_frames
    assert np.isnan(run.records.force_raw[0]).any() and run.records.fs_raw == 4096


def test_device_that_stops_answering_pauses_and_keeps_the_hits(tmp_path: Path) -> None:
    plan = plan_for_bench("engine-rigid", points=[0, 1, 3], length=0.5)
    ev = Events()
    with InProcessBench("engine-rigid") as bench:
        orig = bench.operator.on_hit

        def go_silent(hit: object) -> None:
            if hit.hit_id == 0:  # type: ignore[attr-defined]
                bench.frontend.faults.silent = True
            orig(hit)

        bench.operator.on_hit = go_silent  # type: ignore[method-assign]
        proc = HammerProcedure(plan, bench.station, tmp_path / "run.h5",
                               listeners=[bench.operator, ev], partial=True)
        proc.start()
        assert ev.paused_evt.wait(120)  # the stall timeout, then the pause
        assert proc.state is RunState.PAUSED
        assert "frontend" in ev.paused[0] and "stopped answering" in ev.paused[0]
        assert "saved" in ev.paused[0]
        assert len(read_run(tmp_path / "run.h5").records) == 1  # the hit is in the file
        bench.frontend.faults.silent = False
        proc.resume()
        assert proc.wait(120) is RunState.FINISHED, proc.message
    run = read_run(tmp_path / "run.h5")
    assert run.state == "finished" and int(run.records.accepted.sum()) == 3


def test_mock_devices_clocks_are_judged_with_the_mock_benchs_timing_scatter(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Beside five busy processes a mock front end's frames scattered by 25 ms and the run
    paused: its clock is judged with the mock benches' 0.5 s, a real device's with 5 ms."""
    import app.acquire.streams as st
    from drivers.base import TIMING_SCATTER, StreamingFrontEnd
    from drivers.errors import SyncError
    from drivers.registry import create_device
    from drivers.sync import ClockFit
    from hardware_mocks.physics import TIMING_SCATTER as MOCK_SCATTER

    with InProcessBench("engine-rigid") as bench:
        devices = {name: create_device(cfg) for name, cfg in bench.station.devices.items()}
        streaming = {n: d for n, d in devices.items() if isinstance(d, StreamingFrontEnd)}
        assert set(streaming) == {"frontend", "hammer"}
        assert all(d.timing_scatter == MOCK_SCATTER for d in streaming.values())
        real = create_device(bench.station.devices["hammer"], timing_scatter=TIMING_SCATTER)
        assert isinstance(real, StreamingFrontEnd) and real.timing_scatter == 0.005
    fe, hammer = streaming["frontend"], streaming["hammer"]
    streams = st.HitStreams(fe, [0], hammer, 0, 10, 100, 5.0)
    scattered = ClockFit(rate=4096.0, t0=0.0, nominal=4096.0, residual=0.025, n_pairs=100,
                         span=10.0)
    monkeypatch.setattr(st, "fit_clock", lambda pairs, fs: scattered)
    streams._fits()  # 25 ms: within the mock bench's limit
    hammer.timing_scatter = TIMING_SCATTER
    with pytest.raises(SyncError, match=r"hammer: frame timing scatters by 25\.0 ms"):
        streams._fits()
