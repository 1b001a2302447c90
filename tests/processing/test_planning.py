"""Test planning (processing/planning.py): the search beats a bad layout on its criterion,
refuses rank-deficient candidates, keeps to the allowed directions, and its prediction is
within a stated factor of a small Monte Carlo on the independent reference model."""

from __future__ import annotations

import numpy as np
import pytest

from hardware_mocks.reference.measurement import force_channels, h1_with_noise, sensor_channels
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from processing.data import FRFSet, Geometry
from processing.identify import IdentifyOptions, fit
from processing.measurement import Measurement
from processing.montecarlo import StatedUncertainty
from processing.planning import (
    ApproximateModel,
    Candidates,
    PlanningError,
    TestConditions,
    box_inertia,
    fisher_blocks,
    layout_value,
    mount_stiffness,
    plan_test,
    search,
)


def _model(first_elastic: float | None = None) -> ApproximateModel:
    K, D = np.zeros((6, 6)), np.zeros((6, 6))
    for p in ([-0.2, -0.15, -0.1], [-0.2, 0.15, -0.1], [0.2, -0.15, -0.1], [0.2, 0.15, -0.1]):
        k, d = mount_stiffness(p, np.eye(3), [1e5, 1e5, 3e5], [0.1] * 3)
        K, D = K + k, D + d
    return ApproximateModel(100.0, np.array([0.01, 0.0, 0.05]), box_inertia(100.0, [0.5, 0.4, 0.3]),
                            K, D, first_elastic_hz=first_elastic)


def _candidates(seed: int = 11, n: int = 16) -> Candidates:
    rng = np.random.default_rng(seed)
    half = np.array([0.25, 0.2, 0.15])

    def surface(count: int) -> tuple[np.ndarray, np.ndarray]:
        p = rng.uniform(-1, 1, (count, 3))
        ax = rng.integers(0, 3, count)
        p[np.arange(count), ax] = np.sign(p[np.arange(count), ax])
        return p * half, ax

    sx, _ = surface(n)
    px, ax = surface(n)
    ep, ed = [], []
    for i in range(n):
        d = np.zeros(3)
        d[ax[i]] = -np.sign(px[i, ax[i]])  # into the body, from its face
        ep.append(i)
        ed.append(d)
        d2 = np.zeros(3)
        d2[(ax[i] + 1) % 3] = 1.0
        ep.append(i)
        ed.append(d2)
    return Candidates(np.arange(1, n + 1), sx, np.arange(101, 101 + n), px, np.array(ep),
                      np.array(ed))


COND = TestConditions(np.arange(1, 401) * 0.5, noise=0.01, averages=5,
                      stated=StatedUncertainty(location=0.001, draws=200), realisations=1)


def test_the_search_beats_a_bad_layout_on_its_criterion() -> None:
    model, cand = _model(), _candidates()
    info = fisher_blocks(model, cand, COND)
    lay = search(info, cand, 3, 6, "D")
    # a poor layout: the three sensors nearest each other, excitations at one point mostly
    d = np.linalg.norm(cand.sensor_xyz - cand.sensor_xyz[0], axis=1)
    close = list(np.argsort(d)[:3])
    rng = np.random.default_rng(0)
    worse = [layout_value(info, close, list(rng.choice(cand.exc_dirs.shape[0], 6, replace=False)),
                          "D") for _ in range(20)]
    assert lay.value < min(worse)
    assert len(set(lay.sensors)) == 3 and len(set(lay.excitations)) == 6
    a = search(info, cand, 3, 6, "A")
    assert layout_value(info, a.sensors, a.excitations, "A") == pytest.approx(a.value, rel=1e-3)


def test_rank_deficient_candidates_are_refused() -> None:
    model, cand = _model(), _candidates()
    # every excitation along z: T has rank 3 whatever the points
    flat = Candidates(cand.sensor_nodes, cand.sensor_xyz, cand.point_nodes, cand.point_xyz,
                      np.arange(cand.point_nodes.size),
                      np.tile([0.0, 0.0, 1.0], (cand.point_nodes.size, 1)))
    with pytest.raises(PlanningError, match="rank"):
        plan_test(model, flat, 3, 6, COND, predicted=False)
    # sensors on one line: E has rank 5
    line = Candidates(cand.sensor_nodes, np.outer(np.linspace(-0.2, 0.2, 16), [1.0, 0, 0]),
                      cand.point_nodes, cand.point_xyz, cand.exc_point, cand.exc_dirs)
    with pytest.raises(PlanningError, match="one line"):
        plan_test(model, line, 3, 6, COND, predicted=False)
    with pytest.raises(PlanningError, match="candidate"):
        plan_test(model, cand, 3, 60, COND, predicted=False)


def test_chosen_directions_are_allowed_ones_and_the_layout_has_rank_6() -> None:
    cand = _candidates(seed=5)
    design = plan_test(_model(), cand, 4, 8, COND)
    P = list(design.layout.excitations)
    for i in P:  # an allowed (point, direction) pair of the candidates
        assert any(np.allclose(cand.exc_dirs[i], cand.exc_dirs[j]) and
                   cand.exc_point[i] == cand.exc_point[j] for j in range(cand.exc_dirs.shape[0]))
    assert design.prediction is not None and design.prediction.geometry.ok
    assert design.prediction.geometry.rank_T == 6 and design.prediction.geometry.rank_E == 6


def test_prediction_within_a_factor_of_a_reference_monte_carlo() -> None:
    """A stiff reference body with noise and location errors; the planner gets the truth
    perturbed by a few %; 8 Monte Carlo draws of the chosen layout on the reference model.
    The predicted std of mass, CoG and the moments is within 0.3-3x the draws' spread
    (median over each group: 8 draws leave the spread itself 25 % uncertain)."""
    spec = ScenarioSpec(seed=9071, shape="engine", noise=0.01, n_averages=10,
                        location_error=0.002, elastic_ratio=None, n_lines=800)
    sc = build_scenario(spec)
    body, t = sc.system.body, sc.truth
    rng = np.random.default_rng(9071)
    surf = np.flatnonzero(body.surface)
    s_nodes = rng.choice(surf, 14, replace=False)
    p_nodes = rng.choice(surf, 14, replace=False)
    axes = np.vstack([np.eye(3), -np.eye(3)])
    ep = np.repeat(np.arange(14), 3)
    ed = axes[rng.integers(0, 6, ep.size)]
    cand = Candidates(np.arange(1, 15), body.xyz[s_nodes], np.arange(101, 115),
                      body.xyz[p_nodes], ep, ed)
    K = np.zeros((6, 6))
    D = np.zeros((6, 6))
    for m in sc.mounts:
        k, d = mount_stiffness(m.position, m.axes, m.rates * 1.1, m.loss_factors)
        K, D = K + k, D + d
    model = ApproximateModel(t.mass * 1.05, t.cog + 0.01, t.inertia_cog * 0.9, K, D)
    cond = TestConditions(sc.freq, noise=spec.noise, averages=spec.n_averages,
                          stated=StatedUncertainty(location=0.002 / np.sqrt(3), draws=300),
                          realisations=1)
    design = plan_test(model, cand, 4, 8, cond)
    pred = design.prediction
    assert pred is not None
    S, P = list(design.layout.sensors), list(design.layout.excitations)
    est = []
    for _ in range(8):
        sens = sensor_channels(body.xyz, s_nodes[S], rng, location_error=0.002)
        forces = force_channels(body.xyz, p_nodes[ep[P]], ed[P], rng, location_error=0.002)
        H = sc.system.accelerance(sc.freq, sens.nodes, sens.vectors, forces.nodes,
                                  forces.vectors)
        H1, coh = h1_with_noise(H, spec.noise, spec.n_averages, rng)
        ids = np.concatenate([sens.ids, forces.ids])
        pts = np.concatenate([sens.reported_xyz, forces.reported_xyz])
        uniq, first = np.unique(ids, return_index=True)
        frf = FRFSet(sc.freq, H1, sens.ids, sens.reported_dirs, forces.ids,
                     forces.reported_dirs, Geometry(uniq, pts[first]), coherence=coh)
        p = fit(Measurement(frf), IdentifyOptions(uncertainty=False)).properties
        est.append([p.mass, *p.cog, *np.diag(p.inertia_cog)])
    spread = np.std(est, axis=0, ddof=1)
    predicted = np.array([pred.std["mass"], *pred.std["cog"], *np.diag(pred.std["inertia_cog"])])
    ratio = predicted / spread
    for name, idx in (("mass", [0]), ("cog", [1, 2, 3]), ("moments", [4, 5, 6])):
        assert 0.3 < np.median(ratio[idx]) < 3.0, (name, ratio)
