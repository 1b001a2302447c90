"""``insitu identify`` on a UFF file of time records: FRFs first, then identification."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff_time import TimeRun, write_time_uff
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import ImpulseResponse, impulse_response, simulate
from processing.excitation import continuous_random

FS = 256.0


def test_identify_time_uff(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b = get_bench("engine-rigid")
    g = b.geometry
    ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                          g.coordinates(b.exc_nodes), b.exc_dirs)
    runs = []
    for k in range(b.exc_nodes.size):
        f = continuous_random(12 * 1024, FS, rms=10.0, seed=k)
        x = simulate(ImpulseResponse(ir.h[:, k:k + 1], FS), f)
        runs.append(TimeRun(k + 1, FS, f[0], int(b.exc_nodes[k]), b.exc_dirs[k], x,
                            b.resp_nodes, b.resp_dirs))
    src, out = tmp_path / "time.uff", tmp_path / "result.json"
    write_time_uff(src, runs, g, binary=True)
    assert main(["identify", str(src), "--nperseg", "2048", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "time records; computing FRFs" in text and "averages" in text
    res = json.loads(out.read_text())
    assert abs(res["mass"] - b.model.mass) / b.model.mass < 2e-4
    np.testing.assert_allclose(res["cog"], b.model.cog, atol=1e-4)
    K = b.model.K
    scale = np.sqrt(np.outer(np.diag(K), np.diag(K)))
    assert np.max(np.abs(np.array(res["stiffness"]) - K) / scale) < 0.006
    assert res["checks"]["coherence"]["checked"]


def test_identify_time_uff_errors_are_one_line(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    b = get_bench("engine-rigid")
    f = continuous_random(4096, FS, rms=10.0, seed=0)
    x = np.zeros((12, 4096))
    run = TimeRun(1, FS, f[0], int(b.exc_nodes[0]), b.exc_dirs[0], x, b.resp_nodes,
                  b.resp_dirs)
    src = tmp_path / "time.uff"
    write_time_uff(src, [run], b.geometry, binary=True)
    assert main(["identify", str(src), "--nperseg", "1024"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("insitu identify: error:") and "\n" not in err
    assert main(["identify", str(src), "--refine-points", "-1"]) == 2
    assert "--refine-points" in capsys.readouterr().err
