"""The fit of K* = K + j w C + j D over a band and the choice of its damping model, on a
6-DOF system written here (random symmetric positive-definite M, K; C, D chosen)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from processing.stiffness import (
    LeakageMoments,
    StiffnessMoments,
    choose_damping,
    dynamic_stiffness,
    fit_stiffness,
    stiffness_moments,
)

_RNG = np.random.default_rng(7)
_A, _B = _RNG.normal(size=(6, 6)), _RNG.normal(size=(6, 6))
M = _A @ _A.T + 6 * np.eye(6)
K = 100 * _B @ _B.T + 600 * np.eye(6)
C = np.diag(_RNG.uniform(1.0, 3.0, 6))
D = 0.1 * K
T = _RNG.normal(size=(6, 12))
TRUTH = {"viscous": (C, 0 * D), "hysteretic": (0 * C, D), "both": (C, D)}


def accelerances(model: str, w: np.ndarray, noise: float = 0.0, seed: int = 0,
                 decay: float = 0.0) -> np.ndarray:
    """X (6, 12, n) of ``(K + j w C + j D - w^2 M) X = -w^2 T``, with relative noise; with
    ``decay`` a, of the viscous system at ``s = j w + a`` (what an exponential window of
    time constant 1 / a gives): ``(K + s C + s^2 M) X = s^2 T``."""
    Cm, Dm = TRUTH[model]
    s = 1j * w + decay
    Z = K[None] + s[:, None, None] * Cm + 1j * Dm + (s**2)[:, None, None] * M
    X = (s**2)[:, None, None] * np.linalg.solve(Z, np.broadcast_to(T + 0j, (w.size, 6, 12)))
    X = np.moveaxis(X, 0, -1)
    rng = np.random.default_rng(seed)
    return X * (1 + noise * (rng.normal(size=X.shape) + 1j * rng.normal(size=X.shape)))


W = np.linspace(10.0, 60.0, 40)  # rad/s, a band over the modes (ratio 6)


@pytest.mark.parametrize("model", ["viscous", "hysteretic", "both"])
def test_each_model_fits_its_own_data_exactly(model: str) -> None:
    Cm, Dm = TRUTH[model]
    sf = fit_stiffness(accelerances(model, W), T, W, M, model=model)  # type: ignore[arg-type]
    scale = np.abs(K).max()
    assert_allclose(sf.K, K, atol=1e-10 * scale)
    assert_allclose(sf.C, Cm, atol=1e-10 * scale / W.mean())
    assert_allclose(sf.D, Dm, atol=1e-10 * scale)
    assert sf.model == model


def test_the_viscous_fit_is_biased_by_structural_damping() -> None:
    """What the choice is for: K + jwC fitted to K + jD data is off by 0.5 % of max |K|."""
    sf = fit_stiffness(accelerances("hysteretic", W), T, W, M)
    assert np.abs(sf.K - K).max() > 1e-3 * np.abs(K).max()


@pytest.mark.parametrize("model", ["viscous", "hysteretic", "both"])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_the_damping_model_is_chosen_from_the_data(model: str, noise: float) -> None:
    X = accelerances(model, W, noise)
    choice = choose_damping(X, T, W, M)
    assert choice.model == model, choice.reason
    assert choice.reason.startswith("damping ") and "BIC" in choice.reason


@pytest.mark.parametrize("seed", range(5))
def test_a_narrow_band_keeps_the_viscous_model(seed: int) -> None:
    """Over a 2 % band at 1 % noise w C and a constant are alike: the residuals tie and the
    article's viscous model stays (another needs a BIC lower by more than 10)."""
    w = np.linspace(30.0, 30.6, 20)
    X = accelerances("viscous", w, 0.01, seed)
    assert choose_damping(X, T, w, M).model == "viscous"


def test_an_exponential_windows_decay_is_fitted_exactly() -> None:
    """Accelerances at ``s = j w + a``: the fit with ``decay=a`` gives K and C to rounding;
    read as if unwindowed, K is off by more than 1 %."""
    a = 2.0  # 1/s: tau 0.5 s
    X = accelerances("viscous", W, decay=a)
    sf = fit_stiffness(X, T, W, M, decay=a)
    scale = np.abs(K).max()
    assert_allclose(sf.K, K, atol=1e-10 * scale)
    assert_allclose(sf.C, C, atol=1e-10 * scale / W.mean())
    assert np.abs(fit_stiffness(X, T, W, M).K - K).max() > 1e-2 * scale


def test_the_windowed_fit_weighs_lines_the_line_by_line_stiffness_cannot() -> None:
    """Windowed accelerances with 5 % noise on every fourth line and 0.5 % on the others: the
    least squares weighted by the lines' inverse variances (``decay=a``, ``weights``) is
    within 4 % of max |K| in each of 10 draws, and closer than the mean over lines of each
    line's dynamic stiffness (eq. 14 with the window's correction, which weighs every line
    alike) in each."""
    a, scale = 2.0, np.abs(K).max()
    s = 1j * W + a
    sigma = np.where(np.arange(W.size) % 4 == 0, 0.05, 0.005)
    X0 = accelerances("viscous", W, decay=a)
    for seed in range(10):
        rng = np.random.default_rng(seed)
        X = X0 * (1 + sigma * (rng.normal(size=X0.shape) + 1j * rng.normal(size=X0.shape)))
        P = -(s**2 / W**2)[:, None, None] * dynamic_stiffness(X, T, W, M)
        C_line = np.tensordot(W, P.imag, axes=1) / np.sum(W**2)
        line_mean = np.mean(P.real, axis=0) - a * C_line
        weights = np.broadcast_to(1 / sigma**2, (T.shape[1], W.size))
        fitted = fit_stiffness(X, T, W, M, weights=weights, decay=a).K
        assert np.abs(fitted - K).max() < 0.04 * scale, seed
        assert np.abs(fitted - K).max() < np.abs(line_mean - K).max(), seed


def test_a_window_with_structural_damping_is_refused() -> None:
    with pytest.raises(ValueError, match="viscous"):
        fit_stiffness(accelerances("viscous", W), T, W, M, model="hysteretic", decay=1.0)


@pytest.mark.parametrize("stiffened", [False, True])
def test_leakage_moments_equal_the_moments_of_the_cleaned_lines(stiffened: bool) -> None:
    """The moments of ``X - Y S`` from the lines' own (formed once) and Y: the sums over the
    lines of the cleaned X, for any amplitudes, with and without the mounts' stiffening."""
    rng = np.random.default_rng(4710)
    n_e, n_l, n_s = 5, 40, 2
    X = rng.normal(size=(6, n_e, n_l)) + 1j * rng.normal(size=(6, n_e, n_l))
    T, w = rng.normal(size=(6, n_e)), np.linspace(10.0, 100.0, n_l)
    S = rng.normal(size=(n_s, n_l)) + 1j * rng.normal(size=(n_s, n_l))
    wt = rng.random((n_e, n_l))
    g = np.linspace(1.0, 1.2, n_l) if stiffened else None
    moments = LeakageMoments.of(X, T, w, S, wt, g)
    for _ in range(3):
        Y = rng.normal(size=(6, n_e, n_s)) + 1j * rng.normal(size=(6, n_e, n_s))
        want = stiffness_moments(X - np.einsum("ies,sl->iel", Y, S), T, w, wt, g)
        got = moments.at(Y)
        for name in ("G0", "G1", "G2", "G3", "Q0", "Q1", "Q2", "Q3"):
            a = getattr(want, name)
            assert_allclose(getattr(got, name), a, rtol=0, atol=1e-13 * np.abs(a).max())
        assert got.stiffened == stiffened and got.n_equations == want.n_equations
        if stiffened:
            assert_allclose(got.G2c, want.G2c, rtol=0, atol=1e-13 * np.abs(want.G2c).max())


@pytest.mark.parametrize("model", ["viscous", "both"])
@pytest.mark.parametrize("symmetric", [True, False])
def test_stacked_moments_give_each_stiffenings_own_fit(model: str, symmetric: bool) -> None:
    """The moments of several stiffenings stacked on a leading axis (the stiffening's search
    fits its trial rises at once) give, for each, the fit of its moments alone."""
    X = accelerances(model, W, noise=0.01, seed=3)
    wt = np.random.default_rng(11).random(X.shape[1:])
    rows = np.linspace(0.5, 2.0, 6)
    one = [stiffness_moments(X, T, W, wt, (W / 30.0) ** a) for a in (0.0, 0.05, 0.2)]
    names = ("G0", "G1", "G2", "G3", "Q0", "Q1", "Q2", "Q3")
    stacked = StiffnessMoments(*(np.stack([getattr(m, n) for m in one]) for n in names),
                               one[0].n_equations, np.stack([m.G2c for m in one]))
    got = fit_stiffness(stacked, T, W, M, row_scale=rows, symmetric=symmetric, model=model)
    assert got.K.shape == (3, 6, 6)
    for k, m in enumerate(one):
        want = fit_stiffness(m, T, W, M, row_scale=rows, symmetric=symmetric, model=model)
        for a, b in ((got.K[k], want.K), (got.C[k], want.C), (got.D[k], want.D)):
            assert_allclose(a, b, rtol=0, atol=1e-9 * max(np.abs(b).max(), 1.0))
