"""``insitu frf RUN.h5``: the run file's hits processed as replay does, bad points reported."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from app.acquire.analysis import hit_result, margin_samples, point_result
from app.cli.main import main
from app.io.frf_h5 import read_frf_h5, read_frf_measurement
from app.io.runfile import RunWriter
from app.io.uff import read_frf_uff
from app.mockbench.bench import plan_for_bench
from drivers.base import ChannelConfig
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import half_sine, impulse_response, simulate

FS = 256.0
POINTS = [0, 7, 9]


def _hit(k: int, double: bool = False) -> np.ndarray:
    """One stored record (force N, accelerations m/s^2) of a hit at bench excitation ``k``."""
    b = get_bench("engine-rigid")
    g = b.geometry
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    n = plan.record.n_samples + 2 * margin_samples(FS)
    t0 = (margin_samples(FS) + plan.record.n_pretrigger + 2) / FS
    f = half_sine(n, FS, t0, 0.02, 200.0)
    if double:
        f = f + half_sine(n, FS, t0 + 0.1, 0.02, 80.0)
    ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                          g.coordinates(b.exc_nodes[k:k + 1]), b.exc_dirs[k:k + 1])
    return np.vstack([f[None], simulate(ir, f[None])])


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[np.ndarray]]:
    b = get_bench("engine-rigid")
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    chans = [ChannelConfig("F", 0, "force", 2.25)] + [
        ChannelConfig(f"a{i}", i + 1, "acceleration", 10.2, node=int(nd),
                      direction=(float(d[0]), float(d[1]), float(d[2])))
        for i, (nd, d) in enumerate(zip(b.resp_nodes, b.resp_dirs, strict=True))]
    path = tmp_path_factory.mktemp("run") / "run.h5"
    good = [_hit(POINTS[0]), _hit(POINTS[0])]
    w = RunWriter.create(path, plan_data=plan.to_dict(), station_data={}, channels=chans,
                         devices=["fe"] * len(chans), geometry=plan.geometry(), fs=FS,
                         n_samples=good[0].shape[1], method="hammer")
    for i, data in enumerate(good):
        w.add_record(0, data, time=float(i), peak_force=200.0, auto_accepted=True, reason="")
    w.add_record(1, _hit(POINTS[1], double=True), time=5.0, peak_force=200.0,
                 auto_accepted=False, reason="double hit (second impact 100.0 ms after the first)")
    w.finish("stopped", "stopped by the operator")  # point 3: no hit recorded
    return path, good


def test_frf_from_run_file_skips_points_without_hits(
        tmp_path: Path, run_file: tuple[Path, list[np.ndarray]],
        capsys: pytest.CaptureFixture[str]) -> None:
    path, good = run_file
    out = tmp_path / "frf.h5"
    assert main(["frf", str(path), "--out", str(out)]) == 2
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 2 and all(line.endswith("(skipped)") for line in lines)
    assert "point 2 (node 108" in lines[0] and "every hit rejected (double hit" in lines[0]
    assert "point 3 (node 110" in lines[1] and "no hit recorded: hit it again" in lines[1]
    assert "2 of 2 hits used" in cap.out and "2 bad run(s) skipped, exit status 2" in cap.out
    frf = read_frf_h5(out)
    b = get_bench("engine-rigid")
    assert frf.exc_nodes.tolist() == [int(b.exc_nodes[0])]
    # the same FRFs as the replay code path gives for that point, on 0 < f <= fs / 2.56
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    names = ["F", *(f"a{i}" for i in range(12))]
    ref = point_result([hit_result(d, plan.record, names, None) for d in good])
    assert ref is not None and ref.H is not None and ref.coherence is not None
    keep = (ref.freq > 0) & (ref.freq <= FS / 2.56)
    assert_array_equal(frf.freq, ref.freq[keep])
    assert_array_equal(frf.H, ref.H[..., keep])
    assert_array_equal(frf.coherence, ref.coherence[..., keep])
    prov = read_frf_measurement(out).provenance
    assert prov.excitation == "impact" and prov.estimator == "H1" and prov.estimated
    # the UFF output of the same: the same FRFs, coherence, DOFs and geometry when read back
    # (ASCII 58 records keep 12 significant digits)
    assert main(["frf", str(path), "--out", str(tmp_path / "frf.uff")]) == 2
    cap = capsys.readouterr()
    assert "2 bad run(s) skipped, exit status 2" in cap.out
    back = read_frf_uff(tmp_path / "frf.uff")
    assert_allclose(back.freq, frf.freq, rtol=1e-6)
    assert_allclose(back.H, frf.H, rtol=1e-11, atol=1e-11 * np.abs(frf.H).max())
    assert back.coherence is not None and frf.coherence is not None
    assert_allclose(back.coherence, frf.coherence, rtol=1e-11, atol=1e-12)
    assert_array_equal(back.resp_nodes, frf.resp_nodes)
    assert_array_equal(back.exc_nodes, frf.exc_nodes)
    assert_allclose(back.resp_dirs, frf.resp_dirs, atol=1e-12)
    assert_allclose(back.exc_dirs, frf.exc_dirs, atol=1e-12)
    assert_allclose(back.resp_xyz, frf.resp_xyz, atol=1e-9)
    assert_allclose(back.exc_xyz, frf.exc_xyz, atol=1e-9)


def test_identify_tells_a_run_file_from_an_frf_file(
        run_file: tuple[Path, list[np.ndarray]], capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = run_file
    assert main(["identify", str(path)]) == 2  # a run file: replayed, a point has no hit
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has no accepted hit: resume the run" in err


def test_averages_on_a_run_file_uses_the_first_hits(run_file: tuple[Path, list[np.ndarray]],
                                                     tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    path, good = run_file
    out = tmp_path / "frf.h5"
    assert main(["frf", str(path), "--out", str(out), "--averages", "1"]) == 2  # 2 bad points
    assert "1 of 2 hits used" in capsys.readouterr().out
    kept = read_frf_measurement(out)
    assert kept.provenance.n_averages == (1,)
    frf = kept.frf
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    names = ["F", *(f"a{i}" for i in range(12))]
    ref = point_result([hit_result(good[0], plan.record, names, None)])
    assert ref is not None and ref.H is not None
    keep = (ref.freq > 0) & (ref.freq <= FS / 2.56)
    assert_array_equal(frf.H, ref.H[..., keep])
    assert main(["frf", str(path), "--out", str(out), "--averages", "0"]) == 2
    assert "--averages must be at least 1" in capsys.readouterr().err
