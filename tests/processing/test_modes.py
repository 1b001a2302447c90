"""Rigid-body modes, energy decoupling, torque roll axis, elastic axis and isolation against
truths built from point masses and springs (``mount_truth.py``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg
from mount_truth import (
    ETA_HZ,
    Spring,
    Truth,
    cuboid_points,
    engine_on_four_mounts,
    point_map,
    rotation,
)
from numpy.testing import assert_allclose

from hardware_mocks.benches import get_bench
from processing.identify import identify
from processing.modes import isolation, rigid_body_modes, torque_roll_axis


def truth_modes(t: Truth) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies (Hz), mass-normalised shapes, damping ratios and kinetic-energy fractions
    at the CoG, straight from scipy.linalg.eigh and the point masses."""
    w2, V = scipy.linalg.eigh(t.K, t.M)
    w = np.sqrt(w2)
    zeta = np.einsum("ir,ij,jr->r", V, t.C, V) / (2 * w)
    MG = t.M_about(t.cog)
    P = point_map(t.cog)  # displacement of the CoG for each q at O
    Psi = np.vstack([P @ V, V[3:]])
    E = Psi * (MG @ Psi)
    return w / (2 * np.pi), V, zeta, E / E.sum(axis=0)


def aligned(V: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """V's columns with the signs of ref's."""
    return V * np.sign(np.sum(V * ref, axis=0))


def test_modes_equal_the_truths() -> None:
    t = engine_on_four_mounts()
    f, V, zeta, E = truth_modes(t)
    m = rigid_body_modes(t.M, t.K, t.C)
    assert_allclose(m.frequency_hz, f, rtol=1e-9)
    assert_allclose(aligned(m.shapes, V), V, atol=1e-9 * np.abs(V).max())
    assert_allclose(m.damping_ratio, zeta, rtol=1e-9)
    assert_allclose(m.energy, E, atol=1e-9)
    assert_allclose(m.energy.sum(axis=0), 1.0, rtol=1e-12)
    assert_allclose(m.shapes.T @ t.M @ m.shapes, np.eye(6), atol=1e-9)
    assert m.warnings == ()
    js = m.to_json()
    assert len(js) == 6 and set(js[0]) >= {"frequency_hz", "damping_ratio", "shape", "energy"}
    assert_allclose([d["frequency_hz"] for d in js], f, rtol=1e-9)


def test_decoupled_body_has_pure_modes() -> None:
    """A body with diagonal inertia about its CoG, O at the CoG, springs symmetric about
    it: every mode is 100 % one DOF."""
    pts = cuboid_points((0.4, 0.3, 0.2), (-0.2, -0.15, -0.1), n=2)
    springs = tuple(
        Spring(f"m{i}", np.array([sx * 0.25, sy * 0.2, sz * 0.1]), np.eye(3),
               np.array([1e5, 2e5, 3e5]), np.array([10.0, 20, 30]))
        for i, (sx, sy, sz) in enumerate(
            ((1, 1, 1), (-1, 1, -1), (1, -1, -1), (-1, -1, 1))))
    t = Truth(np.full(len(pts), 10.0), pts, springs)
    m = rigid_body_modes(t.M, t.K, t.C)
    assert_allclose(np.sort(m.energy.max(axis=0)), 1.0, atol=1e-9)
    assert sorted(m.dominant()) == sorted(["x", "y", "z", "rx", "ry", "rz"])


def test_modes_of_the_identified_model_match_the_true_ones() -> None:
    """Noise-free FRFs of the simulated engine -> identify -> modes within 0.1 % of the
    modes of the bench's own M and K (frequencies, shapes, energy fractions)."""
    bench = get_bench("engine-rigid")
    r = identify(bench.frfset())
    m = rigid_body_modes(r.M, r.K, r.C)
    Mt, Kt = bench.model.M, bench.model.K
    w2, V = scipy.linalg.eigh(Kt, Mt)
    assert_allclose(m.frequency_hz, np.sqrt(w2) / (2 * np.pi), rtol=1e-3)
    assert_allclose(aligned(m.shapes, V), V, atol=1e-3 * np.abs(V).max())
    truth = rigid_body_modes(Mt, Kt, bench.model.C)
    assert_allclose(m.energy, truth.energy, atol=1e-3)
    assert_allclose(m.damping_ratio, truth.damping_ratio, rtol=1e-3)
    js = r.to_json()["modes"]  # every result JSON carries the modes
    assert_allclose([d["frequency_hz"] for d in js], m.frequency_hz, rtol=1e-12)


def test_torque_roll_axis_of_a_principal_crank_axis_is_that_axis_through_the_cog() -> None:
    pts = cuboid_points((0.5, 0.3, 0.2), (0.1, -0.2, 0.05), n=3)
    t = Truth(np.full(len(pts), 4.0), pts, ())
    tra = torque_roll_axis(t.M, None, [2.0, 0.0, 0.0])
    assert_allclose(tra.direction, [1.0, 0.0, 0.0], atol=1e-12)
    assert_allclose(tra.point, t.cog, atol=1e-12)
    assert tra.angle_to_crank_deg < 1e-6
    assert tra.elastic_axis is None


def test_torque_roll_axis_of_an_unbalanced_body() -> None:
    """The free body's angular acceleration under a torque t about the CoG: J_G alpha = t."""
    t = engine_on_four_mounts()
    crank = np.array([1.0, 0.2, 0.0])
    tra = torque_roll_axis(t.M, t.K, crank)
    alpha = np.linalg.solve(t.inertia_cog, crank)
    assert_allclose(tra.direction, alpha / np.linalg.norm(alpha), atol=1e-12)
    assert_allclose(tra.point, t.cog, atol=1e-12)
    assert tra.angle_to_crank_deg > 1.0  # the lump and the mounts' tilt turn it away
    js = tra.to_json()
    assert set(js) >= {"direction", "point"}
    assert js["elastic_axis"] is not None


def test_elastic_axis_of_symmetric_mounts() -> None:
    """Four equal mounts at (+-a, +-b, 0), global axes: a torque about x turns the body
    about the x axis through (0, 0, 0) without translation (pitch 0); the CoG at
    (0.05, 0.02, 0.2) is sqrt(0.02^2 + 0.2^2) from it."""
    springs = tuple(Spring(f"m{i}", np.array([sx * 0.3, sy * 0.2, 0.0]), np.eye(3),
                           np.array([1e5, 1.5e5, 4e5]), np.zeros(3))
                    for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))))
    pts = cuboid_points((0.4, 0.3, 0.2), (-0.15, -0.13, 0.1), n=2)
    t = Truth(np.full(len(pts), 5.0), pts, springs)
    assert_allclose(t.cog, [0.05, 0.02, 0.2], atol=1e-12)
    tra = torque_roll_axis(t.M, t.K, [1.0, 0.0, 0.0])
    ea = tra.elastic_axis
    assert ea is not None
    assert_allclose(ea.direction, [1.0, 0.0, 0.0], atol=1e-12)
    assert_allclose(ea.point, [0.05, 0.0, 0.0], atol=1e-12)
    assert abs(ea.pitch) < 1e-12
    assert_allclose(tra.distance_m, np.hypot(0.02, 0.2), rtol=1e-9)
    assert tra.angle_deg < 1e-6


def test_no_elastic_axis_when_k_is_singular() -> None:
    t = engine_on_four_mounts()
    K = np.diag([1e5, 1e5, 1e5, 0.0, 1e4, 1e4])
    tra = torque_roll_axis(t.M, K, [1, 0, 0])
    assert tra.elastic_axis is None and "singular" in tra.note
    assert tra.to_json()["elastic_axis"] is None


def test_isolation_margin() -> None:
    M = np.diag([10.0, 10, 10, 1, 1, 1])
    K = np.diag([1e4, 4e4, 9e4, 1e3, 2e3, 3e3])
    C = 0.01 * K
    m = rigid_body_modes(M, K, C)
    iso = isolation(m, 12.0)
    assert_allclose(iso.ratio, 12.0 / m.frequency_hz, rtol=1e-12)
    assert_allclose(iso.margin, iso.ratio / np.sqrt(2), rtol=1e-12)
    r, z = iso.ratio, m.damping_ratio
    tr = np.sqrt((1 + (2 * z * r) ** 2) / ((1 - r**2) ** 2 + (2 * z * r) ** 2))
    assert_allclose(iso.transmissibility, tr, rtol=1e-12)
    assert_allclose(iso.isolated, m.frequency_hz < 12.0 / np.sqrt(2))
    js = m.to_json(iso)
    assert_allclose([d["isolation_margin"] for d in js], iso.margin)
    with pytest.raises(ValueError, match="> 0 Hz"):
        isolation(m, 0.0)


def test_bad_matrices() -> None:
    with pytest.raises(ValueError, match="6x6"):
        rigid_body_modes(np.eye(5), np.eye(6))
    with pytest.raises(ValueError, match="positive definite"):
        rigid_body_modes(-np.eye(6), np.eye(6))
    m = rigid_body_modes(np.eye(6), np.diag([-1.0, 1, 1, 1, 1, 1]))
    assert m.frequency_hz[0] == 0.0 and "not positive definite" in m.warnings[0]
    js = m.to_json(isolation(m, 5.0))  # a 0 Hz mode: no finite ratio, null in JSON
    assert js[0]["isolation_margin"] is None and js[1]["isolation_margin"] is not None
    json.dumps(js, allow_nan=False)
    with pytest.raises(ValueError, match="crank axis"):
        torque_roll_axis(np.eye(6), None, [0, 0, 0])


def test_rotation_helper_is_a_rotation() -> None:
    R = rotation("y", 30.0) @ rotation("z", -20.0)
    assert_allclose(R @ R.T, np.eye(3), atol=1e-12)


def test_damping_ratios_with_structural_damping() -> None:
    """``zeta_r = phi_r^T D phi_r / (2 w_r^2)``: half the loss factor of the complex
    eigenvalues of ``(K + j D, M)`` (exact for D proportional to K; within 1 % for the
    four mounts' D, measured 0.45 %, coupling 0.22)."""
    t = engine_on_four_mounts()
    m = rigid_body_modes(t.M, t.K, None, 0.1 * t.K)
    assert_allclose(m.damping_ratio, 0.05, rtol=1e-10)
    D = 2 * np.pi * ETA_HZ * t.C  # the springs' eta k: structural instead of viscous
    lam = scipy.linalg.eigvals(t.K + 1j * D, t.M)
    lam = lam[np.argsort(lam.real)]
    m = rigid_body_modes(t.M, t.K, None, D)
    assert_allclose(2 * m.damping_ratio, lam.imag / lam.real, rtol=0.01)
    both = rigid_body_modes(t.M, t.K, t.C, D)  # viscous and structural parts add
    alone = rigid_body_modes(t.M, t.K, t.C)
    assert_allclose(both.damping_ratio, alone.damping_ratio + m.damping_ratio, rtol=1e-12)
