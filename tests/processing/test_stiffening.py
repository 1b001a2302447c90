"""Mounts that stiffen with frequency: K(f) read from the stiffness lines, carried into the
mass line. Truth from the independent reference model (``hardware_mocks/reference``);
seeds of these tests only (the benchmark's suites are 4242 and 5151)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from hardware_mocks.reference.metrics import errors
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from processing.data import FRFSet, Geometry
from processing.identify import identify
from processing.problem import IdentifyOptions
from processing.stiffness import Stiffening, choose_stiffening


def _frfs(sc) -> FRFSet:
    ids, xyz = sc.geometry()
    return FRFSet(sc.freq, sc.H, sc.sensors.ids, sc.sensors.reported_dirs, sc.forces.ids,
                  sc.forces.reported_dirs, Geometry(ids, xyz), sc.coherence)


def _errors(sc, res) -> dict[str, float]:
    K = res.K if res.stiffening is None else res.K * (
        sc.truth.stiffness_hz / res.stiffening.reference_hz) ** res.stiffening.alpha
    p = res.properties
    return errors(sc.truth, p.mass, p.cog, p.inertia_origin, p.inertia_cog, K)


@pytest.mark.parametrize("shape", ["engine", "gearbox"])
def test_stiffening_mounts_are_read_and_carried_into_the_mass_line(shape: str) -> None:
    """Noise-free, stiff body, mounts +25 % a decade: the rise is read within 4 points (the
    model's rates stop falling below f_k / 100, which the lowest lines reach), and the
    inertia is several times closer than with a constant K."""
    sc = build_scenario(ScenarioSpec(seed=8101, shape=shape, n_forces=18, elastic_ratio=None,
                                     stiffening=0.25))
    auto = identify(_frfs(sc))
    const = identify(_frfs(sc), IdentifyOptions(stiffening="constant"))
    assert auto.stiffening is not None, auto.stiffening_note
    assert auto.stiffening.per_decade == pytest.approx(0.25, abs=0.04)
    assert "stiffness rising" in auto.stiffening_note
    assert const.stiffening is None and "asked for" in const.stiffening_note
    e, e0 = _errors(sc, auto), _errors(sc, const)
    assert e["mass"] < 0.3 and e["cog"] < 0.3 and e["inertia"] < 0.5 and e["stiffness"] < 0.6
    assert e0["mass"] > 3 * e["mass"] and e0["inertia"] > 3 * e["inertia"]
    js = auto.to_json()["stiffening"]
    assert js["per_decade"] == pytest.approx(auto.stiffening.per_decade)
    assert js["stiffness_at_hz"] == pytest.approx(auto.stiffening.reference_hz)


@pytest.mark.parametrize("seed", [8102, 8103, 8104])
def test_constant_mounts_keep_a_constant_k(seed: int) -> None:
    """Constant mounts with noise, a flexible body and test errors: no stiffening is taken,
    and the result is the constant-K fit's exactly."""
    sc = build_scenario(ScenarioSpec(seed=seed, shape="engine", n_forces=18, noise=0.01,
                                     elastic_ratio=8.0, location_error=0.002,
                                     misalignment_deg=1.0))
    auto = identify(_frfs(sc))
    const = identify(_frfs(sc), IdentifyOptions(stiffening="constant"))
    assert auto.stiffening is None, auto.stiffening_note
    assert auto.stiffening_note.startswith("stiffness constant over frequency")
    assert_allclose(auto.theta, const.theta, rtol=0, atol=0)


def test_choose_stiffening_on_equations_written_here() -> None:
    """Per-line equations ``(g(w) K + j w C) x = w^2 (M x - t)`` built here from a 6-DOF
    model with K rising 20 % a decade: the search finds alpha to 1e-4, and a constant K
    is kept on the same model without the rise."""
    rng = np.random.default_rng(8105)
    A = rng.normal(size=(6, 6))
    M = A @ A.T + 6 * np.eye(6)
    B = rng.normal(size=(6, 6))
    K = (B @ B.T + 6 * np.eye(6)) * 400.0
    C = 0.02 * K / (2 * np.pi * 5)
    T = rng.normal(size=(6, 12))
    w = 2 * np.pi * np.geomspace(0.5, 20.0, 60)
    alpha = np.log10(1.2)
    for a, want in ((alpha, True), (0.0, False)):
        g = (w / (2 * np.pi * 3.0)) ** a
        Z = (g[:, None, None] * K[None] + 1j * w[:, None, None] * C[None]
             - (w**2)[:, None, None] * M[None])
        X = np.moveaxis(-(w**2)[:, None, None] * np.linalg.solve(Z, np.broadcast_to(
            T, (w.size, 6, 12))), 0, -1)
        ch = choose_stiffening(X, T, w, M)
        assert (ch.stiffening is not None) == want, ch.reason
        if want:
            assert isinstance(ch.stiffening, Stiffening)
            assert ch.stiffening.alpha == pytest.approx(alpha, abs=1e-4)
            assert ch.stiffening.per_decade == pytest.approx(0.2, abs=3e-4)


def test_the_command_line_reads_or_keeps_the_stiffening(tmp_path) -> None:
    """``insitu identify`` reads the stiffening by default and states it in the result JSON;
    ``--stiffening constant`` keeps K constant."""
    from app.cli.main import main
    from app.io.uff import write_frf_uff

    sc = build_scenario(ScenarioSpec(seed=8106, shape="engine", n_forces=12, elastic_ratio=None,
                                     stiffening=0.3, n_lines=800))
    path = tmp_path / "frf.uff"
    write_frf_uff(path, _frfs(sc), binary=True)
    out = {}
    for name, extra in (("auto", []), ("constant", ["--stiffening", "constant"])):
        js = tmp_path / f"{name}.json"
        assert main(["identify", str(path), *extra, "--no-uncertainty", "--out", str(js)]) == 0
        out[name] = json.loads(js.read_text())
    assert out["auto"]["stiffening"]["per_decade"] == pytest.approx(0.3, abs=0.05)
    assert out["auto"]["stiffening_choice"].startswith("stiffness rising")
    assert out["constant"]["stiffening"] is None
    assert out["constant"]["stiffening_choice"].endswith("asked for")
