"""``insitu identify`` on time data: the bootstrap over hits runs by default and is reported."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.acquire.analysis import margin_samples
from app.cli.main import main
from app.io.runfile import RunWriter
from app.mockbench.bench import plan_for_bench
from drivers.base import ChannelConfig
from hardware_mocks.benches import get_bench
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import HammerSpec, hammer_test, write_uff
from hardware_mocks.signals import half_sine, impulse_response, simulate

FS = 256.0
POINTS = [0, 2, 4, 7, 9, 11, 13, 16]


def _hit(k: int, rng: np.random.Generator) -> np.ndarray:
    """One stored record (force N, accelerations m/s^2) of a hit at bench excitation ``k``,
    with 0.5 % noise on the responses."""
    b = get_bench("engine-rigid")
    g = b.geometry
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    n = plan.record.n_samples + 2 * margin_samples(FS)
    t0 = (margin_samples(FS) + plan.record.n_pretrigger + 2) / FS
    f = half_sine(n, FS, t0, 0.02, float(rng.uniform(120.0, 200.0)))
    ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                          g.coordinates(b.exc_nodes[k:k + 1]), b.exc_dirs[k:k + 1])
    x = simulate(ir, f[None])
    x = x + 0.005 * np.abs(x).max(axis=1, keepdims=True) * rng.normal(size=x.shape)
    return np.vstack([f[None], x])


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    b = get_bench("engine-rigid")
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    chans = [ChannelConfig("F", 0, "force", 2.25)] + [
        ChannelConfig(f"a{i}", i + 1, "acceleration", 10.2, node=int(nd),
                      direction=(float(d[0]), float(d[1]), float(d[2])))
        for i, (nd, d) in enumerate(zip(b.resp_nodes, b.resp_dirs, strict=True))]
    path = tmp_path_factory.mktemp("run") / "run.h5"
    rng = np.random.default_rng(7)
    first = _hit(POINTS[0], rng)
    w = RunWriter.create(path, plan_data=plan.to_dict(), station_data={}, channels=chans,
                         devices=["fe"] * len(chans), geometry=plan.geometry(), fs=FS,
                         n_samples=first.shape[1], method="hammer")
    for j, k in enumerate(POINTS):
        for h in range(3):
            data = first if (j, h) == (0, 0) else _hit(k, rng)
            w.add_record(j, data, time=float(3 * j + h), peak_force=200.0, auto_accepted=True,
                         reason="")
    w.finish("finished", "")
    return path


def _result(args: list[str], out: Path) -> dict[str, object]:
    assert main([*args, "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert isinstance(result, dict)
    return result


def test_run_file_bootstrap_by_default(run_file: Path, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    r = _result(["identify", str(run_file)], tmp_path / "r.json")
    u = r["uncertainty"]
    assert isinstance(u, dict)
    assert any(s.startswith("bootstrap over hits (200 resamples; 3-3 hits a point")
               for s in u["sources"])
    assert "bootstrap over hits" in capsys.readouterr().out  # the terminal's sources line
    ci = r["ci95"]
    assert isinstance(ci, dict) and isinstance(r["mass"], float)
    lo, hi = ci["mass"]
    assert lo <= r["mass"] <= hi
    none = _result(["identify", str(run_file), "--bootstrap", "0"], tmp_path / "n.json")
    nu = none["uncertainty"]
    assert isinstance(nu, dict) and not any("bootstrap" in s for s in nu["sources"])
    assert "ci95" not in none


@pytest.mark.parametrize(("extra", "message"), [
    (["--bootstrap", "1"], "--bootstrap must be 0 (none) or at least 2 resamples, got 1"),
    (["--bootstrap", "-3"], "--bootstrap must be 0 (none) or at least 2 resamples, got -3"),
    (["--bootstrap", "50", "--no-uncertainty"],
     "--no-uncertainty contradicts --bootstrap: drop one"),
])
def test_bad_bootstrap_options_are_refused_in_one_line(
        run_file: Path, extra: list[str], message: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", str(run_file), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_time_uff_hammer_bootstrap_names_the_points(tmp_path: Path) -> None:
    """A generated hammer test (``hardware_mocks/reference/timedata.py``) written as UFF time
    records: the bootstrap over its hits runs with the defaults, its contributions name the
    excitation columns."""
    sc = build_scenario(ScenarioSpec(seed=3, n_forces=6, n_sensors=3, elastic_ratio=None,
                                     damping="viscous"))
    path = tmp_path / "hammer.uff"
    write_uff(hammer_test(sc, HammerSpec(seed=2, hits=4, spacing=3.0, damping=3.0)), path)
    r = _result(["identify", str(path), "--bootstrap", "60"], tmp_path / "r.json")
    u = r["uncertainty"]
    assert isinstance(u, dict)
    assert any(s.startswith("bootstrap over hits (60 resamples; 4-4 hits a point")
               for s in u["sources"])
    assert "ci95" in r
