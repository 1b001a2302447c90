"""What ``insitu identify``, ``replay`` and ``report`` say: a check that cannot fail says so,
no warning on a normal run, the uncertainty's sources once, one convention for spreads."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff import write_frf_uff
from app.report.tables import SPREADS
from hardware_mocks.benches import get_bench
from tests.app.test_cli_demo import six_point_plans
from tests.app.test_cli_mounts import _toml

SOURCES = "fit covariance: mass-line residual"


@pytest.fixture(scope="module")
def engine_uff(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The engine file of benchmarks/identify.py (`insitu identify engine.uff`)."""
    path = tmp_path_factory.mktemp("engine") / "engine.uff"
    write_frf_uff(path, get_bench("engine").frfset(noise=0.02, seed=9301), binary=False)
    return path


def test_identify_engine_says_each_thing_once(engine_uff: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", str(engine_uff)]) == 0
    text = capsys.readouterr().out
    flat = " ".join(text.split())  # rich wraps long lines
    assert flat.count(SOURCES) == 1  # the uncertainty's sources, once
    assert flat.count(" ".join(SPREADS.split())) == 1  # the spreads' convention, once
    assert "1.96 standard deviations" not in flat.replace(" ".join(SPREADS.split()), "")
    assert "warning" not in text  # a normal run: nothing is off
    assert re.search(r"│ coherence +│ not checked +│ no coherence in the input", text)
    assert "Coherence: not checked, no coherence in the input" in flat


def test_mount_rates_have_the_95_percent_spreads_of_the_other_tables(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bench = get_bench("engine-rigid")
    uff, toml, out = tmp_path / "e.uff", tmp_path / "mounts.toml", tmp_path / "r.json"
    write_frf_uff(uff, bench.frfset(noise=0.01, seed=4))
    toml.write_text(_toml([(f"m{i}", m.position, m.axes.T)
                           for i, m in enumerate(bench.model.mounts)]))
    assert main(["identify", str(uff), "--mounts", str(toml), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "std (N/m)" not in text and "95 % (N/m)" in text
    res = json.loads(out.read_text())
    m0 = res["mounts"][0]
    row = re.search(r"│ m0 +│ u +│ +([-+.e0-9]+) │ +± ([-+.e0-9]+) │ +([.0-9]+) │ +"
                    r"± ([-+.e0-9]+) │", text)
    assert row is not None, text
    # the rate's spread is its 95 % interval (Student's t on the fit's residual), the loss
    # factor's 1.96 std: not the 1 sigma the table gave
    half = m0["ci95"]["rates"][0][1] - m0["rates"][0]
    assert float(row.group(2)) == pytest.approx(half, rel=0.03)
    assert half > 1.96 * m0["std"]["rates"][0]
    assert float(row.group(4)) == pytest.approx(1.96 * m0["std"]["loss_factors"][0], rel=0.03)


@pytest.mark.slow
def test_one_hit_a_point_is_not_a_coherence_check_in_any_view(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    six_point_plans(monkeypatch)  # the demo's plan (one hit a point) on six points
    monkeypatch.setenv("COLUMNS", "200")  # the tables' rows unwrapped, whatever the host
    run, out, html = tmp_path / "run.h5", tmp_path / "r.json", tmp_path / "r.html"
    assert main(["demo", "--bench", "engine-rigid", "--length", "0.5", "--out",
                 str(run)]) == 0
    capsys.readouterr()
    assert main(["replay", str(run), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert re.search(r"│ coherence +│ not checked +│ one hit a point: the coherence is 1 by "
                     r"definition", text), text
    assert not re.search(r"│ coherence +│ pass", text)
    coh = json.loads(out.read_text())["checks"]["coherence"]
    assert coh["pass"] is None and coh["checked"] is False
    assert coh["not_checked"] == "one hit a point: the coherence is 1 by definition"
    assert main(["report", str(run), "--out", str(html)]) == 0
    page = html.read_text()
    assert ('<td class="na">not checked</td><td class="l">one hit a point: the coherence is 1 '
            "by definition") in page
    assert np.isfinite(json.loads(out.read_text())["mass"])
