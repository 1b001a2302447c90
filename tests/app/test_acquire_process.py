"""Two processes, as at a real bench: ``insitu mock-bench`` and ``insitu acquire --mock-operator``.

The bench runs in one process; the acquisition in another connects to it with the
printed station file only (front end over socketcand, TCP), and its simulated operator
hits each point through the bench's control channel. The run file must then identify
the bench's model, and ``insitu replay`` must give the same result.
"""

from __future__ import annotations

import dataclasses
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_allclose

from app.acquire import load_plan
from app.acquire.analysis import anti_aliased, run_measurement
from app.cli.main import main
from app.io.runfile import read_run
from app.pipeline import RUN_FILE, load
from hardware_mocks.benches import get_bench
from processing.identify import fit
from processing.inertia import inertia_properties
from tests.app.bench_checks import SIX, cut_plan

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "docs" / "mock_bench_plan.toml"
BENCH = "engine-rigid"


def _insitu(*args: str) -> list[str]:
    return [sys.executable, "-m", "app.cli.main", *args]


def _stop(proc: subprocess.Popen[str]) -> tuple[str, str]:
    """SIGTERM (the bench's clean exit), then kill if it hangs; always reaped."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        return proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate()


def running_bench(tmp_path: Path, *options: str
                  ) -> Iterator[tuple[subprocess.Popen[str], Path]]:
    """``insitu mock-bench OPTIONS --station FILE`` in its own process, until the caller is
    done with it: the process and its station file (a test failure if it does not start)."""
    station = tmp_path / "bench.toml"
    proc = subprocess.Popen(_insitu("mock-bench", *options, "--station", str(station)),
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120.0  # only guards against a hang
        while not station.exists():
            if proc.poll() is not None or time.monotonic() > deadline:
                _, err = _stop(proc)
                pytest.fail(f"mock-bench did not start (status {proc.returncode}): {err}")
            time.sleep(0.05)
        yield proc, station
    finally:
        _stop(proc)


@pytest.fixture
def mock_bench(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Path]]:
    yield from running_bench(tmp_path, "--bench", BENCH)


@pytest.mark.slow
def test_acquire_in_another_process_identifies_the_bench(
        mock_bench: tuple[subprocess.Popen[str], Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    bench_proc, station = mock_bench
    # six of the documented plan's nine points (the least that identifies), its records
    six = cut_plan(PLAN, SIX, tmp_path / "plan.toml")
    plan = load_plan(six)
    assert plan.record == load_plan(PLAN).record
    assert len(plan.excitations) >= 6 and plan.hits >= 3  # the coherence can show noise
    n_rec = len(plan.excitations) * plan.hits
    out = tmp_path / "run.h5"
    acq = subprocess.run(_insitu("acquire", "--station", str(station), "--plan", str(six),
                                 "--out", str(out), "--mock-operator"),
                         cwd=ROOT, capture_output=True, text=True, timeout=600)  # a hang
    assert acq.returncode == 0, acq.stderr + acq.stdout[-2000:]
    assert f"{n_rec} records, run written to" in acq.stdout
    assert "paused" not in acq.stdout + acq.stderr  # no device stalled, nothing waited for

    run = read_run(out)
    assert run.state == "finished"
    assert run.records.accepted.all() and len(run.records) == n_rec
    assert run.records.point.tolist() == [j for j in range(len(plan.excitations))
                                          for _ in range(plan.hits)]
    assert (run.records.missing == 0).all() and (run.records.bad_frames == 0).all()
    assert run.records.force_alignment == "same-device"  # the front end's own force input
    stored = json.loads(json.dumps(run.result))
    # tolerances: noise-free sensors and an exact model; what remains comes from the
    # 1.5 s records, the front end's sampling and the H1 estimator
    model = get_bench(BENCH).model
    truth = inertia_properties(model.theta)
    assert stored["mass"] == pytest.approx(truth.mass, rel=0.01)
    assert_allclose(stored["cog"], truth.cog, atol=0.002)  # 2 mm
    assert_allclose(np.diag(np.array(stored["stiffness"])), np.diag(model.K), rtol=0.03)

    # replay from the raw records, in-process and through the command line: the same result
    whole, _ = run_measurement(run)  # the whole-band FRFs, recomputed from the records
    stored_m = run.measurement
    assert stored_m is not None and np.array_equal(whole.frf.H, stored_m.frf.H)
    result = fit(load(out, fmt=RUN_FILE))  # what every view identifies from the run file
    assert result is not None
    _same(json.loads(json.dumps(result.to_json())), stored)
    # the stored FRFs keep the hammer's usable band (the 2.5 ms pulse's force is 20 dB down
    # near Nyquist, above the 400 Hz the run identifies) in their provenance: with the
    # per-hit spectra (not stored: they come from the records) they identify as the run did
    band_top = stored_m.provenance.force_band_top
    assert band_top is not None
    assert band_top == whole.provenance.force_band_top < stored_m.frf.freq[-1]
    assert stored_m.provenance.units is None and whole.provenance.units is not None
    with_units = dataclasses.replace(stored_m, provenance=dataclasses.replace(
        stored_m.provenance, units=whole.provenance.units))
    _same(json.loads(json.dumps(fit(anti_aliased(with_units)).to_json())), stored)
    replay = tmp_path / "replay.json"
    rep = subprocess.run(_insitu("replay", str(out), "--out", str(replay)), cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert rep.returncode == 0, rep.stderr
    _same(json.loads(replay.read_text()), stored)

    # the bench really was hit from the other process, hits times a point
    from hardware_mocks.bench_control import BenchControl

    with BenchControl.from_station(station) as control:
        assert control.status()["hits"] == n_rec

    # a bench that is not running any more: one line, exit status 2, no run file
    _, err = _stop(bench_proc)
    assert bench_proc.returncode == 0, err
    capsys.readouterr()
    dead = tmp_path / "dead.h5"
    assert main(["acquire", "--station", str(station), "--plan", str(PLAN), "--out", str(dead),
                 "--mock-operator"]) == 2
    msg = capsys.readouterr().err
    assert msg.count("\n") == 1 and "cannot connect (is insitu mock-bench running?)" in msg
    assert not dead.exists()


def test_station_without_a_control_channel_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    station = tmp_path / "station.toml"
    station.write_text('[station]\nname = "real bench"\n\n[devices.frontend]\n'
                       'backend = "frontend-can"\nfs = 1024\n'
                       'transport = { interface = "virtual", channel = "nowhere" }\n'
                       + "".join(f'\n[[devices.frontend.channels]]\nname = "a{n}{a}"\n'
                                 f'input = {i}\nquantity = "acceleration"\nsensitivity = 10.2\n'
                                 f'range = 5.0\nnode = {n}\ndirection = [{d}]\n'
                                 for i, (n, a, d) in enumerate(
                                     (n, a, d) for n in (1, 2, 3, 4)
                                     for a, d in zip("xyz", ("1, 0, 0", "0, 1, 0", "0, 0, 1"),
                                                     strict=True)))
                       + '\n[[devices.frontend.channels]]\nname = "F"\ninput = 12\n'
                         'quantity = "force"\nsensitivity = 2.25\nrange = 5.0\n')
    out = tmp_path / "run.h5"
    assert main(["acquire", "--station", str(station), "--plan", str(PLAN), "--out", str(out),
                 "--mock-operator"]) == 2
    msg = capsys.readouterr().err
    assert msg.count("\n") == 1, msg
    assert "no [extra.mock_bench] control address" in msg and not out.exists()
    # a plan at another rate than the bench's front end: refused before connecting
    station.write_text(station.read_text().replace("fs = 1024", "fs = 512")
                       + '\n[extra.mock_bench]\ncontrol = "127.0.0.1:9"\n')
    assert main(["acquire", "--station", str(station), "--plan", str(PLAN), "--out", str(out),
                 "--mock-operator"]) == 2
    assert "front end runs at 512 Hz: make them equal (insitu mock-bench --fe-rate 1024)" in (
        capsys.readouterr().err)
    # --mock-operator is for another process's bench only
    assert main(["acquire", "--mock", "--out", str(out), "--mock-operator"]) == 2
    assert "--mock-operator drives a bench started by insitu mock-bench" in capsys.readouterr().err


def _same(a: Any, b: Any, path: str = "result") -> None:
    """Equal results: the same keys and texts, numbers to 1e-6 (the spectra's sums may
    differ in the last digit, and with them which negligible contributions are listed)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for k in a:
            if k == "contributions":  # shares of numerically zero size come and go
                a[k], b[k] = ([c for c in x if c["fraction"] > 1e-9] for x in (a[k], b[k]))
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list) and any(isinstance(x, dict | str) for x in a):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, list | float) and not isinstance(a, bool):
        # to 1e-6 of each value and of the largest in its array: the summation order of
        # another process's BLAS differs, and the iterations (converged to 1e-10) carry the
        # rounding on: K's 0.36 N/m off the diagonal (8.7e5 on it) differed by 1e-14 of K,
        # a value of 1.4e-4 by 4.2e-9 of itself, between the acquiring process and the replay
        # in fresh clones. A different band, line or model moves results by 1e-4 or more.
        B = np.asarray(b, dtype=float)
        assert_allclose(np.asarray(a, dtype=float), B, rtol=1e-6,
                        atol=1e-6 * float(np.max(np.abs(B), initial=0.0)), err_msg=path)
    else:
        assert a == b, path
