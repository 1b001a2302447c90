"""Fast paths of the identification against their plain definitions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hardware_mocks.benches import get_bench
from processing._kernels import real_times_complex, sumsq_columns, sumsq_rows
from processing.geometry import excitation_matrix, response_matrix
from processing.identify import IdentifyOptions, SolverSettings, identify
from processing.inertia import mass_matrix
from processing.massline import MassLineProblem
from processing.selection import reconstruction_error
from processing.stiffness import dynamic_stiffness, line_operators
from processing.synthesis import synthesise


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 5), st.integers(1, 6), st.integers(2, 9), st.integers(0, 3),
       st.integers(0, 2**32 - 1))
def test_sum_of_squares_kernels(a: int, b: int, n: int, start: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    Z = rng.standard_normal((a, b, n + start)) + 1j * rng.standard_normal((a, b, n + start))
    Z = Z[..., start:]  # a strided view, as identify passes
    np.testing.assert_allclose(sumsq_columns(Z), np.sum(np.abs(Z) ** 2, axis=(0, 1)), rtol=1e-12)
    np.testing.assert_allclose(sumsq_rows(Z), np.sum(np.abs(Z) ** 2, axis=-1), rtol=1e-12)
    A = rng.standard_normal((3, a))
    Zf = Z.reshape(a, -1)
    np.testing.assert_allclose(real_times_complex(A, Zf), A @ Zf, rtol=1e-12, atol=1e-12)


def test_reconstruction_error_identity_matches_residual() -> None:
    """||H||^2 - ||E X||^2 equals the explicit residual ||H - E E^+ H|| (to rounding)."""
    frf = get_bench("block-flexible").frfset(noise=0.01, seed=3)
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    R = frf.H - np.einsum("ra,aef->ref", E @ np.linalg.pinv(E), frf.H)
    direct = np.sqrt(np.sum(np.abs(R) ** 2, axis=(0, 1)))
    a, rel = reconstruction_error(frf.H, E)
    np.testing.assert_allclose(a, direct, rtol=1e-6)
    np.testing.assert_allclose(rel, direct / np.sqrt(np.sum(np.abs(frf.H) ** 2, axis=(0, 1))),
                               rtol=1e-6)


@pytest.mark.parametrize("name", ["engine", "block"])
@pytest.mark.parametrize("decay", [0.0, 2.5])
def test_modal_synthesis_matches_direct_solve(name: str, decay: float) -> None:
    """Both paths of the synthesis, without and with an exponential window's decay (the
    model at s = j w + a; the direct solve is taken when the mounts stiffen)."""
    m = get_bench(name).model
    frf = get_bench(name).frfset()
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    f = frf.freq[frf.freq > 0]
    s = 2j * np.pi * f + decay
    Z = m.K[None] + s[:, None, None] * m.C[None] + (s**2)[:, None, None] * m.M[None]
    A = (s**2)[:, None, None] * np.linalg.solve(Z, np.broadcast_to(T, (s.size, *T.shape)))
    direct = np.einsum("ra,fae->ref", E, A)
    for stiffening in (None, np.ones(f.size)):
        np.testing.assert_allclose(synthesise(f, E, T, m.M, m.K, m.C, stiffening=stiffening,
                                              decay=decay), direct, rtol=1e-8,
                                   atol=1e-10 * np.abs(direct).max())


def test_line_operators_match_eq14() -> None:
    frf = get_bench("engine").frfset(noise=0.02, seed=1)
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    X = np.einsum("ar,ref->aef", np.linalg.pinv(E), frf.H)[..., 1:40]
    w = 2 * np.pi * frf.freq[1:40]
    M = get_bench("engine").model.M
    Xl = np.moveaxis(X, -1, 0)
    Xplus = np.linalg.pinv(Xl)  # right inverse per line, (n_l, n_e, 6)
    eq14 = (w**2)[:, None, None] * (M @ Xl - T[None]) @ Xplus
    np.testing.assert_allclose(dynamic_stiffness(X, T, w, M), eq14, rtol=1e-8,
                               atol=1e-8 * np.abs(eq14).max())
    K, C = line_operators(X, T, w).mean_kc()(M)
    np.testing.assert_allclose(K, eq14.real.mean(axis=0), atol=1e-8 * np.abs(K).max())
    np.testing.assert_allclose(C, (eq14.imag / w[:, None, None]).mean(axis=0),
                               atol=1e-8 * np.abs(C).max())


def test_plain_fixed_point_is_the_limit_of_the_article_iteration() -> None:
    """The direct affine solve equals iterating section 2.2 to convergence."""
    frf = get_bench("engine-rigid").frfset(noise=0.02, location_error=0.003, seed=5)
    opt = IdentifyOptions(method="plain", mass_band=(40.0, 60.0), stiffness_band=(1.0, 35.0))
    r = identify(frf, opt, SolverSettings(level=1e9))
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    X = np.einsum("ar,ref->aef", np.linalg.pinv(E), frf.H)
    f = frf.freq
    mass = (f >= 40) & (f <= 60)
    stiff = (f >= 1) & (f <= 35)
    problem = MassLineProblem(X[..., mass])
    mean = line_operators(X[..., stiff], T, 2 * np.pi * f[stiff]).mean_kc()
    K = C = np.zeros((6, 6))
    theta = np.zeros(10)
    for _ in range(200):
        theta = problem.solve_kc(T, K, C, X[..., mass], 2 * np.pi * f[mass]).theta
        K, C = mean(mass_matrix(theta))
    np.testing.assert_allclose(r.theta, theta, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(r.K, K, rtol=1e-9, atol=1e-9 * np.abs(K).max())


def test_duplicate_leakage_shapes_do_not_change_the_fit() -> None:
    """A mode reported twice (two residual peaks on one mode) must not remove information."""
    from processing.massline import stack_real
    from processing.selection import mode_shape_basis

    bench = get_bench("block-flexible")
    frf = bench.frfset()
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    lo, hi = bench.article_bands[0]
    sel = (frf.freq >= lo) & (frf.freq <= hi)
    X = np.einsum("ar,ref->aef", np.linalg.pinv(E), frf.H)[..., sel]
    w = 2 * np.pi * frf.freq[sel]
    r = identify(frf)
    shapes = [stack_real(mode_shape_basis(w, p)) for p in r.elastic_modes]
    shapes.append(stack_real(w**2 + 0j))
    once = MassLineProblem(X, shapes=np.array(shapes)).solve(T[:, :, None] + 0j)
    twice = MassLineProblem(X, shapes=np.array([shapes[0], *shapes])).solve(T[:, :, None] + 0j)
    np.testing.assert_allclose(twice.theta, once.theta, rtol=1e-9)


def test_nearly_dependent_leakage_shapes_keep_the_fit() -> None:
    """Two spurious peaks close together far above the mass line (368.7 and 378.6 Hz for
    a 57.8-83 Hz mass line, seen in a demo run) plus the w^2 term are nearly one shape
    there: the fit must not fall apart (it gave 18 kg for 110 kg before)."""
    from processing.massline import stack_real
    from processing.selection import ElasticPeak, mode_shape_basis

    bench = get_bench("engine")
    frf = bench.frfset()
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    sel = (frf.freq >= 57.8) & (frf.freq <= 83.0)
    X = np.einsum("ar,ref->aef", np.linalg.pinv(E), frf.H)[..., sel]
    w = 2 * np.pi * frf.freq[sel]
    K, C = bench.model.K, bench.model.C
    Xf = X.reshape(6, -1)
    B = T[:, :, None] + ((K @ Xf).reshape(X.shape) + 1j * w * (C @ Xf).reshape(X.shape)) / w**2
    shapes = [stack_real(mode_shape_basis(w, ElasticPeak(f, z)))
              for f, z in ((118.5, 0.02), (368.7, 1e-4), (378.6, 1e-4))]
    shapes.append(stack_real(w**2 + 0j))
    fit = MassLineProblem(X, shapes=np.array(shapes)).solve(B)
    assert abs(fit.theta[0] - bench.model.mass) < 0.002 * bench.model.mass
