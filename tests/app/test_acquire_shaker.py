"""Shaker procedure end to end: mock shaker -> front end -> run file -> FRFs -> identification,
and the output turned off on a device error, when the worker hangs, and on stop."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from app.acquire import Listener, RunState
from app.acquire.analysis import analyse_run
from app.acquire.shaker import ShakerProcedure
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench
from processing.inertia import inertia_properties

#: well-conditioned subset of the engine's 18 excitations (cond(T) 7.5), as the hammer test
POINTS = [0, 1, 3, 4, 6, 8, 9, 12, 15]
FS = 512.0


class Recorder(Listener):
    def __init__(self) -> None:
        self.hits: list = []
        self.frfs: list = []
        self.points: list = []
        self.paused: list[str] = []
        self.finished: list[RunState] = []
        self.event = threading.Event()
        self.hang_once = 0.0

    def on_next_point(self, point: object) -> None:
        self.points.append(point)

    def on_hit(self, hit: object) -> None:
        self.hits.append(hit)
        self.event.set()

    def on_frf(self, frf: object) -> None:
        self.frfs.append(frf)
        if self.hang_once:  # the worker hangs in a listener: nobody feeds the watchdog
            t, self.hang_once = self.hang_once, 0.0
            time.sleep(t)

    def on_paused(self, reason: str) -> None:
        self.paused.append(reason)
        self.event.set()

    def on_finished(self, state: RunState) -> None:
        self.finished.append(state)


def _wait(pred, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return False


def test_chirp_run_identifies_the_engine_and_replay_is_identical(tmp_path: Path) -> None:
    path = tmp_path / "shaker.h5"
    # periodic chirp, one 1 s period per block, leakage-free with a rectangular window;
    # 1 s of settling after the 0.1 s ramp lets the slowest mode (tau 0.46 s) die out
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, method="shaker", shaker={
        "waveform": "chirp", "level": 0.5, "f_start": 2.0, "f_stop": FS / 2.56, "averages": 1,
        "nperseg": 512, "ramp": 0.1, "settle": 1.0})
    rec = Recorder()
    with InProcessBench("engine-rigid", fs_frontend=FS) as bench:
        proc = ShakerProcedure(plan, bench.station, path,
                               listeners=[bench.shaker_operator, rec])
        proc.start()
        assert proc.wait(90) is RunState.FINISHED, proc.message
        assert _wait(lambda: bench.shaker.level_now == 0.0, 2.0)
        assert not bench.shaker.output and bench.shaker.exc is None
        cmds = bench.shaker.commands
        model = bench.bench.model
        assert bench.shaker.heartbeats > 0
    assert bench.shaker_operator.points == list(range(len(POINTS)))
    # the worker armed the watchdog itself, and each point was driven and turned off
    assert "SYST:HEART:TIM 0.5" in cmds and cmds.count("OUTP ON") == len(POINTS)
    assert cmds.count("SOUR:FUNC CHIRP") == len(POINTS) and "SOUR:PER 1" in cmds
    assert cmds.count("OUTP OFF") >= len(POINTS)
    assert [f.n_averages for f in rec.frfs] == [1] * len(POINTS)
    assert rec.frfs[0].H.shape == (12, 257) and rec.finished == [RunState.FINISHED]
    truth = inertia_properties(model.theta)
    assert proc.result is not None and proc.frf is not None
    p = proc.result.properties
    # noise-free sensors and a leakage-free excitation: measured 0.003 % on the mass,
    # 0.01 mm on the centre of gravity, 0.005 % on the inertia, 0.14 % on K; the
    # tolerances are the hammer test's
    assert p.mass == pytest.approx(truth.mass, rel=0.005)
    assert_allclose(p.cog, truth.cog, atol=0.002)
    assert_allclose(p.inertia_cog, truth.inertia_cog, atol=0.01 * np.abs(truth.inertia_cog).max())
    assert_allclose(proc.result.K, model.K, atol=0.02 * np.abs(model.K).max())

    run = read_run(path)
    assert run.method == "shaker" and run.state == "finished"
    assert run.records.data.shape == (len(POINTS), 13, 512)
    assert run.records.accepted.all() and run.records.point.tolist() == list(range(len(POINTS)))
    assert np.abs(run.records.data[:, 0]).max() < 2000  # force within the sensor's range
    assert run.frf is not None and run.frf.meta["n_averages"] == [1] * len(POINTS)
    frf, result, _ = analyse_run(run)
    assert np.isfinite(proc.frf.H).all()  # 0 Hz too: blocks are not detrended
    assert np.array_equal(frf.H, proc.frf.H) and np.array_equal(frf.H, run.frf.H)
    assert np.array_equal(frf.coherence, proc.frf.coherence, equal_nan=True)
    assert np.array_equal(result.theta, proc.result.theta)
    assert main(["replay", str(path)]) == 0


def test_output_off_on_device_error_hung_worker_and_stop(tmp_path: Path) -> None:
    path = tmp_path / "faults.h5"
    plan = plan_for_bench("engine-rigid", points=[0, 1], fs=FS, method="shaker", shaker={
        "waveform": "random", "level": 0.5, "f_start": 2.0, "f_stop": 200.0, "averages": 1000,
        "nperseg": 128, "ramp": 0.1, "settle": 0.2})
    rec = Recorder()
    with InProcessBench("engine-rigid", fs_frontend=FS) as bench:
        dev = bench.shaker
        proc = ShakerProcedure(plan, bench.station, path, partial=True,
                               listeners=[bench.shaker_operator, rec])
        proc.start()
        try:
            assert _wait(lambda: len(rec.hits) >= 2), proc.message
            assert dev.output and dev.level_now == pytest.approx(0.5)
            # 1. the amplifier trips: the run pauses with the device's reason, output off
            dev.amplifier_fault()
            assert _wait(lambda: rec.paused), proc.message
            assert "103" in rec.paused[0] and "Amplifier fault" in rec.paused[0]
            assert "acquired blocks are saved" in rec.paused[0]
            assert not dev.output and _wait(lambda: dev.level_now == 0.0, 1.0)
            n_before = len(rec.hits)
            # 2. resumed, then the worker hangs 1.5 s in a listener: the watchdog (0.5 s)
            # turns the output off by itself, and the run pauses when the worker is back
            rec.hang_once = 1.5
            proc.resume()
            assert _wait(lambda: len(rec.paused) == 2, 15.0), proc.message
            assert "101" in rec.paused[1] and "Heartbeat lost" in rec.paused[1]
            assert not dev.output and len(rec.hits) > n_before
            # 3. resumed, then stopped: the output ramps down and goes off
            proc.resume()
            assert _wait(lambda: dev.output and len(rec.hits) > n_before + 2, 10.0)
            proc.stop()
            assert proc.wait(10) is RunState.STOPPED
            assert not dev.output and _wait(lambda: dev.level_now == 0.0, 1.0)
        finally:
            proc.stop()
            proc.wait(10)
    run = read_run(path)
    assert run.state == "stopped" and len(run.records) == len(rec.hits)
    rejected = [i for i, h in enumerate(rec.hits) if not h.auto_accepted]
    assert rejected and all("output went off" in run.records.reason[i] for i in rejected)
    assert not run.records.auto_accepted[rejected].any()


def test_stop_during_the_ramp_turns_the_output_off_at_once(tmp_path: Path) -> None:
    """A Stop pressed while the output ramps up (here a 3 s ramp) is not held until the
    ramp and settling end: the output goes off within a read (0.1 s) or two."""
    plan = plan_for_bench("engine-rigid", points=[0, 1], fs=FS, method="shaker", shaker={
        "waveform": "random", "level": 0.5, "f_start": 2.0, "f_stop": 200.0, "averages": 2,
        "nperseg": 128, "ramp": 3.0, "settle": 1.0})
    rec = Recorder()
    with InProcessBench("engine-rigid", fs_frontend=FS) as bench:
        dev = bench.shaker
        proc = ShakerProcedure(plan, bench.station, tmp_path / "ramp.h5", partial=True,
                               listeners=[bench.shaker_operator, rec])
        proc.start()
        try:
            assert _wait(lambda: dev.output and 0.0 < dev.level_now < 0.5), proc.message
            t0 = time.monotonic()
            proc.stop()
            assert _wait(lambda: not dev.output, 2.0)
            took = time.monotonic() - t0
            assert proc.wait(10) is RunState.STOPPED
        finally:
            proc.stop()
            proc.wait(10)
    assert took < 0.5, f"output went off {took:.2f} s after Stop"
    assert not rec.hits  # stopped before the first block
