"""The independent reference model against closed forms (no processing/ code in any truth)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from numpy.testing import assert_allclose

from hardware_mocks.reference.body import SHAPES, make_body
from hardware_mocks.reference.kinematics import (
    inertia_tensor,
    mass_matrix_6,
    rigid_map,
    rotation,
    theta_from_masses,
)
from hardware_mocks.reference.measurement import h1_with_noise, sensor_channels
from hardware_mocks.reference.mounts import Mount, mounts_toml
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.system import ReferenceSystem


def _midpoint_cuboid(a: float, b: float, c: float, n: int, mass: float):
    """n^3 equal point masses at the cell centres of an a x b x c cuboid centred at 0."""
    g = [(np.arange(n) + 0.5) / n * L - L / 2 for L in (a, b, c)]
    x, y, z = np.meshgrid(*g, indexing="ij")
    pts = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    return np.full(n**3, mass / n**3), pts


def test_uniform_cuboid_inertia():
    a, b, c, m, n = 0.5, 0.3, 0.2, 160.0, 40
    masses, pts = _midpoint_cuboid(a, b, c, n, m)
    J = inertia_tensor(masses, pts)
    # midpoint sums: mean of x^2 over the cell centres is a^2 (1 - 1/n^2) / 12, exactly
    s = [L**2 * (1 - 1 / n**2) / 12 for L in (a, b, c)]
    assert_allclose(np.diag(J), m * np.array([s[1] + s[2], s[0] + s[2], s[0] + s[1]]),
                    rtol=1e-12)
    # the continuum cuboid, m (b^2 + c^2) / 12 etc., within the 1/n^2 discretisation
    assert_allclose(np.diag(J), m / 12 * np.array([b**2 + c**2, a**2 + c**2, a**2 + b**2]),
                    rtol=1.001 / n**2)
    assert_allclose(J - np.diag(np.diag(J)), 0.0, atol=1e-12)


def test_parallel_axis_and_product_sign():
    rng = np.random.default_rng(0)
    masses, pts = rng.uniform(0.5, 2.0, 30), rng.normal(size=(30, 3)) * 0.2 + [0.3, -0.1, 0.2]
    m = masses.sum()
    cog = masses @ pts / m
    J_o, J_g = inertia_tensor(masses, pts), inertia_tensor(masses, pts, cog)
    assert_allclose(J_o, J_g + m * (cog @ cog * np.eye(3) - np.outer(cog, cog)), rtol=1e-12)
    # two masses on the x = y diagonal: product Jxy = sum m x y = 2 > 0, tensor entry -2
    J = inertia_tensor([1.0, 1.0], [[1.0, 1.0, 0.0], [-1.0, -1.0, 0.0]])
    assert J[0, 1] == pytest.approx(-2.0) and J[1, 0] == pytest.approx(-2.0)
    theta = theta_from_masses([1.0, 1.0], [[1.0, 1.0, 0.0], [-1.0, -1.0, 0.0]])
    assert_allclose(theta, [2, 0, 0, 0, 2, 2, 4, 2, 0, 0], atol=1e-15)


def test_mass_matrix_is_the_articles_eq2():
    rng = np.random.default_rng(1)
    masses, pts = rng.uniform(0.5, 2.0, 20), rng.normal(size=(20, 3)) * 0.3 + 0.1
    m, mx, my, mz, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz = theta_from_masses(masses, pts)
    eq2 = np.array([
        [m, 0, 0, 0, mz, -my],
        [0, m, 0, -mz, 0, mx],
        [0, 0, m, my, -mx, 0],
        [0, -mz, my, Jxx, -Jxy, -Jxz],
        [mz, 0, -mx, -Jxy, Jyy, -Jyz],
        [-my, mx, 0, -Jxz, -Jyz, Jzz],
    ])
    assert_allclose(mass_matrix_6(masses, pts), eq2, rtol=1e-12, atol=1e-14)


def test_one_inclined_spring_at_origin():
    """Rate k along n = (sin b, 0, cos b) at p = (a, 0, 0): a rotation ry = t moves p by
    (0, 0, -a t), so the spring stretches by n . (u - a ry z^) and K = k g g^T with
    g = [sin b, 0, cos b, 0, -a cos b, 0]."""
    a, beta, k = 0.25, np.deg2rad(30.0), 2.0e5
    n = np.array([np.sin(beta), 0.0, np.cos(beta)])
    u = np.cross([0.0, 1.0, 0.0], n)  # any two axes completing n to a right-handed set
    v = np.cross(n, u)
    mount = Mount(0, [a, 0.0, 0.0], np.vstack([u, v, n]), [0.0, 0.0, k], [0.0, 0.0, 0.1])
    g = np.array([np.sin(beta), 0.0, np.cos(beta), 0.0, -a * np.cos(beta), 0.0])
    K = mount.stiffness_at_origin()
    assert_allclose(K.real, k * np.outer(g, g), rtol=1e-12, atol=1e-9)
    assert_allclose(K.imag, 0.1 * k * np.outer(g, g), rtol=1e-12, atol=1e-9)


def test_mounts_file_text_round_trips(engine):
    parsed = tomllib.loads(mounts_toml(engine.mounts, crank_axis=(0.0, 1.0, 0.0)))
    assert parsed["crank_axis"] == [0.0, 1.0, 0.0]
    assert len(parsed["mount"]) == len(engine.mounts) == 3
    for m, entry in zip(engine.mounts, parsed["mount"], strict=True):
        assert np.array_equal(entry["position"], m.position)
        assert np.array_equal(entry["axes"], m.axes)


def test_rotation_is_proper_and_small_angle():
    R = rotation([0.0, 0.0, np.pi / 2])
    assert_allclose(R @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(R @ R.T, np.eye(3), atol=1e-15)


@pytest.mark.parametrize("shape", SHAPES)
def test_free_lattice_has_exactly_six_rigid_modes(shape):
    f = make_body(shape, np.random.default_rng(3)).free_modes_hz(8)
    assert np.all(f[:6] < 1e-6 * f[6]) and f[6] > 0


@pytest.fixture(scope="module")
def engine():
    sc = build_scenario(ScenarioSpec(seed=7, shape="engine", n_mounts=3, n_sensors=4,
                                     n_forces=8, elastic_ratio=6.0, n_lines=400))
    return sc


def test_modal_frfs_equal_the_direct_solve(engine):
    sys, s, f = engine.system, engine.sensors, engine.forces
    lines = engine.freq[::37]
    H = sys.accelerance(lines, s.nodes, s.vectors, f.nodes, f.vectors)
    Hd = sys.accelerance_direct(lines, s.nodes, s.vectors, f.nodes, f.vectors)
    assert_allclose(H, Hd, rtol=1e-8, atol=1e-10 * np.abs(Hd).max())


def test_viscous_modal_frfs_equal_the_direct_solve(engine):
    sys = ReferenceSystem(engine.system.body, engine.mounts, damping="viscous", reference_hz=12.0)
    s, f = engine.sensors, engine.forces
    lines = engine.freq[::37]
    H = sys.accelerance(lines, s.nodes, s.vectors, f.nodes, f.vectors)
    Hd = sys.accelerance_direct(lines, s.nodes, s.vectors, f.nodes, f.vectors)
    assert_allclose(H, Hd, rtol=1e-8, atol=1e-10 * np.abs(Hd).max())
    # the truth's viscous C: each mount's eta k / w_ref along its axes, at O
    assert_allclose(sys.truth.K_loss, 0.0)
    assert_allclose(sys.truth.C * 2 * np.pi * 12.0, engine.truth.K_loss, rtol=1e-12,
                    atol=1e-12 * np.abs(engine.truth.K_loss).max())
    assert_allclose(sys.natural_frequencies_hz()[:6], engine.natural_frequencies_hz[:6],
                    rtol=0.05)


def test_truth_symmetry_and_positivity(engine):
    t = engine.truth
    for A in (t.M, t.K, t.K_loss, t.inertia_cog, t.inertia_origin):
        assert_allclose(A, A.T, rtol=0, atol=1e-12 * np.abs(A).max())
    assert np.linalg.eigvalsh(t.M).min() > 0
    assert np.linalg.eigvalsh(t.K).min() > 0  # 3 inclined mounts restrain all six DOFs
    assert np.linalg.eigvalsh(t.K_loss).min() > 0
    J = t.principal_moments
    assert J.min() > 0 and J[0] + J[1] >= J[2]
    assert t.mass == pytest.approx(engine.system.body.masses.sum(), rel=1e-14)
    f, shapes = t.rigid_modes()
    assert_allclose(shapes.T @ t.M @ shapes, np.eye(6), atol=1e-10)
    assert_allclose(shapes.T @ t.K @ shapes, np.diag((2 * np.pi * f) ** 2), rtol=1e-9,
                    atol=1e-9 * (2 * np.pi * f[-1]) ** 2)


def test_rigid_system_is_the_truths_rigid_frf(engine):
    rigid = ReferenceSystem(engine.system.body, engine.mounts, rigid=True)
    s, f, b = engine.sensors, engine.forces, engine.system.body
    H = rigid.accelerance(engine.freq, s.nodes, s.vectors, f.nodes, f.vectors)
    # above the mounts the accelerance tends to the mass line: E M^-1 T, from G maps by hand
    Gs = np.array([np.hstack([np.eye(3), -np.cross(np.eye(3), r)]) for r in b.xyz[s.nodes]])
    rows = np.einsum("ni,nij->nj", s.vectors, Gs)
    Gf = np.array([np.hstack([np.eye(3), -np.cross(np.eye(3), r)]) for r in b.xyz[f.nodes]])
    cols = np.einsum("nji,nj->in", Gf, f.vectors)
    mass_line = rows @ np.linalg.solve(engine.truth.M, cols)
    w_hi, f_r = engine.freq[-1], engine.rigid_modes_hz[-1]
    assert_allclose(H[..., -1], mass_line, atol=3 * (f_r / w_hi) ** 2 * np.abs(mass_line).max())


@pytest.mark.parametrize("shape", SHAPES)
def test_lattice_converges_to_the_rigid_body_below_its_first_mode(shape):
    """Below the first elastic mode the elastic modes add ~(f / f_e)^2 of the mass line, so
    the difference to the rigid truth falls as 1 / stiffness."""
    sc = build_scenario(ScenarioSpec(seed=11, shape=shape, n_mounts=4, n_sensors=4,
                                     n_forces=8, elastic_ratio=20.0, n_lines=400))
    s, f = sc.sensors, sc.forces
    lines = sc.freq[sc.freq <= 3 * sc.rigid_modes_hz[-1]]
    b = sc.system.body
    H_rigid = sc.truth.accelerance(lines, b.xyz[s.nodes], s.vectors, b.xyz[f.nodes], f.vectors)
    diffs = []
    for scale in (1.0, 16.0):
        sys = sc.system if scale == 1.0 else ReferenceSystem(b.scaled(scale), sc.mounts)
        H = sys.accelerance(lines, s.nodes, s.vectors, f.nodes, f.vectors)
        ratio = (3 * sc.rigid_modes_hz[-1] / sys.first_elastic_hz()) ** 2
        d = np.abs(H - H_rigid).max() / np.abs(H_rigid).max()
        assert d < 3 * ratio, (scale, d, ratio)
        diffs.append(d)
    assert 8.0 < diffs[0] / diffs[1] < 32.0  # ~16: the leakage goes as 1 / stiffness


def test_sensor_errors_are_bounded():
    rng = np.random.default_rng(5)
    xyz = rng.normal(size=(10, 3))
    ch = sensor_channels(xyz, np.array([1, 4, 7]), rng, location_error=0.003,
                         misalignment_deg=2.0, gain_error=0.02, transverse=0.03)
    assert np.all(np.abs(ch.reported_xyz - xyz[ch.nodes]) <= 0.003)
    gains = np.linalg.norm(ch.vectors, axis=1)
    assert np.all(np.abs(gains - 1) <= 0.02 * np.hypot(1, 0.03) + 0.03**2)
    angle = np.degrees(np.arccos(np.sum(ch.vectors * ch.reported_dirs, 1) / gains))
    assert np.all(angle <= 2.0 + np.degrees(np.arctan(0.03)) + 1e-9)
    assert angle.max() > 0.1


def test_h1_noise_free_is_exact_and_noise_scales():
    rng = np.random.default_rng(6)
    H = rng.normal(size=(3, 2, 500)) + 1j * rng.normal(size=(3, 2, 500))
    H0, coh0 = h1_with_noise(H, 0.0, 10, rng)
    assert_allclose(H0, H, rtol=0) and np.all(coh0 == 1)
    H1, coh = h1_with_noise(H, 0.02, 20, rng)
    rel = np.abs(H1 - H) / np.sqrt(np.mean(np.abs(H) ** 2, axis=2, keepdims=True))
    # response noise 2 % of RMS over 20 averages of unit-variance force: ~0.02 / sqrt(20)
    assert 0.002 < np.median(rel) < 0.008
    assert np.all(coh <= 1 + 1e-12) and np.median(coh) > 0.99


@pytest.mark.parametrize("damping", ["hysteretic", "viscous"])
def test_stiffening_mounts_frfs_equal_the_direct_solve(engine, damping):
    """Mounts 25 % stiffer a decade: the Woodbury update of the modal FRFs equals a dense
    solve with each line's mount stiffness, and differs from the constant mounts' FRFs."""
    sys = ReferenceSystem(engine.system.body, engine.mounts, damping=damping,
                          stiffening=0.25, stiffness_hz=7.0)
    s, f = engine.sensors, engine.forces
    lines = np.concatenate([[0.0], engine.freq[::37]])  # 0 Hz: no accelerance
    H = sys.accelerance(lines, s.nodes, s.vectors, f.nodes, f.vectors)
    Hd = sys.accelerance_direct(lines[1:], s.nodes, s.vectors, f.nodes, f.vectors)
    assert_allclose(H[..., 0], 0.0)
    assert_allclose(H[..., 1:], Hd, rtol=1e-8, atol=1e-10 * np.abs(Hd).max())
    constant = ReferenceSystem(engine.system.body, engine.mounts, damping=damping)
    H0 = constant.accelerance(lines[1:], s.nodes, s.vectors, f.nodes, f.vectors)
    assert np.abs(H[..., 1:] - H0).max() > 0.01 * np.abs(H0).max()


def test_stiffening_truth_holds_at_its_frequency(engine):
    """The truth's K is the mounts' at ``stiffness_hz`` and rises 25 % a decade; the rigid
    system's FRFs use each line's K (a dense 6-DOF solve per line, written here)."""
    rigid = ReferenceSystem(engine.system.body, engine.mounts, rigid=True,
                            stiffening=0.25, stiffness_hz=7.0)
    t = rigid.truth
    assert_allclose(t.K, engine.truth.K, rtol=1e-14)
    assert_allclose(t.stiffness_at([7.0, 70.0, 0.7]),
                    [t.K, 1.25 * t.K, t.K / 1.25], rtol=1e-12)
    assert_allclose(t.stiffness_at([0.0, 0.01]), [t.K / 1.25**2] * 2, rtol=1e-12)  # plateau
    s, f, b = engine.sensors, engine.forces, engine.system.body
    freq = engine.freq[::53]
    H = rigid.accelerance(freq, s.nodes, s.vectors, f.nodes, f.vectors)
    R = np.einsum("ni,nij->nj", s.vectors, rigid_map(b.xyz[s.nodes]))
    T = np.einsum("nji,nj->in", rigid_map(b.xyz[f.nodes]), f.vectors)
    for k, fk in enumerate(freq):
        w = 2 * np.pi * fk
        g = (fk / 7.0) ** np.log10(1.25)
        Z = g * (t.K + 1j * t.K_loss) - w**2 * t.M
        assert_allclose(H[..., k], -(w**2) * R @ np.linalg.solve(Z, T), rtol=1e-9)


def test_stiffening_scenario_states_its_frequency():
    """A scenario's stiffening mounts hold their rates at the geometric mean of the rigid-body
    modes those rates give; without stiffening the FRFs are the constant mounts' exactly."""
    spec = ScenarioSpec(seed=31, shape="engine", n_lines=200, stiffening=0.3)
    sc, sc0 = build_scenario(spec), build_scenario(ScenarioSpec(seed=31, shape="engine",
                                                                n_lines=200))
    f0 = sc0.truth.rigid_modes()[0]
    assert sc.truth.stiffness_hz == pytest.approx(float(np.exp(np.mean(np.log(f0)))),
                                                  rel=1e-12)
    assert sc.truth.stiffening == 0.3 and sc0.truth.stiffening == 0.0
    assert_allclose(sc.truth.K, sc0.truth.K, rtol=1e-14)
    assert not np.allclose(sc.H_exact, sc0.H_exact, rtol=1e-3)
