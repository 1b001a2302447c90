"""The ``insitu`` command line: simulate -> identify -> JSON, and one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff import write_frf_uff
from hardware_mocks.benches import get_bench
from processing.data import FRFSet, Geometry

KEYS = {"mass", "cog", "inertia_cog", "inertia_origin", "principal_moments", "principal_axes",
        "stiffness", "damping", "bands", "checks"}


def test_simulate_identify_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    uff = tmp_path / "block.uff"
    out = tmp_path / "result.json"
    assert main(["simulate", "block-rigid", "--out", str(uff), "--mm"]) == 0
    assert main(["identify", str(uff), "--out", str(out), "--physical"]) == 0
    text = capsys.readouterr().out
    assert "Inertia parameters" in text and "Checks" in text
    res = json.loads(out.read_text())
    assert KEYS <= set(res)
    model = get_bench("block-rigid").model
    assert res["mass"] == pytest.approx(model.mass, rel=1e-4)
    np.testing.assert_allclose(res["cog"], model.cog, atol=5e-5)
    np.testing.assert_allclose(res["inertia_cog"], model.inertia_cog, atol=1e-3)
    np.testing.assert_allclose(res["stiffness"], model.K, atol=3e-3 * np.abs(model.K).max())
    assert set(res["bands"]) == {"mass_line", "stiffness"}
    assert res["checks"]["physical_consistency"]["pass"] is True


def _write(tmp_path: Path, frf: FRFSet) -> str:
    path = tmp_path / "bad.uff"
    write_frf_uff(path, frf)
    return str(path)


def _run_error(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    return err


def test_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = get_bench("engine-rigid").frfset()
    assert "bad.uff" in _run_error(["identify", str(tmp_path / "bad.uff")], capsys)
    good = _write(tmp_path, f)
    msg = _run_error(["identify", good, "--mass-band", "60", "900"], capsys)
    assert "outside the data" in msg
    few = FRFSet(f.freq, f.H[:, :5], f.resp_nodes, f.resp_dirs, f.exc_nodes[:5],
                 f.exc_dirs[:5], f.geometry)
    assert "excitation geometry has rank" in _run_error(["identify", _write(tmp_path, few)],
                                                        capsys)
    # all response points on one line
    xyz = f.geometry.xyz.copy()
    is_resp = np.isin(f.geometry.node_ids, f.resp_nodes)
    xyz[is_resp] = np.outer(np.arange(is_resp.sum()), [0.1, 0.05, 0.0])
    collinear = FRFSet(f.freq, f.H, f.resp_nodes, f.resp_dirs, f.exc_nodes, f.exc_dirs,
                       Geometry(f.geometry.node_ids, xyz))
    assert "collinear" in _run_error(["identify", _write(tmp_path, collinear)], capsys)
    assert "--noise" in _run_error(["simulate", "engine", "--out", str(tmp_path / "x.uff"),
                                    "--noise", "-1"], capsys)
