"""Uncertainty of an identification from its own fit: covariance of theta, K and C, and
its linear propagation to every reported number.

Inertia (the mass-line least squares, :class:`processing.massline.MassLineProblem`)
    The residual of a mass line is not white: elastic-mode leakage, location and sensor
    errors make it a smooth function of frequency, correlated over many lines, so the
    textbook ``s^2 N^-1`` is far too small. The covariance is the cluster-robust
    (sandwich) form with contiguous blocks of lines as clusters::

        cov(theta) = N^-1 [g / (g - 1) sum_b (S_b - S_mean)(S_b - S_mean)^T] N^-1 * n / (n - p)

    ``S_b`` the sum over block b's lines of the per-line gradient terms ``a_p . r``
    (:meth:`~processing.massline.MassLineProblem.line_scores`), ``g`` the number of
    blocks, ``n / (n - p)`` the degrees of freedom taken by the ten parameters and the
    leakage coefficients eliminated by projection. It is the delete-a-block jackknife
    to first order: a residual that drifts with frequency (an estimate that moves with
    the band) weighs in, white noise gives the usual variance. The larger of this and
    ``s^2 N^-1`` is kept (per parameter scale).

Stiffness and damping
    ``K*_j`` per stiffness line (eq. 14) scatters about the fitted ``K + j w_j C``; the
    fit's estimate moves with the line average of that scatter. Its covariance is the same
    block form over the stiffness lines (``K``: mean of ``Re``; ``C``: least squares of
    ``Im = w C``), plus theta's covariance carried through M by the exact Jacobian of the
    stiffness step (it is affine in M).

Derived numbers
    mass, CoG, tensors about O and the CoG, principal moments (eigenvalue derivatives
    ``v^T dJ v``) and rigid-body modes (``phi^T (dK - w^2 dM) phi``, mass-normalised
    shapes) by first-order propagation of the joint covariance of
    ``[theta (10), vec K (36), vec C (36)]``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from processing.inertia import MASS_BASIS, mass_matrix, tensor_from_theta
from processing.massline import MassLineProblem
from processing.results import UNCERTAIN_KEYS, Contribution, Uncertainty

__all__ = [
    "FitCovariance",
    "block_covariance",
    "combine",
    "draw_covariance",
    "draw_variances",
    "drift_factor",
    "excitation_jackknife",
    "fit_covariance",
    "flexibility_bias",
    "force_noise_ratio",
    "propagate",
    "regressor_weights",
    "series_softening",
    "symmetrised",
    "theta_covariance",
]

#: number of contiguous line blocks of the cluster-robust covariance (at most)
DEFAULT_BLOCKS = 16
#: relative precision of the arithmetic chain (spectra, E^+, solves): the smallest std kept,
#: relative to each parameter's scale
NUMERICAL_FLOOR = 1e-10

StiffnessMap = Callable[[NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]]


@dataclass(frozen=True)
class FitCovariance:
    """Joint covariance of ``p = [theta (10), vec K (36), vec C (36)]`` (row-major vecs).

    ``cov`` (82, 82) in SI units; ``parts`` the same split by source (each (82, 82),
    summing to ``cov``), named as :class:`Contribution` sources.
    """

    cov: NDArray[np.float64]
    parts: dict[str, NDArray[np.float64]]


def _blocks(n: int, n_blocks: int) -> NDArray[np.int64]:
    """Block index (n,) of n consecutive lines split into ``min(n, n_blocks)`` runs."""
    g = max(1, min(n, n_blocks))
    return np.minimum((np.arange(n) * g) // n, g - 1)


def block_covariance(terms: NDArray[np.float64], n_blocks: int = DEFAULT_BLOCKS) -> (
    NDArray[np.float64]
):
    """Cluster-robust covariance of ``sum_j terms[:, j]`` with contiguous blocks as clusters.

    Parameters
    ----------
    terms : (q, n) contributions of n consecutive lines to q sums
    n_blocks : how many contiguous blocks (at most n)

    Returns
    -------
    (q, q) ``g / (g - 1) sum_b (S_b - S_mean)(S_b - S_mean)^T``; zeros under 2 blocks.
    """
    q, n = terms.shape
    idx = _blocks(n, n_blocks)
    g = int(idx[-1]) + 1 if n else 0
    if g < 2:
        return np.zeros((q, q))
    S = np.zeros((q, g))
    np.add.at(S.T, idx, terms.T)
    S -= S.mean(axis=1, keepdims=True)
    return np.asarray(g / (g - 1) * (S @ S.T))


def theta_covariance(ml: MassLineProblem, theta: NDArray[np.float64],
                     B: NDArray[np.complexfloating], n_blocks: int = DEFAULT_BLOCKS) -> (
    NDArray[np.float64]
):
    """(10, 10) covariance of the mass-line estimate (see the module docstring)."""
    N = ml.normal
    Ninv = np.linalg.pinv(N)
    scores = ml.line_scores(theta, B)  # (10, n_exc, n_lines)
    dof = max(ml.n_equations - ml.n_free, 1)
    inflate = ml.n_equations / dof
    candidates = [
        excitation_jackknife(ml, scores.sum(axis=2)),
        Ninv @ block_covariance(scores.sum(axis=1), n_blocks) @ Ninv * inflate,
        Ninv * ml.residual_ss(theta, B) / dof,
    ]
    return _largest(candidates)


def excitation_jackknife(ml: MassLineProblem, col_scores: NDArray[np.float64]) -> (
    NDArray[np.float64]
):
    """Delete-one-excitation jackknife covariance of theta, (10, 10).

    Leaving column k out moves the least-squares solution by exactly
    ``(N - N_k)^-1 s_k`` (``N_k`` its share of the normal matrix, ``s_k`` its gradient
    terms, (10, n_exc)); their spread is the jackknife variance. An elastic mode, a
    misplaced hit or a bad force channel makes the columns disagree.
    """
    n_e = col_scores.shape[1]
    if n_e < 2:
        return np.zeros((10, 10))
    A = ml.normal[None] - ml.column_normals()
    D = np.einsum("kpq,qk->kp", np.linalg.pinv(A), col_scores)
    D -= D.mean(axis=0)
    return np.asarray((n_e - 1) / n_e * D.T @ D)


def _largest(covs: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """The first covariance with each parameter's variance raised to the largest of all
    (a congruence ``S C S``, so it stays positive semi-definite)."""
    base = covs[0]
    d0 = np.diag(base)
    top = np.max([np.diag(c) for c in covs], axis=0)
    ok = d0 > 0
    scale = np.where(ok, np.sqrt(top / np.where(ok, d0, 1.0)), 0.0)
    cov = base * np.outer(scale, scale)
    cov[~ok, ~ok] = top[~ok]
    return np.asarray(0.5 * (cov + cov.T))


def stiffness_scatter(Ks_lines: NDArray[np.complex128], w: NDArray[np.float64],
                      K: NDArray[np.float64], C: NDArray[np.float64],
                      n_blocks: int = DEFAULT_BLOCKS,
                      D: NDArray[np.float64] | None = None,
                      weight: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(72, 72) covariance of [vec K, vec C] from the scatter of ``K*_j`` (n, 6, 6) about
    ``K + j w_j C + j D`` over the stiffness lines ``w`` (rad/s).

    ``K`` is the weighted mean of ``Re``; ``C`` the weighted least squares of ``Im = w C``
    or, when a structural ``D`` was fitted alongside (non-zero), of ``Im = w C + D`` (a
    slope with an intercept: its variance grows by ``sum w^2 / sum (w - mean w)^2``).
    ``weight`` (n,) is each line's share of the fit (:func:`regressor_weights`; equal
    without): a line whose accelerances are small and noisy scatters most and counts
    least, in the fit as here. Per entry, the
    larger of the block-robust form with ``n_blocks`` blocks and the two-block jackknife
    (the lower against the upper half of the lines: a drift of ``K*`` with frequency that
    the many small blocks average out).
    """
    n = w.size
    nu = np.ones(n) if weight is None else np.clip(np.asarray(weight, float), 0.0, None)
    if not np.sum(nu) > 0:
        nu = np.ones(n)
    E = Ks_lines - (K[None] + 1j * w[:, None, None] * C[None])
    with_d = D is not None and bool(np.any(D))
    if D is not None:
        E = E - 1j * D[None]
    wc = w - np.average(w, weights=nu) if with_d else w
    denom = float(np.sum(nu * wc**2))
    terms = np.concatenate([(nu[:, None] * E.real.reshape(n, 36)).T / np.sum(nu),
                            ((nu * wc)[:, None] * E.imag.reshape(n, 36)).T
                            / max(denom, 1e-300)])
    n_eff = float(np.sum(nu) ** 2 / np.sum(nu**2))
    dof = max(n_eff - (3 if with_d else 2), 1.0)
    return _largest([block_covariance(terms, n_blocks), block_covariance(terms, 2)]) * n_eff / dof


def drift_factor(w: NDArray[np.float64], weight: NDArray[np.float64]) -> float:
    """How far the estimate of the whole mass line lies from the residual-free one, in units
    of the difference between its upper and lower halves (the split of the half-band fits).

    Modes above the band add a residual growing like ``w^2`` to the accelerances below them
    (the first term of ``w^2 / (w_e^2 - w^2)``); on a mass line where the regressors are
    nearly flat, a least-squares estimate over a set of lines is then biased by
    ``v <w^2>``, ``<.>`` the mean over those lines weighted by their share of the normal
    matrix, ``v`` the same for every set. The two halves give
    ``d = v (<w^2>_upper - <w^2>_lower)``, so the bias of the whole band is
    ``d <w^2>_all / (<w^2>_upper - <w^2>_lower)``: this factor.

    Parameters
    ----------
    w : (n,) rad/s, the mass lines in ascending order
    weight : (n,) each line's weight in the fit (non-negative)

    Returns
    -------
    The factor (0.5 when the halves carry no information about the drift, e.g. < 2 lines).
    """
    n = w.size
    h = n // 2
    wt = np.clip(np.asarray(weight, float), 0.0, None)
    if h < 1 or np.sum(wt[:h]) <= 0 or np.sum(wt[h:]) <= 0:
        return 0.5
    w2 = np.asarray(w, float) ** 2
    lo = float(np.average(w2[:h], weights=wt[:h]))
    hi = float(np.average(w2[h:], weights=wt[h:]))
    al = float(np.average(w2, weights=wt))
    return max(al / (hi - lo), 0.5) if hi > lo else 0.5


def regressor_weights(X: NDArray[np.complexfloating], weights: NDArray[np.float64] | None,
                      row_scale: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """(n_lines,) each line's share of a fit whose regressors are the accelerances X
    (6, n_exc, n_lines): their weighted squared size ``sum_e weight_el sum_i (s_i |X_iel|)^2``
    (``s`` the equations' row scale)."""
    s2 = (np.ones(6) if row_scale is None else np.asarray(row_scale, float) ** 2)[:, None, None]
    size = np.sum(s2 * np.abs(X) ** 2, axis=0)  # (n_e, n_l)
    if weights is not None:
        size = size * weights
    return np.asarray(np.sum(size, axis=0))


def force_noise_ratio(coherence: NDArray[np.float64], weight: NDArray[np.float64]) -> float:
    """Upper bound of the force channels' noise-to-signal power ratio from the coherence.

    Noise on the force biases an H1 estimate low by ``Sff_true / Sff = 1 / (1 + a_f)``
    (errors in variables; noise on the responses does not bias it). Per excitation and
    line, ``1 - g_r = 1 - 1 / ((1 + a_f)(1 + a_r))`` for each response r of that run, so
    the best-coherent response bounds ``a_f <= 1 / max_r g_r - 1``. Returned: that bound,
    averaged over columns and lines with the fit's weights.

    Parameters
    ----------
    coherence : (n_resp, n_exc, n_lines) on the lines of the fit
    weight : (n_exc, n_lines) each value's weight in the fit
    """
    g = np.clip(np.max(coherence, axis=0), 1e-6, 1.0)
    wt = np.clip(np.asarray(weight, float), 0.0, None)
    if np.sum(wt) <= 0:
        return 0.0
    return float(np.average(1.0 / g - 1.0, weights=wt))


def _sym_basis() -> NDArray[np.float64]:
    """(21, 6, 6) basis of the symmetric 6x6 matrices (upper-triangle order)."""
    iu = np.triu_indices(6)
    out = np.zeros((21, 6, 6))
    out[np.arange(21), iu[0], iu[1]] = 1.0
    out[np.arange(21), iu[1], iu[0]] = 1.0
    return out


def flexibility_bias(Ks_lines: NDArray[np.complex128], w: NDArray[np.float64],
                     M: NDArray[np.float64], K: NDArray[np.float64],
                     weight: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(6, 6) bias of K from a flexibility in series with the rigid body, fitted to the
    stiffness lines.

    The body's elastic modes above the band add a nearly constant flexibility ``R``
    (rigid-body coordinates at O) in series with the mounts: a line's dynamic stiffness is
    then ``(D_j^-1 + R)^-1 ~ D_j - D_j R D_j`` with ``D_j = K - w_j^2 M``, a term that
    changes with frequency (largest at the lowest lines, none at the rigid-body modes).
    The fit of a constant K absorbs its mean: ``K_fit ~ K - <D R D>``. ``R`` (symmetric,
    21 numbers) is fitted to how ``Re K*_j`` varies over the lines (weighted least
    squares of the deviations from their weighted means), and ``<D R D>`` returned, scaled
    by the positive-part James-Stein factor ``max(0, 1 - 21 / F)``, ``F = r^T N r / s^2``
    the fitted R's size against its own noise (about 21 when the lines show none): a
    flexibility fitted to the noise of a stiff body's lines is dropped, the lines' scatter
    having that noise already.

    Parameters
    ----------
    Ks_lines : (n, 6, 6) K* of each stiffness line; w : (n,) rad/s
    M, K : (6, 6) the fitted mass and stiffness matrices at O
    weight : (n,) each line's share of the fit (equal without)
    """
    n = w.size
    nu = np.ones(n) if weight is None else np.clip(np.asarray(weight, float), 0.0, None)
    if n < 8 or not np.sum(nu) > 0:
        return np.zeros((6, 6))
    nu = nu / np.sum(nu)
    Dj = K[None] - (np.asarray(w, float) ** 2)[:, None, None] * M[None]
    Dj = 0.5 * (Dj + np.swapaxes(Dj, 1, 2))
    i, j = np.triu_indices(6)
    # d(D R D)/dR_ij = d_i d_j^T + d_j d_i^T (d_i the i-th column of the symmetric D; once
    # on the diagonal)
    A = Dj[:, :, i].transpose(0, 2, 1)[..., None] * Dj[:, :, j].transpose(0, 2, 1)[:, :, None]
    A = A + np.where((i != j)[None, :, None, None], np.swapaxes(A, 2, 3), 0.0)
    iu = i * 6 + j  # the 21 distinct entries of the symmetric matrices
    A = A.reshape(n, 21, 36)[:, :, iu]
    Ks_re = np.real(Ks_lines)
    y = (0.5 * (Ks_re + np.swapaxes(Ks_re, 1, 2))).reshape(n, 36)[:, iu]
    A = A - np.tensordot(nu, A, axes=1)[None]
    y = y - nu @ y
    Af = np.ascontiguousarray(A.transpose(1, 0, 2)).reshape(21, n * 21)
    Anf = Af * np.repeat(nu, 21)[None]
    N = Anf @ Af.T
    g = Anf @ y.ravel()
    # minus sign: K* = D - D R D, so the deviations of Re K* are -(D R D - <D R D>)
    r = -np.linalg.lstsq(N, g, rcond=None)[0]
    # how far R stands out of the lines' noise: F = r^T N r / s^2 with s^2 the residual
    # variance (21 on average when there is no flexibility); the positive-part James-Stein
    # factor 1 - 21 / F keeps a real flexibility and drops one fitted to noise
    e = y + (Af.T @ r).reshape(n, 21)
    s2 = float(np.sum(nu[:, None] * e**2)) / max(21 * n - 21, 1)
    F = float(r @ N @ r) / s2 if s2 > 0 else np.inf
    shrink = max(0.0, 1.0 - 21.0 / F) if F > 0 else 0.0
    R = shrink * np.einsum("k,kab->ab", r, _sym_basis())
    return np.asarray(np.einsum("l,lab,bc,lcd->ad", nu, Dj, R, Dj))


def series_softening(M: NDArray[np.float64], K: NDArray[np.float64],
                     elastic_hz: float | tuple[float, ...],
                     C: NDArray[np.float64] | None = None,
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(6, 6) sizes of the changes of K and C by a body flexibility with elastic modes at
    ``elastic_hz`` (Hz): ``K M^-1 K s`` and ``(K M^-1 C + C M^-1 K) s``, ``s = sum 1 / w_e^2``.

    The mounts act on the body at points that the body's elastic modes move: the rigid-body
    model sees their dynamic stiffness ``Z = K + j w C`` in series with the body's
    flexibility there, ``(Z^-1 + R_m)^-1 ~ Z - Z R_m Z``, a change of K and C that no
    rigid-body residual shows. Each mode at ``w_e`` with a unit share at the mounts adds
    ``M^-1 / w_e^2`` to ``R_m``; the relative change of a rigid-body mode's ``w_r^2`` is then
    ``w_r^2 sum 1 / w_e^2``.
    """
    f = np.atleast_1d(np.asarray(elastic_hz, dtype=float))
    f = f[f > 0]
    s = float(np.sum(1.0 / (2 * np.pi * f) ** 2)) if f.size else 0.0
    Minv = np.linalg.pinv(M)
    S = K @ Minv @ K * s
    Cz = np.zeros((6, 6)) if C is None else C
    T = (K @ Minv @ Cz + Cz @ Minv @ K) * s
    return np.asarray(0.5 * (S + S.T)), np.asarray(0.5 * (T + T.T))


def fit_covariance(ml: MassLineProblem, theta: NDArray[np.float64],
                   B: NDArray[np.complexfloating], stiffness_map: StiffnessMap,
                   Ks_lines: NDArray[np.complex128], w_stiff: NDArray[np.float64],
                   K: NDArray[np.float64], C: NDArray[np.float64],
                   n_blocks: int = DEFAULT_BLOCKS,
                   half_thetas: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
                   D: NDArray[np.float64] | None = None,
                   w_mass: NDArray[np.float64] | None = None,
                   force_noise: float = 0.0,
                   stiff_weight: NDArray[np.float64] | None = None,
                   elastic_hz: tuple[float, ...] = (),
                   symmetric: bool = False,
                   ) -> FitCovariance:
    """Joint covariance of theta, K and C of one fit.

    Parameters
    ----------
    ml, theta, B : the final mass-line problem, its solution and right-hand side
    stiffness_map : M (6, 6) -> (K, C), the fit's stiffness step (affine in M)
    Ks_lines : (n, 6, 6) K* of each stiffness line used, w_stiff (n,) rad/s
    K, C : the fitted stiffness and damping
    half_thetas : theta of the same model on the lower and upper half of the mass lines;
        their difference d gives the band-drift term ``(f d)(f d)^T``, f from
        :func:`drift_factor` on ``w_mass`` (rad/s, the mass lines; without them the
        two-block jackknife ``d d^T / 4``), a further candidate of the largest-variance rule
    force_noise : bound of the force noise-to-signal ratio (:func:`force_noise_ratio`):
        the H1 bias it causes scales theta, K and C alike, its part is
        ``a^2 p p^T`` for ``p = [theta, vec K, vec C]``
    stiff_weight : (n,) each stiffness line's share of the stiffness fit
        (:func:`regressor_weights`), for :func:`stiffness_scatter` and
        :func:`flexibility_bias` (whose result is a part of its own)
    elastic_hz : the elastic modes seen in the data (Hz), if any: the part
        :func:`series_softening` of K and C
    symmetric : K and C were fitted symmetric: each part is then :func:`symmetrised`
    """
    cov_t = theta_covariance(ml, theta, B, n_blocks)
    if half_thetas is not None:
        d = np.asarray(half_thetas[1]) - np.asarray(half_thetas[0])
        if np.all(np.isfinite(d)):
            f = 0.5 if w_mass is None else drift_factor(
                np.asarray(w_mass), regressor_weights(ml.X, ml.weights, ml._row_scale))
            cov_t = _largest([cov_t, np.outer(d, d) * f**2])
    # floor: the precision of the arithmetic, relative to m, m L and m L^2
    m = abs(float(theta[0]))
    L = np.sqrt(max(abs(float(np.sum(theta[4:7]))) / max(m, 1e-300), 1e-12))
    scale = np.array([m, *(3 * [m * L]), *(6 * [m * L**2])]) * NUMERICAL_FLOOR
    cov_t = cov_t + np.diag(scale**2)
    M0 = mass_matrix(theta)
    K0, C0 = stiffness_map(M0)
    J = np.empty((72, 10))
    for p in range(10):  # the step is affine in M: one evaluation per basis matrix
        Kp, Cp = stiffness_map(M0 + MASS_BASIS[p])
        J[:36, p] = (Kp - K0).ravel()
        J[36:, p] = (Cp - C0).ravel()
    scatter = stiffness_scatter(Ks_lines, w_stiff, K, C, n_blocks, D, stiff_weight)
    dk = np.sqrt(np.abs(np.diag(K)))
    dc = np.sqrt(np.abs(np.diag(C)))
    scatter = scatter + np.diag(np.concatenate([np.outer(dk, dk).ravel(),
                                                np.outer(dc, dc).ravel()]) * NUMERICAL_FLOOR)**2
    A = np.vstack([np.eye(10), J])
    from_theta = A @ cov_t @ A.T
    from_lines = np.zeros((82, 82))
    from_lines[10:, 10:] = scatter
    parts = {"mass-line fit": from_theta, "stiffness-line scatter": from_lines}
    if elastic_hz:
        v = np.zeros(82)
        dK, dC = series_softening(M0, K, tuple(elastic_hz), C)
        v[10:46], v[46:] = dK.ravel(), dC.ravel()
        parts["mounts softened by the body's flexibility"] = np.outer(v, v)
    dK = flexibility_bias(Ks_lines, w_stiff, M0, K, stiff_weight)
    if np.all(np.isfinite(dK)) and np.any(dK):
        v = np.zeros(82)
        v[10:46] = dK.ravel()
        parts["body flexibility in the stiffness lines"] = np.outer(v, v)
    if force_noise > 0:
        p_all = np.concatenate([theta, np.ravel(K), np.ravel(C)])
        parts["force noise (H1 bias)"] = force_noise**2 * np.outer(p_all, p_all)
    if symmetric:
        parts = {name: symmetrised(part) for name, part in parts.items()}
    return FitCovariance(np.sum(list(parts.values()), axis=0), parts)


def _symmetriser() -> NDArray[np.float64]:
    """(82, 82) ``Q`` mapping ``[theta, vec K, vec C]`` to ``[theta, vec sym K, vec sym C]``,
    ``sym A = (A + A^T) / 2`` (row-major vec)."""
    swap = np.arange(36).reshape(6, 6).T.ravel()  # vec A -> vec A^T
    P = 0.5 * (np.eye(36) + np.eye(36)[swap])
    Q = np.eye(82)
    Q[10:46, 10:46] = P
    Q[46:, 46:] = P
    return Q


_SYM = _symmetriser()


def symmetrised(cov: NDArray[np.float64]) -> NDArray[np.float64]:
    """The (82, 82) covariance of ``[theta, vec sym K, vec sym C]`` from that of
    ``[theta, vec K, vec C]``: ``Q cov Q^T``.

    A symmetric fit's K is the symmetric part of what the per-line scatter describes
    entry by entry; the variance of its ``[i, j]`` entry is then
    ``(var K_ij + var K_ji + 2 cov(K_ij, K_ji)) / 4``, the same for ``[j, i]``. Parts that
    are already symmetric (carried from theta through the symmetric stiffness step) are
    unchanged.
    """
    return np.asarray(_SYM @ cov @ _SYM.T)


# --- propagation -----------------------------------------------------------------------------


def _jacobians(theta: NDArray[np.float64], K: NDArray[np.float64],
               M_modes: NDArray[np.float64] | None = None) -> dict[str, NDArray[np.float64]]:
    """d(key)/dp for every key of :data:`UNCERTAIN_KEYS`, shapes ``key shape + (82,)``."""
    m, h = float(theta[0]), theta[1:4]
    out: dict[str, NDArray[np.float64]] = {}
    dm = np.zeros(82)
    dm[0] = 1.0
    out["mass"] = dm
    dc = np.zeros((3, 82))
    dc[:, 0] = -h / m**2
    dc[:, 1:4] = np.eye(3) / m
    out["cog"] = dc
    dJO = np.zeros((3, 3, 82))
    for p in range(4, 10):
        e = np.zeros(10)
        e[p] = 1.0
        dJO[..., p] = tensor_from_theta(e)
    out["inertia_origin"] = dJO
    # J_G = J_O - (|h|^2 I - h h^T) / m
    I3 = np.eye(3)
    Sh = (h @ h) * I3 - np.outer(h, h)
    dJG = dJO.copy()
    dJG[..., 0] += Sh / m**2
    for k in range(3):
        ek = I3[k]
        dS = 2 * h[k] * I3 - np.outer(ek, h) - np.outer(h, ek)
        dJG[..., 1 + k] -= dS / m
    out["inertia_cog"] = dJG
    JG = tensor_from_theta(theta) - Sh / m
    _, V = np.linalg.eigh(JG)
    out["principal_moments"] = np.einsum("ai,abp,bi->ip", V, dJG, V)
    out["stiffness"] = np.zeros((6, 6, 82))
    out["stiffness"].reshape(36, 82)[:, 10:46] = np.eye(36)
    out["damping"] = np.zeros((6, 6, 82))
    out["damping"].reshape(36, 82)[:, 46:] = np.eye(36)
    M = mass_matrix(theta) if M_modes is None else M_modes
    dmodes = np.full((6, 82), np.nan)
    try:
        lam, Phi = scipy.linalg.eigh(0.5 * (K + K.T), M)  # mass-normalised columns
        dK = np.zeros((6, 6, 82))
        dK.reshape(36, 82)[:, 10:46] = np.eye(36)
        dK = 0.5 * (dK + np.swapaxes(dK, 0, 1))
        dM = np.zeros((6, 6, 82))
        dM[..., :10] = np.moveaxis(MASS_BASIS, 0, -1)
        dlam = (np.einsum("ai,abp,bi->ip", Phi, dK, Phi)
                - lam[:, None] * np.einsum("ai,abp,bi->ip", Phi, dM, Phi))
        f = np.sqrt(np.clip(lam, 0, None)) / (2 * np.pi)
        with np.errstate(divide="ignore", invalid="ignore"):
            dmodes = dlam / (8 * np.pi**2 * f[:, None])
        dmodes[f <= 0] = np.nan
    except (np.linalg.LinAlgError, ValueError):
        pass
    out["rigid_modes_hz"] = dmodes
    return out


def propagate(theta: NDArray[np.float64], K: NDArray[np.float64], cov: NDArray[np.float64],
              ) -> dict[str, NDArray[np.float64]]:
    """Standard deviations of every key of :data:`UNCERTAIN_KEYS` from the (82, 82) joint
    covariance of ``[theta, vec K, vec C]`` (first order)."""
    std: dict[str, NDArray[np.float64]] = {}
    for key, Jk in _jacobians(theta, K).items():
        flat = Jk.reshape(-1, 82)
        var = np.einsum("ip,pq,iq->i", flat, cov, flat)
        std[key] = np.sqrt(np.clip(var, 0.0, None)).reshape(UNCERTAIN_KEYS[key])
    return std


def variance_parts(theta: NDArray[np.float64], K: NDArray[np.float64],
                   parts: dict[str, NDArray[np.float64]],
                   ) -> dict[str, dict[str, NDArray[np.float64]]]:
    """Per key, the variance of each entry due to each part (same keys as ``parts``)."""
    jac = _jacobians(theta, K)
    out: dict[str, dict[str, NDArray[np.float64]]] = {}
    for key, Jk in jac.items():
        flat = Jk.reshape(-1, 82)
        out[key] = {name: np.einsum("ip,pq,iq->i", flat, c, flat).reshape(UNCERTAIN_KEYS[key])
                    for name, c in parts.items()}
    return out


_AXES = "xyz"
_DOF = ("x", "y", "z", "rx", "ry", "rz")


def entry_names(key: str) -> list[str]:
    """The terminal names of the entries of one key, in C order (``"cog z"``, ...)."""
    shape = UNCERTAIN_KEYS[key]
    if key == "mass":
        return ["mass"]
    if key == "cog":
        return [f"cog {a}" for a in _AXES]
    if key in ("inertia_cog", "inertia_origin"):
        return [f"{key} {a}{b}" for a in _AXES for b in _AXES]
    if key == "principal_moments":
        return [f"principal moment {i + 1}" for i in range(3)]
    if key in ("stiffness", "damping"):
        return [f"{key} {a},{b}" for a in _DOF for b in _DOF]
    return [f"rigid mode {i + 1}" for i in range(shape[0])]


#: the entries whose contributions are reported (the ones a test engineer signs off)
HEADLINE: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("mass", ()), ("cog", (0,)), ("cog", (1,)), ("cog", (2,)),
    ("inertia_cog", (0, 0)), ("inertia_cog", (1, 1)), ("inertia_cog", (2, 2)),
    ("stiffness", (0, 0)), ("stiffness", (1, 1)), ("stiffness", (2, 2)),
)


def contributions(var_parts: dict[str, dict[str, NDArray[np.float64]]], top: int = 3,
                  ) -> tuple[Contribution, ...]:
    """The ``top`` largest sources of each headline number's variance, largest first."""
    out: list[Contribution] = []
    for key, index in HEADLINE:
        parts = var_parts.get(key)
        if not parts:
            continue
        vals = {src: float(np.asarray(v)[index]) for src, v in parts.items()}
        total = sum(max(v, 0.0) for v in vals.values())
        if total <= 0 or not np.isfinite(total):
            continue
        name = entry_names(key)[int(np.ravel_multi_index(index, UNCERTAIN_KEYS[key]))
                                if index else 0]
        ranked = sorted(vals.items(), key=lambda kv: -kv[1])[:top]
        out += [Contribution(name, src, max(v, 0.0) / total) for src, v in ranked if v > 0]
    return tuple(out)


def combine(theta: NDArray[np.float64], K: NDArray[np.float64],
            parts: dict[str, NDArray[np.float64]], sources: tuple[str, ...],
            extra_parts: dict[str, dict[str, NDArray[np.float64]]] | None = None,
            extra_cov: NDArray[np.float64] | None = None,
            resampled: dict[str, dict[str, NDArray[np.float64]]] | None = None,
            resampled_cov: NDArray[np.float64] | None = None) -> Uncertainty:
    """:class:`Uncertainty` of independent covariance parts of ``[theta, vec K, vec C]`` plus,
    optionally, per-key variances from elsewhere (a Monte Carlo), keyed like
    :func:`variance_parts`, and that source's (82, 82) covariance ``extra_cov``.

    ``resampled`` (keyed the same) is a second estimate of the errors the fit's covariance
    already measures (the bootstrap over hits or blocks: the FRFs' noise, which the fit
    reads off its residual): per entry, the larger of the two totals is kept with its
    parts, not their sum; ``resampled_cov`` its (82, 82) covariance (the joint covariance
    then takes, per parameter, the larger variance).
    """
    vp = variance_parts(theta, K, parts)
    if resampled:
        for key, fit_parts in vp.items():
            alt = resampled.get(key)
            if not alt:
                continue
            fit_total = np.sum(list(fit_parts.values()), axis=0)
            wins = np.sum(list(alt.values()), axis=0) > fit_total
            vp[key] = {**{n: np.where(wins, 0.0, v) for n, v in fit_parts.items()},
                       **{n: np.where(wins, v, 0.0) for n, v in alt.items()}}
    for key, more in (extra_parts or {}).items():
        vp.setdefault(key, {}).update(more)
    std = {key: np.sqrt(np.clip(np.sum(list(v.values()), axis=0), 0.0, None))
           .reshape(UNCERTAIN_KEYS[key]) for key, v in vp.items()}
    std = {k: np.where(np.isfinite(v), v, np.nan) for k, v in std.items()}
    std = {k: v for k, v in std.items() if np.all(np.isfinite(v))}
    cov = np.sum(list(parts.values()), axis=0)
    if resampled_cov is not None:
        cov = _largest([cov, resampled_cov])
    if extra_cov is not None:
        cov = cov + extra_cov
    return Uncertainty(std=std, sources=sources, contributions=contributions(vp), covariance=cov)


def draw_covariance(theta: NDArray[np.float64], K: NDArray[np.float64],
                    C: NDArray[np.float64]) -> NDArray[np.float64]:
    """(82, 82) sample covariance of ``[theta, vec K, vec C]`` over draws."""
    n = theta.shape[0]
    p = np.concatenate([theta, K.reshape(n, 36), C.reshape(n, 36)], axis=1)
    return np.asarray(np.cov(p, rowvar=False))


# --- Monte Carlo draws -----------------------------------------------------------------------


def derived_of_draws(theta: NDArray[np.float64], K: NDArray[np.float64],
                     C: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
    """Every key of :data:`UNCERTAIN_KEYS` for n draws (theta (n, 10), K, C (n, 6, 6)):
    arrays (n, *shape); rigid modes nan where M is not positive definite."""
    n = theta.shape[0]
    m, h = theta[:, 0], theta[:, 1:4]
    e = np.eye(10)
    basis = np.stack([tensor_from_theta(e[p]) for p in range(10)])  # (10, 3, 3)
    JO = np.einsum("np,pij->nij", theta, basis)
    hh = np.einsum("ni,ni->n", h, h)
    Sh = hh[:, None, None] * np.eye(3)[None] - np.einsum("ni,nj->nij", h, h)
    JG = JO - Sh / m[:, None, None]
    Ms = np.einsum("np,pij->nij", theta, MASS_BASIS)
    with np.errstate(invalid="ignore"):
        lam = np.sort(np.linalg.eigvals(np.linalg.solve(Ms, 0.5 * (K + np.swapaxes(K, 1, 2))))
                      .real, axis=1)
        modes = np.sqrt(lam) / (2 * np.pi)
    return {"mass": m, "cog": h / m[:, None], "inertia_origin": JO, "inertia_cog": JG,
            "principal_moments": np.linalg.eigvalsh(JG), "stiffness": K, "damping": C,
            "rigid_modes_hz": modes.reshape(n, 6)}


def draw_variances(theta: NDArray[np.float64], K: NDArray[np.float64], C: NDArray[np.float64],
                   z: NDArray[np.float64], groups: tuple[str, ...],
                   ) -> dict[str, dict[str, NDArray[np.float64]]]:
    """Per key, the variance of each entry over the draws, split by input group.

    The split is first order: a linear regression of the draws on their perturbations
    ``z`` (n, n_in); group g gets ``sum_(i in g) beta_i^2 var(z_i)``; what the linear part
    does not explain is ``"Monte Carlo (non-linear part)"``. Parts are scaled down when
    the regression's noise makes them exceed the total.
    """
    values = derived_of_draws(theta, K, C)
    names = list(dict.fromkeys(groups))
    gidx = np.array([names.index(g) for g in groups])
    zc = z - z.mean(axis=0)
    keys = list(values)
    flat = np.concatenate([values[k].reshape(z.shape[0], -1) for k in keys], axis=1)
    ok = np.all(np.isfinite(flat), axis=0)
    yc = np.where(ok, flat, 0.0)
    yc = yc - yc.mean(axis=0)
    total = np.var(yc, axis=0, ddof=1)
    beta = np.linalg.lstsq(zc, yc, rcond=None)[0]  # (n_in, n_out)
    part = beta**2 * np.var(zc, axis=0, ddof=1)[:, None]
    per_group = np.zeros((len(names), flat.shape[1]))
    np.add.at(per_group, gidx, part)
    lin = per_group.sum(axis=0)
    shrink = np.where(lin > total, total / np.maximum(lin, 1e-300), 1.0)
    per_group *= shrink
    rest = np.clip(total - per_group.sum(axis=0), 0.0, None)
    out: dict[str, dict[str, NDArray[np.float64]]] = {}
    col = 0
    for k in keys:
        size = int(np.prod(UNCERTAIN_KEYS[k], dtype=int))
        sl = slice(col, col + size)
        col += size
        if not np.all(ok[sl]):
            out[k] = {"Monte Carlo": np.full(UNCERTAIN_KEYS[k], np.nan)}
            continue
        parts = {g: per_group[i, sl].reshape(UNCERTAIN_KEYS[k]) for i, g in enumerate(names)}
        parts["Monte Carlo (non-linear part)"] = rest[sl].reshape(UNCERTAIN_KEYS[k])
        out[k] = parts
    return out
