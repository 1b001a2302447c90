"""Uncertainty of an identification against the independent reference model's truth.

The truth (mass, CoG, tensors, K at O) comes from ``hardware_mocks.reference`` alone (point
masses and springs), never from ``processing``. The bodies are stiff (no elastic mode in
the band: the method's own domain), measured with noise, location and misalignment errors.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario
from processing import identify as idm
from processing.data import FRFSet, Geometry
from processing.montecarlo import StatedUncertainty, simulate
from processing.problem import IdentifyOptions, prepare
from processing.results import UNCERTAIN_KEYS
from processing.uncertainty import (
    block_covariance,
    drift_factor,
    flexibility_bias,
    force_noise_ratio,
    series_softening,
)


def _frfset(sc: Scenario) -> FRFSet:
    ids, xyz = sc.geometry()
    return FRFSet(freq=sc.freq, H=sc.H, resp_nodes=sc.sensors.ids,
                  resp_dirs=sc.sensors.reported_dirs, exc_nodes=sc.forces.ids,
                  exc_dirs=sc.forces.reported_dirs, geometry=Geometry(ids, xyz),
                  coherence=sc.coherence)


def _spec(seed: int, shape: str, noise: float = 0.01, location: float = 0.002,
          misalignment: float = 1.0) -> ScenarioSpec:
    return ScenarioSpec(seed=seed, shape=shape, n_sensors=4, n_forces=12, noise=noise,
                        location_error=location, misalignment_deg=misalignment,
                        elastic_ratio=None)


def _ratios(sc: Scenario, r: idm.IdentificationResult) -> np.ndarray:
    """|error| / std of mass, CoG, the tensor about the CoG (6 entries) and K (21)."""
    u, p, tr = r.uncertainty, r.properties, sc.truth
    assert u is not None
    i3, i6 = np.triu_indices(3), np.triu_indices(6)
    return np.concatenate([
        [abs(p.mass - tr.mass) / u.std["mass"]],
        np.abs(p.cog - tr.cog) / u.std["cog"],
        (np.abs(p.inertia_cog - tr.inertia_cog) / u.std["inertia_cog"])[i3],
        (np.abs(r.K - tr.K) / u.std["stiffness"])[i6],
    ])


def test_intervals_cover_the_truth_on_stiff_bodies() -> None:
    """Five scenarios with 1 % noise, +-2 mm locations, 1 deg misalignment; the stated
    uncertainties are those levels as standard deviations. Measured: 155 of 155 entries within
    1.96 std, median |error|/std 0.41 (0.28 before the stiffness scatter was weighted like
    the fit; a normal error gives 0.67)."""
    z = []
    for seed, shape in [(21, "block"), (22, "engine"), (23, "gearbox"), (24, "block"),
                        (25, "engine")]:
        sc = build_scenario(_spec(seed, shape))
        stated = StatedUncertainty(location=0.002 / np.sqrt(3), angle=np.deg2rad(1.0) / 3,
                                   draws=300)
        r = idm.identify(_frfset(sc), IdentifyOptions(stated=stated))
        z.append(_ratios(sc, r))
    zz = np.concatenate(z)
    assert 0.8 <= np.mean(zz < 1.96) <= 1.0, np.round(np.sort(zz), 2)
    assert 0.2 < np.median(zz) < 1.3, np.round(np.sort(zz), 2)


def _noise_only(noise: float) -> tuple[Scenario, idm.IdentificationResult]:
    sc = build_scenario(_spec(21, "block", noise=noise, location=0.0, misalignment=0.0))
    r = idm.identify(_frfset(sc))
    assert r.uncertainty is not None
    return sc, r


def test_std_shrinks_with_the_noise() -> None:
    """The covariance part alone (no geometry error, none stated): 4x less noise gives a
    clearly smaller std (median over each key's entries)."""
    stds = {noise: _noise_only(noise)[1].uncertainty.std  # type: ignore[union-attr]
            for noise in (0.02, 0.005)}
    ratios = {key: float(np.median(stds[0.005][key] / stds[0.02][key]))
              for key in ("mass", "cog", "inertia_cog", "stiffness")}
    # measured: mass 0.50 (the H1 bias and the residual's floor do not scale with the noise)
    assert max(ratios.values()) < 0.65, ratios


def test_noise_only_interval_holds_the_truth() -> None:
    """Noise only (no geometry error): the mass error is the H1 bias of the noisy force
    (errors in variables, about noise^2); the coherence bound of the force noise puts it
    inside the interval without making it wide (measured |error|/std 0.49 at 2 %, 0.56 at
    0.5 %; without the term the std was 7x under the error)."""
    for noise in (0.02, 0.005):
        sc, r = _noise_only(noise)
        err = abs(r.properties.mass - sc.truth.mass)
        std = r.uncertainty.std["mass"]  # type: ignore[union-attr]
        assert err <= 1.96 * std <= 8 * err, (noise, err, std)


def test_force_noise_ratio_bounds_the_reference_force_noise() -> None:
    """The reference measurement adds force noise of power noise^2 of the force's
    (hardware_mocks/reference/measurement.py); the bound from the best-coherent response of
    each run lies above it and within 3x (measured 1.86-1.91x at 0.5-2 %)."""
    for noise, seed, shape in ((0.02, 21, "block"), (0.005, 22, "engine")):
        sc = build_scenario(_spec(seed, shape, noise=noise, location=0.0, misalignment=0.0))
        frf = _frfset(sc)
        pb = prepare(frf.freq, frf.H, frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
                     coherence=frf.coherence, options=IdentifyOptions(), exponential_tau=None)
        weights = idm.weigh_lines(pb, idm.choose_bands(pb))
        assert pb.coherence is not None
        a = force_noise_ratio(pb.coherence[..., weights.mass_lines], weights.mass)
        assert noise**2 <= a <= 3 * noise**2, (noise, a / noise**2)


def test_drift_factor_recovers_a_residual_growing_like_w2() -> None:
    """A quantity measured on lines with a residual ``v w^2`` (modes above the band): the
    weighted least-squares estimate over a band is biased by ``v <w^2>``; the factor times
    the difference between the upper and lower halves' estimates gives that bias."""
    rng = np.random.default_rng(3)
    w = np.sort(2 * np.pi * rng.uniform(20.0, 45.0, 301))
    wt = rng.uniform(0.2, 1.0, w.size)
    m, v = 3.0, 2e-6
    y = m + v * w**2

    def est(sl: slice) -> float:
        return float(np.average(y[sl], weights=wt[sl]))

    h = w.size // 2
    d = est(slice(h, None)) - est(slice(0, h))
    np.testing.assert_allclose(drift_factor(w, wt) * d, est(slice(None)) - m, rtol=1e-10)
    assert drift_factor(w[:1], wt[:1]) == 0.5  # no halves: the two-block jackknife


def test_flexibility_bias_recovers_a_series_flexibility() -> None:
    """Stiffness lines of a rigid body on mounts K with a flexibility R in series
    (``K* = ((K - w^2 M)^-1 + R)^-1 + w^2 M``, exact, written here): the fitted bias of a
    constant K over the lines matches ``<D R D>`` to first order in R (|R K| ~ 1 %)."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(6, 6))
    M = A @ A.T + 6 * np.eye(6)
    B = rng.normal(size=(6, 6))
    K = 1e4 * (B @ B.T + 6 * np.eye(6))
    R = rng.normal(size=(6, 6))
    R = 0.5 * (R + R.T) * 1e-2 / np.linalg.norm(K, 2)
    w = np.linspace(0.5, 1.5, 400) * np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(M, K)).real))
    Dj = K[None] - w[:, None, None] ** 2 * M[None]
    Ks = np.linalg.inv(np.linalg.inv(Dj) + R[None]) + w[:, None, None] ** 2 * M[None]
    got = flexibility_bias(Ks + 0j, w, M, K)
    want = np.mean(Dj @ R @ Dj, axis=0)
    np.testing.assert_allclose(got, want, atol=0.05 * np.abs(want).max())


def test_flexibility_bias_drops_a_flexibility_fitted_to_noise() -> None:
    """Stiffness lines of a rigid body (no flexibility) with white noise on each K*_j: the
    fitted R stands no higher than its own noise, and the James-Stein factor drops or
    shrinks it (measured: zero in 7 of 20 draws, median largest entry 0.015 of the lines'
    noise)."""
    rng = np.random.default_rng(8)
    A = rng.normal(size=(6, 6))
    M = A @ A.T + 6 * np.eye(6)
    B = rng.normal(size=(6, 6))
    K = 1e4 * (B @ B.T + 6 * np.eye(6))
    w = np.linspace(0.5, 1.5, 300) * np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(M, K)).real))
    sigma = 1e-3 * np.abs(K).max()
    sizes = []
    for _ in range(20):
        E = rng.normal(size=(w.size, 6, 6)) * sigma
        Ks = K[None] + 0.5 * (E + np.swapaxes(E, 1, 2)) + 0j
        sizes.append(np.abs(flexibility_bias(Ks, w, M, K)).max())
    assert np.mean(np.array(sizes) == 0) >= 0.3, sizes
    assert np.median(sizes) < 0.05 * sigma, sizes


def test_series_softening_matches_a_flexible_mount_stack() -> None:
    """One DOF at a time: a mount k in series with a body flexibility 1 / (m w_e^2) has the
    stiffness (1/k + 1/(m w_e^2))^-1; the term is its first-order change k^2 / (m w_e^2)."""
    M, K = np.diag([2.0, 3.0, 4.0, 0.5, 0.6, 0.7]), np.diag([4e4, 5e4, 6e4, 1e3, 2e3, 3e3])
    fe = 150.0
    we2 = (2 * np.pi * fe) ** 2
    exact = K.diagonal() - 1 / (1 / K.diagonal() + 1 / (M.diagonal() * we2))
    C = np.diag([40.0, 50.0, 60.0, 1.0, 2.0, 3.0])
    dK, dC = series_softening(M, K, fe, C)
    np.testing.assert_allclose(dK.diagonal(), exact, rtol=0.05)
    z = K.diagonal() + 1j * C.diagonal()  # at w = 1 rad/s: Im Z = C
    exact_c = (z - 1 / (1 / z + 1 / (M.diagonal() * we2))).imag
    np.testing.assert_allclose(dC.diagonal(), exact_c, rtol=0.1)


def test_result_json_and_switch() -> None:
    sc = build_scenario(_spec(22, "engine"))
    frf = _frfset(sc)
    r = idm.identify(frf)
    out = r.to_json()
    assert set(out["std"]) >= set(UNCERTAIN_KEYS) - {"rigid_modes_hz"}
    assert np.shape(out["std"]["inertia_cog"]) == (3, 3)
    assert np.all(np.asarray(out["std"]["stiffness"]) > 0)
    assert "fit covariance" in out["uncertainty"]["sources"][0]
    assert idm.identify(frf, IdentifyOptions(uncertainty=False)).uncertainty is None


@pytest.mark.parametrize("tau", [None, 0.5])
def test_draws_match_a_full_refit(tau: float | None) -> None:
    """A draw of the fast path (moments, fixed lines and model) equals identifying again
    with that draw's geometry and gains and the same bands and lines, where its algebra is
    exact: equal weights on the channels (no coherence) and viscous mounts. With coherence
    weights or structural damping it is the first-order spread of that estimator (measured
    on this scenario with its coherence and hysteretic mounts: theta off by as much as the
    draw moves it; docs/uncertainty.md). With an exponential window (``tau``, s) the fast
    path leaves the window's decay out: the draw still follows the windowed re-fit, to
    first order in 1 / (tau w)."""
    sc = build_scenario(dataclasses.replace(_spec(23, "gearbox"), damping="viscous"))
    frf = dataclasses.replace(_frfset(sc), coherence=None)
    opt = IdentifyOptions(uncertainty=False, damping="viscous")
    args = (frf.freq, frf.H, frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs)
    pb = prepare(*args, coherence=frf.coherence, options=opt, exponential_tau=tau)
    bands = idm.choose_bands(pb)
    weights = idm.weigh_lines(pb, bands)
    fitted = idm.solve(pb, bands, weights)
    model = idm.monte_carlo_model(pb, weights, fitted, (frf.resp_nodes, frf.exc_nodes))
    stated = StatedUncertainty(location=0.003, angle=0.02, gain=0.02, draws=2, seed=4)
    d = simulate(model, stated)
    n_p, n_r = len(model.point_names), model.resp_xyz.shape[0]
    x = d.z[0]
    dP = x[:3 * n_p].reshape(n_p, 3)
    tilt = x[3 * n_p:3 * n_p + 2 * n_r].reshape(n_r, 2)
    g_r, g_e = x[3 * n_p + 2 * n_r:3 * n_p + 3 * n_r], x[3 * n_p + 3 * n_r:]
    d0 = model.resp_dirs
    helper = np.where(np.abs(d0[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    u1 = np.cross(d0, helper)
    u1 /= np.linalg.norm(u1, axis=1, keepdims=True)
    u2 = np.cross(d0, u1)
    dirs = d0 + tilt[:, :1] * u1 + tilt[:, 1:] * u2
    H = frf.H * (1 + g_e)[None, :, None] / (1 + g_r)[:, None, None]
    pb2 = prepare(frf.freq, H, frf.resp_xyz + dP[model.resp_point], dirs,
                  frf.exc_xyz + dP[model.exc_point], frf.exc_dirs, coherence=frf.coherence,
                  options=opt, exponential_tau=tau)
    full = idm.solve(pb2, bands, weights)
    scale = abs(fitted.theta[0])
    moved = np.abs(full.theta - fitted.theta) / scale
    miss = np.abs(d.theta[0] - full.theta) / scale
    # the draw moves theta by up to a few % of m; the fast path is within 2 % of that move
    # (measured: within 1.1e-5 of m; the leakage cleaning of the stiffness lines is linearised;
    # 0.10 % of the move without a window, 0.14 % with tau = 0.5 s)
    assert np.max(moved) > 1e-3
    assert np.max(miss) < 0.02 * np.max(moved), (miss, moved)
    dK_full = np.abs(full.K - fitted.K).max()
    assert np.abs(d.K[0] - full.K).max() < 0.02 * dK_full


def test_draws_split_over_seeds_are_the_same_draws() -> None:
    sc = build_scenario(_spec(24, "block"))
    frf = _frfset(sc)
    opt = IdentifyOptions(uncertainty=False)
    pb = prepare(frf.freq, frf.H, frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
                 coherence=frf.coherence, options=opt, exponential_tau=None)
    bands = idm.choose_bands(pb)
    weights = idm.weigh_lines(pb, bands)
    model = idm.monte_carlo_model(pb, weights, idm.solve(pb, bands, weights))
    stated = StatedUncertainty(location=0.002, draws=6)
    whole = simulate(model, stated, seeds=list(range(6)))
    parts = [simulate(model, stated, seeds=s) for s in ([0, 1, 2], [3, 4, 5])]
    np.testing.assert_allclose(np.concatenate([p.theta for p in parts]), whole.theta,
                               rtol=1e-12)


def test_block_covariance_of_white_terms_is_their_variance() -> None:
    rng = np.random.default_rng(3)
    sums = []
    covs = []
    for _ in range(400):
        t = rng.normal(size=(1, 320))
        sums.append(t.sum())
        covs.append(block_covariance(t, 16)[0, 0])
    # the sum of 320 unit-variance terms has variance 320
    assert np.var(sums) == pytest.approx(320, rel=0.2)
    assert np.mean(covs) == pytest.approx(320, rel=0.1)


@pytest.mark.parametrize(("field", "value"), [("location", -1e-3), ("angle", float("nan")),
                                              ("draws", 1)])
def test_stated_uncertainty_refuses_bad_values(field: str, value: float) -> None:
    bad: dict[str, Any] = {field: value}
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(StatedUncertainty(), **bad)
