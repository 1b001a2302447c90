"""A shaker plan driven through a Keysight 33500 function generator (backend generator-visa,
PyVISA's pyvisa-py backend) simulated on a TCP socket, on the in-process mock bench: the
bench identified, and the failures (an error queued, the generator silent, the connection
dropped, PyVISA missing) each one line, output off, records kept."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import app.cli.acquire as cli_acquire
from app.acquire import Listener, RunState
from app.acquire.shaker import ShakerProcedure
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench
from hardware_mocks.generator_33500 import Generator33500
from hardware_mocks.operator import MockShakerOperator
from processing.inertia import inertia_properties
from tests.app.bench_checks import assert_identifies
from tests.app.cli_lines import one_error_line

#: six of the engine's 18 excitations, spanning the rigid-body motions: the least that
#: identifies (each point is real time on the mock bench)
POINTS = [0, 1, 4, 8, 12, 15]
FS = 512.0


class Recorder(Listener):
    def __init__(self) -> None:
        self.hits: list = []
        self.paused: list[str] = []
        self.finished: list[RunState] = []

    def on_hit(self, hit: object) -> None:
        self.hits.append(hit)

    def on_paused(self, reason: str) -> None:
        self.paused.append(reason)

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


def _chirp_plan(points: list[int], averages: int = 1):
    # periodic chirp, one 1 s period a block (an arbitrary waveform on the 33500), as the
    # SG-1's chirp test: leakage-free with a rectangular window
    return plan_for_bench("engine-rigid", points=points, fs=FS, method="shaker", shaker={
        "waveform": "chirp", "level": 0.5, "f_start": 2.0, "f_stop": FS / 2.56,
        "averages": averages, "nperseg": 512, "ramp": 0.1, "settle": 1.0})


@pytest.mark.slow
def test_chirp_plan_through_the_simulated_33500_identifies_the_engine(tmp_path: Path) -> None:
    path = tmp_path / "generator.h5"
    rec = Recorder()
    with InProcessBench("engine-rigid", fs_frontend=FS, generator="33500") as bench:
        gen = bench.shaker
        assert isinstance(gen, Generator33500)
        assert bench.station.devices["shaker"].backend == "generator-visa"
        proc = ShakerProcedure(_chirp_plan(POINTS), bench.station, path,
                               listeners=[bench.shaker_operator, rec])
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
        assert not gen.output and gen.exc is None and gen.connections == 1
        cmds = list(gen.commands)
        model = bench.bench.model
    # each point: the chirp uploaded as an arbitrary waveform, played at 4000 Sa/s
    # (20 samples a cycle at 200 Hz), 1 V peak to peak (0.5 V peak; set again after each
    # new waveform from the second point on), output on, then off
    n = len(POINTS)
    assert cmds[:6] == ["*IDN?", "OUTP OFF", "*RST", "*CLS", "OUTP:LOAD INF", "VOLT:OFFS 0"]
    assert cmds.count("FUNC ARB") == n and cmds.count("FUNC:ARB:SRAT 4000") == n
    assert cmds.count("VOLT:UNIT VPP") == cmds.count("VOLT 1") == 2 * n - 1
    assert cmds.count("OUTP ON") == n and cmds.count("OUTP OFF") >= n + 1
    assert rec.finished == [RunState.FINISHED] and not rec.paused
    run = read_run(path)
    assert run.state == "finished" and run.records.data.shape == (n, 13, 512)
    assert run.records.accepted.all()
    assert proc.result is not None
    p = proc.result.properties
    truth = inertia_properties(model.theta)
    print(f"33500 chirp: mass {p.mass:.5f} kg (truth {truth.mass:.5f}), CoG error "
          f"{np.abs(p.cog - truth.cog).max() * 1000:.4f} mm, inertia error "
          f"{np.abs(p.inertia_cog - truth.inertia_cog).max() / np.abs(truth.inertia_cog).max():.2e}"
          f", K error {np.abs(proc.result.K - model.K).max() / np.abs(model.K).max():.2e}")
    assert_identifies({"mass": p.mass, "cog": p.cog, "inertia_cog": p.inertia_cog,
                       "stiffness": proc.result.K}, model)


class Faulty(MockShakerOperator):
    """Attaches the shaker, then does ``fault`` to the generator at the first block."""

    def __init__(self, gen: Generator33500, fault) -> None:
        super().__init__(gen)
        self.gen = gen
        self.fault = fault
        self.done = False

    def on_hit(self, hit: object) -> None:
        if not self.done:
            self.done = True
            self.fault(self.gen)


def test_an_error_in_the_queue_or_a_dropped_connection_pauses_with_the_output_off(
        tmp_path: Path) -> None:
    path = tmp_path / "faults.h5"
    plan = plan_for_bench("engine-rigid", points=[0, 1], fs=FS, method="shaker", shaker={
        "waveform": "random", "level": 0.5, "f_start": 2.0, "f_stop": 200.0, "averages": 1000,
        "nperseg": 128, "ramp": 0.1, "settle": 0.2})
    rec = Recorder()
    with InProcessBench("engine-rigid", fs_frontend=FS, generator="33500") as bench:
        gen = bench.shaker
        assert isinstance(gen, Generator33500)
        proc = ShakerProcedure(plan, bench.station, path, partial=True,
                               listeners=[bench.shaker_operator, rec])
        proc.start()
        try:
            assert _wait(lambda: len(rec.hits) >= 2), proc.message
            assert gen.output and gen.function == "NOIS" and gen.unit == "VRMS"
            # 1. the generator queues an error: the driver turns the output off, the run
            # pauses naming it
            gen.push_error(-241, "Hardware missing")
            assert _wait(lambda: rec.paused), proc.message
            assert "generator error -241 Hardware missing" in rec.paused[0]
            assert "output turned off" in rec.paused[0] and "blocks are saved" in rec.paused[0]
            assert not gen.output
            n_before = len(rec.hits)
            # 2. resumed (a new connection), then the LAN cable is pulled: the run pauses
            # again, one line naming the generator (the 33500's output stays on: no watchdog)
            proc.resume()
            assert _wait(lambda: gen.output and len(rec.hits) > n_before + 1), proc.message
            gen.drop()
            assert _wait(lambda: len(rec.paused) == 2), proc.message
            assert "generator" in rec.paused[1] and "\n" not in rec.paused[1]
            assert gen.connections == 2
            proc.stop()
            assert proc.wait(300) is RunState.STOPPED
        finally:
            proc.stop()
            proc.wait(300)
    run = read_run(path)
    assert run.state == "stopped" and len(run.records) == len(rec.hits) > n_before
    rejected = [i for i, h in enumerate(rec.hits) if not h.auto_accepted]
    assert any("-241" in run.records.reason[i] for i in rejected)


class KeptBench(InProcessBench):
    """An in-process bench the command cannot shut down: the test looks at it afterwards."""

    def shutdown(self) -> None:
        pass

    def close(self) -> None:
        InProcessBench.shutdown(self)


@pytest.fixture
def benches():
    made: list[KeptBench] = []
    yield made
    for b in made:
        b.close()


def _patched_bench(monkeypatch: pytest.MonkeyPatch, benches: list[KeptBench], fault) -> None:
    """``insitu acquire --mock`` on a bench whose shaker is the simulated 33500 (kept in
    ``benches``); ``fault`` is done to it at the first block."""

    def bench(name: str, fs: float, shakers: int = 1) -> InProcessBench:
        b = KeptBench(name, fs_frontend=fs, shakers=shakers, generator="33500")
        assert isinstance(b.shaker, Generator33500)
        b.shaker_operator = Faulty(b.shaker, fault)
        benches.append(b)
        return b

    monkeypatch.setattr(cli_acquire, "_in_process_bench", bench)


def _acquire(out: Path) -> list[int]:
    status: list[int] = []
    cmd = threading.Thread(target=lambda: status.append(main([
        "acquire", "--mock", "--bench", "engine-rigid", "--method", "shaker", "--length",
        "0.25", "--hits", "50", "--out", str(out)])), daemon=True)
    cmd.start()
    cmd.join(600)
    assert not cmd.is_alive()
    return status


def test_a_silent_generator_stops_the_command_in_one_line_records_kept(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        benches: list[KeptBench]) -> None:
    def silence(gen: Generator33500) -> None:
        gen.silent = True

    _patched_bench(monkeypatch, benches, silence)
    out = tmp_path / "silent.h5"
    assert _acquire(out) == [2]
    last = one_error_line(capsys)
    assert last.startswith("insitu acquire: error: run paused") and "no answer from the " \
        "generator" in last and f"records are in {out}" in last
    run = read_run(out)
    assert run.state == "stopped" and len(run.records) >= 1
    gen = benches[0].shaker
    assert isinstance(gen, Generator33500) and gen.output  # silent: nothing reached it
    gen.silent = False  # it wakes up: the driver's OUTP OFF, waiting in its socket, runs
    assert _wait(lambda: not gen.output)


def test_without_pyvisa_the_run_ends_in_one_line_naming_the_pip_install(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        benches: list[KeptBench]) -> None:
    _patched_bench(monkeypatch, benches, lambda gen: None)
    monkeypatch.setitem(sys.modules, "pyvisa", None)  # import pyvisa raises ImportError
    out = tmp_path / "novisa.h5"
    assert _acquire(out) == [2]
    last = one_error_line(capsys)
    assert "needs PyVISA, which is not installed: pip install 'insitu[visa]'" in last
    assert "no record was acquired" in last
