"""A fast subset of the reference scenario suite (``benchmarks/accuracy.py`` runs all of it).

Each scenario goes through a binary UFF file and ``insitu identify`` exactly as a user runs
it; the truth and the article's baseline come from ``hardware_mocks.reference`` alone.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff import write_frf_uff
from hardware_mocks.reference.article import article_identify, identify_scenario
from hardware_mocks.reference.metrics import errors
from hardware_mocks.reference.scenarios import Scenario, build_scenario, suite
from processing.data import FRFSet, Geometry

SPECS = suite(40)


def _uff(sc: Scenario, tmp_path: Path) -> Path:
    ids, xyz = sc.geometry()
    frf = FRFSet(freq=sc.freq, H=sc.H, resp_nodes=sc.sensors.ids,
                 resp_dirs=sc.sensors.reported_dirs, exc_nodes=sc.forces.ids,
                 exc_dirs=sc.forces.reported_dirs, geometry=Geometry(ids, xyz),
                 coherence=sc.coherence)
    path = tmp_path / f"{sc.spec.name}.uff"
    write_frf_uff(path, frf, binary=True)
    return path


def _insitu(path: Path, *extra: str) -> dict[str, Any] | None:
    """``insitu identify PATH [EXTRA] --out JSON``: the result, or None when it refuses."""
    out = path.with_suffix(f".{'-'.join(extra) or 'default'}.json")
    code = main(["identify", str(path), *extra, "--out", str(out)])
    return json.loads(out.read_text()) if code == 0 else None


def _errors(sc: Scenario, r: dict[str, Any]) -> dict[str, float]:
    return errors(sc.truth, r["mass"], r["cog"], r["inertia_origin"], r["inertia_cog"],
                  r["stiffness"])


@pytest.mark.parametrize("index", [0, 10, 20])  # block, engine, gearbox: stiff, error-free
def test_rigid_clean_scenarios_are_exact(index: int, tmp_path: Path) -> None:
    sc = build_scenario(SPECS[index])
    assert "rigid-clean" in sc.spec.tags
    path = _uff(sc, tmp_path)
    for extra in ((), ("--method", "plain")):
        r = _insitu(path, *extra)
        assert r is not None, extra
        e = _errors(sc, r)
        assert max(e["mass"], e["inertia"], e["stiffness"]) < 1e-3, (extra, e)  # %
        assert e["cog"] < 1e-3, (extra, e)  # mm
    a = identify_scenario(sc)
    assert a.converged
    e = errors(sc.truth, a.mass, a.cog, a.inertia_origin, a.inertia_cog, a.K)
    assert max(e.values()) < 1e-6, e


def test_article_leakage_grows_with_its_mass_line() -> None:
    """A noise-free gearbox whose first elastic mode is 20x its highest rigid mode: the
    article's method (independent of processing/) errs more the closer its mass line
    reaches the elastic mode, as the elastic modes' residual grows like (f / f_e)^2."""
    sc = build_scenario(SPECS[5])
    assert sc.spec.is_clean and sc.spec.elastic_ratio == 20.0
    nat = sc.natural_frequencies_hz
    s, f = sc.sensors, sc.forces
    errs = []
    for top in (0.2, 0.4, 0.8):
        a = article_identify(sc.freq, sc.H, s.reported_xyz, s.reported_dirs, f.reported_xyz,
                             f.reported_dirs, (2 * nat[5], top * nat[6]),
                             (sc.freq[0], 1.2 * nat[5]))
        errs.append(errors(sc.truth, a.mass, a.cog, a.inertia_origin, a.inertia_cog, a.K))
    assert errs[0]["mass"] < 0.2 and errs[0]["cog"] < 10.0  # %, mm (measured 0.087, 6.6)
    for key in ("cog", "inertia", "stiffness"):
        assert errs[0][key] < errs[1][key] < errs[2][key], key
    # the article's own rule (mass line to 0.8 f_e) is the last of these
    rule = identify_scenario(sc)
    assert rule.mass_band[1] == pytest.approx(min(0.8 * nat[6], sc.freq[-1]))


@pytest.mark.parametrize("index", [6, 19])  # refused before the band fallbacks (issue 12)
def test_default_answers_where_the_article_answers(index: int, tmp_path: Path) -> None:
    sc = build_scenario(SPECS[index])
    identify_scenario(sc)  # answers (raises ArticleRefusalError otherwise)
    assert _insitu(_uff(sc, tmp_path)) is not None


def test_default_not_worse_than_the_article_on_a_clean_flexible_engine(tmp_path: Path) -> None:
    sc = build_scenario(SPECS[25])
    assert sc.spec.is_clean and sc.spec.shape == "engine"
    a = identify_scenario(sc)
    art = errors(sc.truth, a.mass, a.cog, a.inertia_origin, a.inertia_cog, a.K)
    r = _insitu(_uff(sc, tmp_path))
    assert r is not None
    e = _errors(sc, r)
    assert all(e[k] <= art[k] for k in art), (e, art)
    assert np.isfinite(list(e.values())).all()


def test_mass_line_ends_where_the_estimate_is_stable(tmp_path: Path) -> None:
    """An engine whose first elastic mode (80.8 Hz) the residual does not show at 0.9 %
    noise: the automatic mass line to the end of the data erred 5.5 % in mass and 23 % in
    K (worse than the article's method given the true modes); ended where the two halves
    of the band agree, it beats the article in every metric."""
    sc = build_scenario(SPECS[28])
    assert 0.5 < sc.spec.noise * 100 < 1.5 and 70 < sc.first_elastic_hz < 90
    a = identify_scenario(sc)
    art = errors(sc.truth, a.mass, a.cog, a.inertia_origin, a.inertia_cog, a.K)
    r = _insitu(_uff(sc, tmp_path))
    assert r is not None
    assert r["bands"]["mass_line"][1] < 0.7 * sc.first_elastic_hz
    # ended where the halves agree, or (since the rigid band passes over the noisy lowest
    # lines) already at the rigidity check's limit, under the mode
    assert ("where the estimate is stable" in r["band_choice"]
            or "rigidity check's limit" in r["band_choice"]), r["band_choice"]
    e = _errors(sc, r)
    assert all(e[k] <= art[k] for k in art), (e, art)
    assert e["mass"] < 1.0 and e["stiffness"] < 10.0, e  # % (measured 0.04, 5.4)
