"""``insitu identify FILE --mounts mounts.toml``: modes always, mount rates and the torque roll
axis with a mounts file, one-line refusals for bad files and undetermined geometries."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.mounts import MountsFileError, load_mounts, mounts_from_dict
from app.io.uff import read_frf_uff, write_frf_uff
from app.report.mount_system import mount_system
from hardware_mocks.benches import get_bench
from processing.identify import identify


def _toml(mounts: list[tuple[str, np.ndarray, np.ndarray]], crank: str = "[1.0, 0.0, 0.0]"
          ) -> str:
    def vec(v: np.ndarray) -> str:
        return "[" + ", ".join(repr(float(x)) for x in v) + "]"
    text = f"crank_axis = {crank}\n"
    for name, p, axes in mounts:
        text += (f'[[mount]]\nname = "{name}"\nposition = {vec(p)}\n'
                 f"axes = [{', '.join(vec(a) for a in axes)}]\n")
    return text


@pytest.fixture(scope="module")
def engine(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The simulated engine's FRFs and a mounts file describing its three mounts."""
    d = tmp_path_factory.mktemp("engine")
    bench = get_bench("engine-rigid")
    uff = d / "engine.uff"
    write_frf_uff(uff, bench.frfset())
    toml = d / "mounts.toml"
    toml.write_text(_toml([(f"m{i}", m.position, m.axes.T)
                           for i, m in enumerate(bench.model.mounts)]))
    return uff, toml


def test_identify_with_mounts(engine: tuple[Path, Path], tmp_path: Path,
                              capsys: pytest.CaptureFixture[str]) -> None:
    uff, toml = engine
    out = tmp_path / "r.json"
    assert main(["identify", str(uff), "--mounts", str(toml), "--excitation-hz", "25",
                 "--loss-factor-hz", "20", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    for title in ("Rigid-body modes", "Kinetic-energy decoupling", "Individual mount rates",
                  "Torque roll axis"):
        assert title in text
    res = json.loads(out.read_text())
    model = get_bench("engine-rigid").model
    assert len(res["modes"]) == 6
    for m in res["modes"]:
        assert set(m) >= {"frequency_hz", "damping_ratio", "shape", "energy",
                          "isolation_margin"}
        assert sum(m["energy"]) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose([m["frequency_hz"] for m in res["modes"]],
                               model.rigid_modes().frequency, rtol=1e-3)
    assert [m["name"] for m in res["mounts"]] == ["m0", "m1", "m2"]
    np.testing.assert_allclose([m["rates"] for m in res["mounts"]],
                               [m.stiffness for m in model.mounts], rtol=0.01)
    # the bench's mounts have c = 2 zeta k / (2 pi 20 Hz), zeta = 0.06: eta(20 Hz) = 0.12
    np.testing.assert_allclose([m["loss_factors"] for m in res["mounts"]], 0.12, rtol=0.01)
    assert all(m["identifiable"] == [True] * 3 for m in res["mounts"])
    assert set(res["mounts"][0]["std"]) == {"rates", "loss_factors"}
    tra = res["torque_roll_axis"]
    JG = model.inertia_cog
    d = np.linalg.solve(JG, [1.0, 0, 0])
    np.testing.assert_allclose(tra["direction"], d / np.linalg.norm(d), atol=2e-3)
    np.testing.assert_allclose(tra["point"], model.cog, atol=1e-4)


def test_modes_without_mounts(engine: tuple[Path, Path], tmp_path: Path,
                              capsys: pytest.CaptureFixture[str]) -> None:
    uff, _ = engine
    out = tmp_path / "r.json"
    assert main(["identify", str(uff), "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert len(res["modes"]) == 6 and "mounts" not in res and "torque_roll_axis" not in res
    assert "Individual mount rates" not in capsys.readouterr().out


def _one_line_error(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    return err


@pytest.mark.parametrize(("content", "match"), [
    ("crank_axis = [1, 0, 0\n", "not valid TOML"),
    ('[[mount]]\nname = "a"\nposition = [0, 0, 0]\n', "crank_axis is missing"),
    ("crank_axis = [1, 0, 0]\n", "no [[mount]]"),
    ('crank_axis = [1, 0, 0]\n[[mount]]\nname = "a"\nposition = [0, 0]\n', "3 finite numbers"),
    ('crank_axis = [1, 0, 0]\n[[mount]]\nname = "a"\nposition = [0, 0, 0]\n'
     "axes = [[1, 0, 0], [1, 0, 0], [0, 0, 1]]\n", "orthonormal"),
    ('crank_axis = [0, 0, 0]\n[[mount]]\nposition = [0, 0, 0]\n', "must not be zero"),
    ('crank_axis = [1, 0, 0]\n[[mount]]\nposition = [0, 0, 0]\nstiffness = 3\n', "unknown"),
])
def test_bad_mounts_files(engine: tuple[Path, Path], tmp_path: Path, content: str, match: str,
                          capsys: pytest.CaptureFixture[str]) -> None:
    uff, _ = engine
    bad = tmp_path / "bad.toml"
    bad.write_text(content)
    err = _one_line_error(["identify", str(uff), "--mounts", str(bad)], capsys)
    assert match in err and "bad.toml" in err


def test_missing_mounts_file_and_bad_frequencies(engine: tuple[Path, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    uff, _ = engine
    assert "cannot read" in _one_line_error(
        ["identify", str(uff), "--mounts", str(tmp_path / "none.toml")], capsys)
    assert "--excitation-hz" in _one_line_error(
        ["identify", str(uff), "--excitation-hz", "-3"], capsys)


def test_refused_when_the_geometry_determines_no_rate(engine: tuple[Path, Path],
                                                      tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Eight mounts (24 rates, 21 entries of K): refused in one line before identifying."""
    uff, _ = engine
    rng = np.random.default_rng(2)
    toml = tmp_path / "eight.toml"
    toml.write_text(_toml([(f"m{i}", rng.normal(size=3) * 0.2, np.eye(3)) for i in range(8)]))
    err = _one_line_error(["identify", str(uff), "--mounts", str(toml)], capsys)
    assert "determines no rate" in err


def test_reader_round_trip(engine: tuple[Path, Path]) -> None:
    _, toml = engine
    m = load_mounts(toml)
    again = mounts_from_dict(m.to_dict())
    assert again.crank_axis == m.crank_axis
    for a, b in zip(again.mounts, m.mounts, strict=True):
        np.testing.assert_array_equal(a.position, b.position)
    with pytest.raises(MountsFileError, match="used twice"):
        mounts_from_dict({"crank_axis": [1, 0, 0], "mount": [
            {"name": "a", "position": [0, 0, 0]}, {"name": "a", "position": [1, 0, 0]}]})


def test_mount_system_without_a_positive_definite_inertia(engine: tuple[Path, Path]) -> None:
    """An identified M that is not positive definite has no modes and no torque roll axis:
    said in one line each, the mount rates (from K alone) still given."""
    uff, toml = engine
    r = identify(read_frf_uff(uff))
    M = r.M.copy()
    M[3:, 3:] *= -1.0  # inertia tensor negative definite
    bad = replace(r, M=M)
    ms = mount_system(bad, load_mounts(toml))
    assert ms.modes is None and ms.tra is None and ms.rates is not None
    assert any("no modes" in p for p in ms.problems)
    js = ms.to_json()
    assert js["modes"] == [] and len(js["mounts"]) == 3 and "torque_roll_axis" not in js
    assert bad.to_json()["modes"] == []
