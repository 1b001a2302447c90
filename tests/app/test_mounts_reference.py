"""Mount rates, modes and decoupling against the independent reference model (issue 16).

The body is the reference model's lattice on its own inclined mounts; its FRFs go through a
UFF file and ``insitu identify --mounts`` as a user runs it. The truth (each mount's rates,
M and K at O) comes from ``hardware_mocks.reference`` alone, and the modes and the energy
decoupling of that truth are computed here with scipy, not with ``processing``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.linalg

from app.cli.main import main
from app.io.uff import write_frf_uff
from hardware_mocks.reference.mounts import mounts_toml
from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario
from processing.data import FRFSet, Geometry
from processing.modes import rigid_body_modes


def _identify(sc: Scenario, tmp_path: Path, mounts: str,
              extra: tuple[str, ...] = ()) -> tuple[int, dict[str, Any] | None]:
    ids, xyz = sc.geometry()
    frf = FRFSet(freq=sc.freq, H=sc.H, resp_nodes=sc.sensors.ids,
                 resp_dirs=sc.sensors.reported_dirs, exc_nodes=sc.forces.ids,
                 exc_dirs=sc.forces.reported_dirs, geometry=Geometry(ids, xyz),
                 coherence=sc.coherence)
    uff, toml, out = tmp_path / "t.uff", tmp_path / "mounts.toml", tmp_path / "r.json"
    write_frf_uff(uff, frf, binary=True)
    toml.write_text(mounts)
    code = main(["identify", str(uff), "--mounts", str(toml), "--out", str(out), *extra])
    return code, json.loads(out.read_text()) if code == 0 else None


def _rates(sc: Scenario) -> np.ndarray:
    return np.array([m.rates for m in sc.mounts])


def _stiff(seed: int, shape: str, noise: float = 0.0, damping: str = "viscous") -> Scenario:
    return build_scenario(ScenarioSpec(seed=seed, shape=shape, n_sensors=4, n_forces=12,
                                       n_mounts=4, noise=noise, elastic_ratio=None,
                                       damping=damping))  # type: ignore[arg-type]


@pytest.mark.parametrize(("seed", "shape"), [(1, "block"), (2, "engine"), (3, "gearbox")])
@pytest.mark.parametrize("damping", ["viscous", "hysteretic"])
def test_rates_and_loss_factors_noise_free(seed: int, shape: str, damping: str,
                                           tmp_path: Path) -> None:
    """Viscous mounts (K + jwC) and hysteretic ones (rubber, K + jD): the identification
    chooses the damping model from the stiffness lines, then the rates come to 0.1 %
    (measured: 1.7e-12 at most) and the loss factors too (measured 1.4e-12): hysteretic
    ones as d / k, viscous ones as 2 pi f c / k at the model's reference 10 Hz."""
    sc = _stiff(seed, shape, damping=damping)
    code, r = _identify(sc, tmp_path, mounts_toml(sc.mounts), ("--loss-factor-hz", "10"))
    assert code == 0 and r is not None
    assert r["damping_model"] == damping and r["damping_choice"].startswith("damping ")
    got = np.array([m["rates"] for m in r["mounts"]])
    ok = np.array([m["identifiable"] for m in r["mounts"]])
    true = _rates(sc)
    assert ok.all()  # four turned mounts: every rate determined
    np.testing.assert_allclose(got, true, rtol=1e-3)
    eta = np.array([m["loss_factors"] for m in r["mounts"]], dtype=float)
    np.testing.assert_allclose(eta, [m.loss_factors for m in sc.mounts], rtol=1e-3)
    D = np.array(r["structural_damping"])
    if damping == "hysteretic":  # D is the mounts' K_loss; no viscous part
        np.testing.assert_allclose(D, sc.truth.K_loss, atol=1e-6 * np.abs(sc.truth.K).max())
        assert not np.any(r["damping"])
    else:
        assert not np.any(D)


def test_modes_and_decoupling_of_the_true_system() -> None:
    sc = _stiff(4, "engine")
    t = sc.truth
    M, K = np.asarray(t.M), np.asarray(t.K).real
    ours = rigid_body_modes(M, K)
    w2, phi = scipy.linalg.eigh(K, M)  # the reference, computed here
    f = np.sqrt(np.maximum(w2, 0)) / (2 * np.pi)
    np.testing.assert_allclose(ours.frequency_hz, f, rtol=1e-3)
    np.testing.assert_allclose(f, np.sort(sc.rigid_modes_hz), rtol=1e-3)
    for k in range(6):
        a, b = ours.shapes[:, k], phi[:, k]  # columns, at O
        cos = abs(a @ M @ b) / np.sqrt((a @ M @ a) * (b @ M @ b))
        assert cos > 1 - 1e-3, (k, cos)
    # kinetic-energy decoupling at the CoG, written out: psi = [v_G; rot] = S q,
    # M_G = diag(m, m, m, J_G); fraction of dof j in mode k: psi_j (M_G psi)_j / psi' M_G psi
    c = np.asarray(t.cog)
    S = np.eye(6)
    S[:3, 3:] = -np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
    MG = np.zeros((6, 6))
    MG[:3, :3] = t.mass * np.eye(3)
    MG[3:, 3:] = np.asarray(t.inertia_cog)
    for k in range(6):
        psi = S @ phi[:, k]
        e = psi * (MG @ psi) / (psi @ MG @ psi)
        np.testing.assert_allclose(ours.energy[:, k], e, atol=1e-3)


@pytest.fixture(scope="module")
def rate_z(tmp_path_factory: pytest.TempPathFactory) -> np.ndarray:
    """|error| / std of every identifiable rate over six scenarios at 1.5 % noise (identified
    once for the two tests below)."""
    tmp_path = tmp_path_factory.mktemp("rates")
    z: list[float] = []
    for seed in range(6):
        sc = _stiff(10 + seed, ("block", "engine", "gearbox")[seed % 3], noise=0.015)
        code, r = _identify(sc, tmp_path, mounts_toml(sc.mounts))
        assert code == 0 and r is not None
        got = np.array([m["rates"] for m in r["mounts"]])
        std = np.array([m["std"]["rates"] for m in r["mounts"]])
        ok = np.array([m["identifiable"] for m in r["mounts"]])
        z += list((np.abs(got - _rates(sc)) / std)[ok])
    return np.array(z)


def test_rates_at_noise_within_their_stated_uncertainty(rate_z: np.ndarray) -> None:
    zs = rate_z
    # the rates' std carry K's covariance from the identification (processing.uncertainty):
    # measured 72 of 72 rates within 1.96 std, largest 1.78 std, median 0.44 before the
    # coherence weights and the damping model choice; with them the largest was 0.57 std,
    # 0.87 since the stiffness scatter is weighted like the fit
    # (from the rate fit's residual alone it was 72 % within 1.96 std)
    assert np.mean(zs < 1.96) >= 0.93, np.round(np.sort(zs), 2)
    assert np.max(zs) < 2.5, np.round(np.sort(zs), 2)


@pytest.mark.xfail(strict=True, reason="the rates' median |error|/std is 0.23 (largest 0.87; "
                   "0.011 before the stiffness scatter was weighted like the fit; a calibrated "
                   "std gives 0.67): still about 3x too wide here (issue 15)")
def test_rates_std_not_inflated(rate_z: np.ndarray) -> None:
    zs = rate_z
    assert 0.25 < np.median(zs) < 0.9, np.round(np.sort(zs), 2)  # a normal error: 0.67


def test_undetermined_geometry_flagged_and_refused(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    sc = _stiff(5, "block")
    # the same body, with a mounts file that puts three mounts on one line along x: their
    # x rates are seen only as a sum, the six others are determined
    text = "crank_axis = [1.0, 0.0, 0.0]\n" + "".join(
        f'[[mount]]\nname = "m{i}"\nposition = [{x}, 0.05, -0.1]\n'
        "axes = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n"
        for i, x in enumerate((-0.2, 0.0, 0.2)))
    code, r = _identify(sc, tmp_path, text)
    assert code == 0 and r is not None
    flags = np.array([m["identifiable"] for m in r["mounts"]])
    assert not flags[:, 0].any() and flags[:, 1:].all()
    # eight mounts, 24 rates for 21 entries of K: nothing determined, one line, exit 2
    many = mounts_toml(tuple(sc.mounts) * 2)
    code, _ = _identify(sc, tmp_path, many)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "mount" in err[0]


def test_hysteretic_rates_and_loss_factors_at_noise(tmp_path: Path) -> None:
    """Rubber mounts at 1.5 % FRF noise, the six scenarios of the viscous test above: the
    structural model is chosen every time, rates within 1 % (measured 0.23 % at most,
    median 0.04 %; with the viscous model alone it was 7.5 % and 0.95 %) and loss factors
    within 0.01 (measured 0.0025)."""
    for seed in range(6):
        sc = _stiff(10 + seed, ("block", "engine", "gearbox")[seed % 3], noise=0.015,
                    damping="hysteretic")
        code, r = _identify(sc, tmp_path, mounts_toml(sc.mounts))
        assert code == 0 and r is not None
        assert r["damping_model"] == "hysteretic", r["damping_choice"]
        got = np.array([m["rates"] for m in r["mounts"]])
        np.testing.assert_allclose(got, _rates(sc), rtol=0.01)
        eta = np.array([m["loss_factors"] for m in r["mounts"]], dtype=float)
        np.testing.assert_allclose(eta, [m.loss_factors for m in sc.mounts], atol=0.01)
