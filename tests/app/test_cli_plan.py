"""``insitu plan``: the plan it writes loads with load_plan (its [prediction] kept), and bad
input is one line with exit status 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.acquire.plan import load_plan, parse_plan, plan_differences
from app.cli.main import main
from tests.app.cli_lines import one_error_line

MODEL = """
[model]
mass = 110.0
cog = [0.0, 0.2, 0.15]
box = [0.5, 0.4, 0.35]
first_elastic_hz = 300.0
""" + "".join(f"""
[[mount]]
position = {p}
rates = [1.5e5, 1.5e5, 4e5]
""" for p in ([-0.2, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.45, 0.0]))


def _candidates(n: int = 12, seed: int = 3) -> str:
    rng = np.random.default_rng(seed)
    c, h = np.array([0, 0.2, 0.15]), np.array([0.25, 0.2, 0.175])
    out = ['[plan]', 'name = "planned"', 'hits = 4', '', '[record]', 'fs = 1024.0',
           'length = 1.0', '']
    for i in range(n):
        p = rng.uniform(-1, 1, 3)
        k = int(rng.integers(3))
        p[k] = np.sign(p[k])
        x = (c + p * h).round(3).tolist()
        d = [0, 0, 0]
        d[k] = -int(np.sign(p[k]))
        d2 = [0, 0, 0]
        d2[(k + 1) % 3] = 1
        out += ['[[sensor]]', f'node = {i + 1}', f'xyz = {x}', '', '[[point]]',
                f'node = {101 + i}', f'xyz = {x}', f'directions = [{d}, {d2}]', '']
    return "\n".join(out)


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    (tmp_path / "model.toml").write_text(MODEL)
    (tmp_path / "cand.toml").write_text(_candidates())
    return tmp_path / "model.toml", tmp_path / "cand.toml"


def test_plan_round_trip(files: tuple[Path, Path], tmp_path: Path,
                         capsys: pytest.CaptureFixture[str]) -> None:
    model, cand = files
    out = tmp_path / "plan.toml"
    code = main(["plan", "--model", str(model), "--candidates", str(cand), "--sensors", "3",
                 "--points", "7", "--noise", "1%", "--location-uncertainty", "1mm",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    plan = load_plan(out)
    assert plan.name == "planned" and plan.hits == 4 and plan.record.length == 1.0
    assert len(plan.responses) == 3 and len(plan.excitations) == 7
    assert plan.responses[0].channels == ("a1x", "a1y", "a1z")
    pred = plan.prediction
    assert pred is not None and pred["mass"] > 0 and len(pred["cog"]) == 3
    assert np.shape(pred["inertia_cog"]) == (3, 3)
    # the prediction is kept by to_dict and does not count as a difference of acquisition
    again = parse_plan(plan.to_dict(), "again")
    assert again.prediction == pred
    bare = parse_plan({k: v for k, v in plan.to_dict().items() if k != "prediction"}, "bare")
    assert plan_differences(plan, bare, "a", "b") == []
    printed = capsys.readouterr().out
    assert "predicted standard deviation" in printed and "cond(T)" in printed


@pytest.mark.parametrize(("edit", "words"), [
    (lambda m, c: (m.replace("mass = 110.0", "mass = 110.0\ncolour = 1"), c), "model.colour"),
    (lambda m, c: (m, c.replace("[[sensor]]\nnode = 2", "[[sensor]]\nnode = 2\nweight = 1", 1)),
     "unknown key"),
    (lambda m, c: (m, c.replace("directions = ", "directions_ = ", 1)), "unknown key"),
    (lambda m, c: (m.replace("box = [0.5, 0.4, 0.35]", ""), c), "inertia_cog or box"),
])
def test_bad_files_are_one_line(files: tuple[Path, Path], tmp_path: Path,
                                capsys: pytest.CaptureFixture[str], edit, words: str) -> None:
    model, cand = files
    m, c = edit(model.read_text(), cand.read_text())
    model.write_text(m)
    cand.write_text(c)
    code = main(["plan", "--model", str(model), "--candidates", str(cand), "--sensors", "3",
                 "--points", "7", "--out", str(tmp_path / "plan.toml")])
    assert code == 2
    assert words in one_error_line(capsys)


def test_too_few_candidates_and_rank_deficient_sets(files: tuple[Path, Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    model, cand = files
    out = str(tmp_path / "plan.toml")
    assert main(["plan", "--model", str(model), "--candidates", str(cand), "--sensors", "20",
                 "--points", "7", "--out", out]) == 2
    assert "only 12 candidate sensor" in one_error_line(capsys)
    flat = "\n".join(line if not line.startswith("directions") else
                     "directions = [[0, 0, 1]]" for line in cand.read_text().splitlines())
    cand.write_text(flat)
    assert main(["plan", "--model", str(model), "--candidates", str(cand), "--sensors", "3",
                 "--points", "7", "--out", out]) == 2
    assert "rank" in one_error_line(capsys)
    assert main(["plan", "--model", str(model), "--candidates", str(cand), "--sensors", "2",
                 "--points", "7", "--out", out]) == 2
    assert "--sensors" in one_error_line(capsys)
