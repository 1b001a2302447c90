"""A run whose plan carries ``insitu plan``'s ``[prediction]``: ``insitu identify`` prints and
``insitu report`` shows the predicted std beside the achieved one, with their ratio."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from app.acquire.analysis import margin_samples
from app.cli.main import main
from app.io.runfile import RunWriter
from app.mockbench.bench import plan_for_bench
from app.report.sources import plan_prediction
from app.report.tables import comparison_rows
from drivers.base import ChannelConfig
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import half_sine, impulse_response, simulate

FS = 256.0
PREDICTION = {"criterion": "D", "noise": 0.01, "averages": 1, "cond_E": 2.0, "cond_T": 3.0,
              "mass": 0.5, "cog": [1e-3, 2e-3, 4e-3],
              "inertia_cog": (np.eye(3) * 0.05 + 0.01).tolist(),
              "stiffness": (np.eye(6) * 1e3).tolist()}


def _run(path: Path, prediction: dict[str, object] | None) -> Path:
    b = get_bench("engine-rigid")
    plan = plan_for_bench("engine-rigid", fs=FS, length=4.0, pretrigger=0.25)
    plan = dataclasses.replace(plan, prediction=prediction)
    chans = [ChannelConfig("F", 0, "force", 2.25)] + [
        ChannelConfig(f"a{i}", i + 1, "acceleration", 10.2, node=int(nd),
                      direction=(float(d[0]), float(d[1]), float(d[2])))
        for i, (nd, d) in enumerate(zip(b.resp_nodes, b.resp_dirs, strict=True))]
    n = plan.record.n_samples + 2 * margin_samples(FS)
    f = half_sine(n, FS, (margin_samples(FS) + plan.record.n_pretrigger + 2) / FS, 0.02, 200.0)
    g = b.geometry
    w = RunWriter.create(path, plan_data=plan.to_dict(), station_data={}, channels=chans,
                         devices=["fe"] * len(chans), geometry=plan.geometry(), fs=FS,
                         n_samples=n, method="hammer")
    for j in range(len(plan.excitations)):
        ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                              g.coordinates(b.exc_nodes[j:j + 1]), b.exc_dirs[j:j + 1])
        w.add_record(j, np.vstack([f[None], simulate(ir, f[None])]), time=float(j),
                     peak_force=200.0, auto_accepted=True, reason="")
    w.finish("finished")
    return path


def test_identify_and_report_show_predicted_beside_achieved(
        tmp_path: Path, qapp, capsys: pytest.CaptureFixture[str]) -> None:
    run = _run(tmp_path / "run.h5", PREDICTION)
    assert plan_prediction(run) == PREDICTION
    assert main(["identify", str(run)]) == 0
    out = capsys.readouterr().out
    assert "Predicted and achieved uncertainty" in out
    row = next(line for line in out.splitlines() if "CoG z_c" in line and "mm" in line
               and "4" in line)
    assert re.search(r"\b4\b", row)  # 4 mm predicted, then the achieved std and the ratio
    assert main(["report", str(run)]) == 0
    html = (tmp_path / "run.html").read_text()
    assert "<h2>Predicted and achieved uncertainty</h2>" in html
    m = re.search(r"<td class=\"l\">mass m</td><td class=\"l\">kg</td><td>0.5</td>"
                  r"<td>([^<]+)</td><td>([^<]+)</td>", html)
    assert m is not None
    achieved, ratio = float(m.group(1)), float(m.group(2))
    assert achieved > 0 and ratio == pytest.approx(achieved / 0.5, rel=0.02)
    assert "<td class=\"l\">K rz rz</td><td class=\"l\">N m/rad</td><td>1e+03</td>" in html


def test_no_prediction_no_table(tmp_path: Path, qapp, capsys: pytest.CaptureFixture[str]) -> None:
    run = _run(tmp_path / "run.h5", None)
    assert plan_prediction(run) is None
    assert main(["identify", str(run)]) == 0
    assert "Predicted and achieved" not in capsys.readouterr().out


def test_the_ratio_keeps_its_digits_when_the_test_beats_the_plan_by_far() -> None:
    # exact data give an achieved std far under the prediction: the ratio keeps three
    # significant digits (two decimals would show 0.00794 as 0.01)
    u = SimpleNamespace(std={"mass": 0.00397, "cog": np.array([1e-3, 2e-3, 4e-3])})
    rows = comparison_rows({"mass": 0.5, "cog": [4e-3, 4e-3, 4e-3]}, u)  # type: ignore[arg-type]
    assert rows[0] == ("mass m", "kg", "0.5", "0.00397", "0.00794")
    assert [r[4] for r in rows[1:4]] == ["0.25", "0.5", "1"]
    assert rows[4][3:] == ("—", "—")  # no achieved std for the inertia: no ratio
