"""Shaker procedure end to end: mock shaker -> front end -> run file -> FRFs -> identification,
and the output turned off on a device error, when the worker hangs, and on stop."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from numpy.testing import assert_allclose

from app.acquire import Listener, RunState, load_plan
from app.acquire.analysis import run_measurement
from app.acquire.shaker import ShakerProcedure
from app.acquire.shaker_io import BURST_PRE
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench
from app.pipeline import RUN_FILE, load
from hardware_mocks.benches import get_bench
from hardware_mocks.operator import MockShakerOperator
from hardware_mocks.physics import HEARTBEAT
from processing.identify import fit
from processing.inertia import inertia_properties
from tests.app.bench_checks import SIX, assert_identifies, cut_plan

#: six of the engine's 18 excitations, spanning the rigid-body motions: the least that
#: identifies (each point is real time on the mock bench)
POINTS = [0, 1, 4, 8, 12, 15]
FS = 512.0
ROOT = Path(__file__).resolve().parents[2]

#: the watchdog armed on the shaker where a test hangs the worker on purpose, s
WATCHDOG = 1.0


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


def _wait(pred, timeout: float = 60.0) -> bool:
    """Poll ``pred`` until it holds; ``timeout`` (s) only guards against a hang."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.01)
    return False


@pytest.mark.slow
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
        assert proc.wait(300) is RunState.FINISHED, proc.message
        assert _wait(lambda: bench.shaker.level_now == 0.0)
        assert not bench.shaker.output and bench.shaker.exc is None
        cmds = bench.shaker.commands
        model = bench.bench.model
        assert bench.shaker.heartbeats > 0
    assert bench.shaker_operator.points == list(range(len(POINTS)))
    # the worker armed the watchdog itself (the station's time for the mock shaker), and
    # each point was driven and turned off
    assert f"SYST:HEART:TIM {HEARTBEAT:g}" in cmds and cmds.count("OUTP ON") == len(POINTS)
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
    stored = run.measurement
    assert stored is not None and stored.provenance.n_averages == (1,) * len(POINTS)
    frf = run_measurement(run)[0].frf  # the whole band, as the live run stored it
    result = fit(load(path, fmt=RUN_FILE))  # what every view identifies from the run file
    assert np.isfinite(proc.frf.H).all()  # 0 Hz too: blocks are not detrended
    assert np.array_equal(frf.H, proc.frf.H) and np.array_equal(frf.H, stored.frf.H)
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
                               listeners=[bench.shaker_operator, rec], heartbeat=WATCHDOG)
        proc.start()
        try:
            assert _wait(lambda: len(rec.hits) >= 2), proc.message
            assert dev.output and dev.level_now == pytest.approx(0.5)
            # 1. the amplifier trips: the run pauses with the device's reason, output off
            dev.amplifier_fault()
            assert _wait(lambda: rec.paused), proc.message
            assert "103" in rec.paused[0] and "Amplifier fault" in rec.paused[0]
            assert "acquired blocks are saved" in rec.paused[0]
            assert not dev.output and _wait(lambda: dev.level_now == 0.0)
            n_before = len(rec.hits)
            # 2. resumed, then the worker hangs for three watchdog times in a listener: the
            # watchdog turns the output off by itself, and the run pauses when the worker is back
            rec.hang_once = 3 * WATCHDOG
            proc.resume()
            assert _wait(lambda: len(rec.paused) == 2), proc.message
            assert "101" in rec.paused[1] and "Heartbeat lost" in rec.paused[1]
            assert not dev.output and len(rec.hits) > n_before
            # 3. resumed, then stopped: the output ramps down and goes off
            proc.resume()
            assert _wait(lambda: dev.output and len(rec.hits) > n_before + 2)
            proc.stop()
            assert proc.wait(300) is RunState.STOPPED
            assert not dev.output and _wait(lambda: dev.level_now == 0.0)
        finally:
            proc.stop()
            proc.wait(300)
    run = read_run(path)
    assert run.state == "stopped" and len(run.records) == len(rec.hits)
    rejected = [i for i, h in enumerate(rec.hits) if not h.auto_accepted]
    assert rejected and all("output went off" in run.records.reason[i] for i in rejected)
    assert not run.records.auto_accepted[rejected].any()


def test_stop_during_the_ramp_turns_the_output_off_at_once(tmp_path: Path) -> None:
    """A Stop pressed while the output ramps up (here a 3 s ramp to 0.5 V) is not held until
    the ramp and settling end: the output goes off within a read (0.1 s) or two, so the
    level never gets near 0.5 V (the ramp takes 2.7 s more from where the Stop comes)."""
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
            assert _wait(lambda: dev.output and 0.0 < dev.level_now < 0.05), proc.message
            proc.stop()
            levels: list[float] = []
            assert _wait(lambda: levels.append(dev.level_now) or not dev.output)
            assert proc.wait(300) is RunState.STOPPED
        finally:
            proc.stop()
            proc.wait(300)
    assert max(levels) < 0.4, f"the output ramped to {max(levels):.2f} V after Stop"
    assert not rec.hits  # stopped before the first block


@pytest.mark.slow
def test_burst_random_plan_acquired_and_identified_from_the_command_line(
        tmp_path: Path) -> None:
    """docs/shaker_burst_plan.toml on the built-in engine bench: ``insitu acquire --mock``,
    then ``insitu identify`` of the run file, against the bench's own mass, CoG, inertia, K.
    Six of its nine points (:data:`~tests.app.bench_checks.SIX`), its blocks as they are."""
    doc = ROOT / "docs" / "shaker_burst_plan.toml"
    plan_file = cut_plan(doc, SIX, tmp_path / "burst.toml")
    plan = load_plan(plan_file)
    s = plan.shaker
    assert s.waveform == "burst-random" and s.averages == 3 and s == load_plan(doc).shaker
    path, out = tmp_path / "burst.h5", tmp_path / "burst.json"
    assert main(["acquire", "--mock", "--bench", "engine-rigid", "--plan", str(plan_file),
                 "--out", str(path)]) == 0
    assert main(["identify", str(path), "--out", str(out)]) == 0

    run = read_run(path)
    n_pts = len(plan.excitations)
    assert run.method == "shaker" and run.state == "finished"
    with h5py.File(path, "r") as f:
        assert f["records"].attrs["waveform"] == "burst-random"
        assert f["records"].attrs["window"] == "boxcar"
    assert run.records.data.shape == (3 * n_pts, 13, s.nperseg)
    assert run.records.accepted.all()
    assert run.records.point.tolist() == [j for j in range(n_pts) for _ in range(3)]
    force = run.records.data[:, 0]
    # every block starts at its burst (BURST_PRE samples before it) and ends in silence
    burst = round(s.duty * s.nperseg)
    assert (np.abs(force[:, :BURST_PRE]) < 0.05 * np.abs(force).max(axis=1, keepdims=True)).all()
    on = np.abs(force) > 1e-9
    assert_allclose(on.sum(axis=1), burst, atol=3)
    assert not on[:, BURST_PRE + burst + 3:].any()
    assert run.measurement is not None
    stored = run.measurement.frf
    assert run.measurement.provenance.n_averages == (3,) * n_pts
    band = (stored.freq >= 5.0) & (stored.freq <= 150.0)
    # three bursts of a random multisine per point: coherence 1 but for leakage (none seen)
    assert stored.coherence is not None
    assert np.median(stored.coherence[..., band]) > 0.999

    model = get_bench("engine-rigid").model
    res = json.loads(out.read_text())
    # measured: mass 0.015 %, CoG 0.011 mm, inertia 0.03 % of the largest, K 0.03 % of the
    # largest; the tolerances are the hammer and chirp tests'
    assert_identifies(res, model)


def test_a_mock_run_that_pauses_stops_with_its_blocks_kept(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """``insitu acquire --mock``: nobody at the simulated bench resumes a paused run, so the
    command stops it (output off, blocks kept) and says so in one line, instead of waiting."""
    import app.cli.acquire as cli_acquire

    made = cli_acquire._in_process_bench

    class Tripping(MockShakerOperator):
        def on_hit(self, hit: object) -> None:
            if not self.shaker.errors and self.shaker.output:
                self.shaker.amplifier_fault()

    def bench(name: str, fs: float, shakers: int = 1) -> InProcessBench:
        b = made(name, fs, shakers)
        b.shaker_operator = Tripping(b.shaker)
        return b

    monkeypatch.setattr(cli_acquire, "_in_process_bench", bench)
    out = tmp_path / "tripped.h5"
    status: list[int] = []
    cmd = threading.Thread(target=lambda: status.append(main([
        "acquire", "--mock", "--bench", "engine-rigid", "--method", "shaker", "--length", "0.25",
        "--hits", "3", "--out", str(out)])), daemon=True)
    cmd.start()
    cmd.join(600)  # a command waiting for a resume nobody gives never ends
    assert not cmd.is_alive() and status == [2]
    err = capsys.readouterr().err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]  # after the pause's own warning, the one error line
    assert last.startswith("insitu acquire: error: run paused") and "Amplifier fault" in last
    assert f"records are in {out}" in last
    run = read_run(out)
    assert run.state == "stopped" and len(run.records) >= 1
