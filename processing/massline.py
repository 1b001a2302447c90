"""Inertia parameters from the mass line (article eqs. 7-11), computed from moments.

For the lines ``j`` of the mass band the equations ``M(theta) X_j = B_j`` with
``B_j = T + K*_j X_j / w_j^2`` are solved for theta in the least-squares sense,
real and imaginary parts stacked as in eq. (8). Because ``M`` is linear in
theta, ``M = sum_p theta_p M_p``, the 10x10 normal equations only need the 6x6
moments ``G = sum x x^T`` and ``W = sum b x^T`` of the stacked columns: the
system is never stacked into a (12 n r) x 10 matrix.

Elastic leakage: columns of the residual along given frequency shapes (a
mode's ``-w^2 / (w_e^2 - w^2 + 2 j zeta w_e w)``, or ``w^2``) are free
(one real coefficient per equation entry and shape) and eliminated by
projection before the moments are formed (variable projection).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from processing.inertia import MASS_BASIS, mass_matrix

__all__ = ["MassLineFit", "MassLineProblem", "fit_inertia", "stack_real"]


def stack_real(Z: NDArray[np.complexfloating]) -> NDArray[np.float64]:
    """Real and imaginary parts stacked along the last (frequency) axis."""
    return np.concatenate([Z.real, Z.imag], axis=-1)


@dataclass(frozen=True)
class MassLineFit:
    """Result of one mass-line least-squares solve."""

    theta: NDArray[np.float64]
    #: normal matrix of the (scaled) problem, 10x10
    normal: NDArray[np.float64]
    #: number of real equations
    n_equations: int
    #: leakage coefficients (6, n_exc, n_shapes): the fitted ``Z`` of ``M X + Z b = B``
    leakage: NDArray[np.float64] | None


def _project(A: NDArray[np.float64], Q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Component of A (6, n_e, m) along the per-column orthonormal bases Q (n_e, m, s)."""
    At = np.swapaxes(A, 0, 1)  # (n_e, 6, m)
    P = (At @ Q) @ np.swapaxes(Q, 1, 2)
    return np.swapaxes(P, 0, 1)


class MassLineProblem:
    """The mass-line least-squares problem for fixed accelerances X, solved for many B.

    Everything that depends on X only (weights, leakage projection, the 10x10
    normal matrix and its factorisation) is computed once here; each
    :meth:`solve` then costs one (6 x 2 n_exc n_lines) by (.. x 6) product, and
    :meth:`solve_kc` (the iteration's right-hand side ``T + (K + j w C + j D) Xc / w^2``)
    only 6x6 algebra once the moments of ``Xc`` are known.

    Parameters
    ----------
    X : (6, n_exc, n_lines) complex
        Rigid-body accelerances at O (eq. 6) on the selected lines, (m/s^2)/N.
    weights : (n_exc, n_lines), optional
        Non-negative weight of each column and line (0 drops it).
    row_scale : (6,), optional
        Scale of each equation row (e.g. ``1/L`` for the moment equations).
    shapes : (n_shapes, 2 n_lines), optional
        Real-stacked frequency shapes of free leakage terms (see :func:`stack_real`).
    """

    def __init__(
        self,
        X: NDArray[np.complex128],
        *,
        weights: NDArray[np.float64] | None = None,
        row_scale: NDArray[np.float64] | None = None,
        shapes: NDArray[np.float64] | None = None,
    ) -> None:
        n6, n_e, n_l = X.shape
        self.X = X
        self.shape = X.shape
        self.weights = weights
        #: indices of the given shapes kept (the others depend on them over these lines)
        self.shape_index = (np.zeros(0, int) if shapes is None or not len(shapes)
                            else _independent(np.asarray(shapes, float)))
        self.shapes = (None if shapes is None or not len(shapes)
                       else np.asarray(shapes, float)[self.shape_index])
        self.n_equations = 2 * n6 * n_e * n_l
        Xr = stack_real(X)
        self._sw = (np.sqrt(np.concatenate([weights, weights], axis=-1))
                    if weights is not None else None)
        if self._sw is not None:
            Xr = Xr * self._sw
        self._Q: NDArray[np.float64] | None = None
        if self.shapes is not None:
            # per-column weighted shapes (n_e, 2 n_l, n_s), orthonormalised per column
            Sw = self.shapes.T[None, :, :] * (self._sw[:, :, None] if self._sw is not None
                                              else 1.0)
            Sw = np.broadcast_to(Sw, (n_e, *self.shapes.T.shape))
            self._Q, _ = np.linalg.qr(Sw)
            Xr = Xr - _project(Xr, self._Q)
        # B enters only through W = sum Bw Xp^T: the projection is symmetric and idempotent,
        # so B needs no projection of its own
        self._Xp = Xr.reshape(6, -1)
        self._row_scale = None if row_scale is None else np.asarray(row_scale, float)
        s2 = np.ones(6) if row_scale is None else np.asarray(row_scale, float) ** 2
        G = self._Xp @ self._Xp.T
        self._MBs = (MASS_BASIS * s2[None, :, None]).reshape(10, 36)
        self.normal = (_normal_operator_cached(s2) @ G.ravel()).reshape(10, 10)
        # theta = N^-1 MBs vec(W): the (10, 36) operator is formed once
        try:
            factor = scipy.linalg.cho_factor(self.normal, check_finite=False)
            self._solver = scipy.linalg.cho_solve(factor, self._MBs, check_finite=False)
        except np.linalg.LinAlgError:  # singular: the minimum-norm solution
            self._solver = np.linalg.pinv(self.normal) @ self._MBs
        self._kc_key: tuple[object, object] | None = None
        self._kc: tuple[NDArray[np.float64], ...] | None = None

    def _weighted(self, Z: NDArray[np.complexfloating]) -> NDArray[np.float64]:
        """Real-stacked, weighted (6, n_e * 2 n_l) form of Z (6, n_e, n_l)."""
        Zr = stack_real(np.broadcast_to(Z, self.shape))
        if self._sw is not None:
            Zr = Zr * self._sw
        return Zr.reshape(6, -1)

    def _finish(self, W: NDArray[np.float64], B: NDArray[np.complexfloating] | None) -> MassLineFit:
        theta = self._solver @ W.ravel()
        leakage = None
        if self._Q is not None and self.shapes is not None and B is not None:
            leakage = self._leakage(theta, B)
        return MassLineFit(theta, self.normal, self.n_equations, leakage)

    @functools.cached_property
    def _leakage_operators(self) -> tuple[NDArray[np.float64], NDArray[np.float64] | None,
                                          NDArray[np.float64]]:
        """What :meth:`_leakage` needs that does not depend on theta: the stacked X, the
        line weights (n_e, 2 n_l) and each column's normal matrix of the shapes."""
        assert self.shapes is not None
        Sh, n_e = self.shapes, self.shape[1]
        wf = (np.concatenate([self.weights, self.weights], axis=-1)
              if self.weights is not None else None)
        A = (np.einsum("sl,kl,tl->kst", Sh, wf, Sh) if wf is not None
             else np.broadcast_to(Sh @ Sh.T, (n_e, Sh.shape[0], Sh.shape[0])))
        return stack_real(self.X), wf, A

    def _leakage(self, theta: NDArray[np.float64], B: NDArray[np.complexfloating]) -> (
        NDArray[np.float64]
    ):
        """Leakage coefficients: ``Z b`` = projection of ``B - M X`` on the shapes, per column."""
        assert self.shapes is not None
        M = mass_matrix(theta)
        Sh = self.shapes
        Xs, wf, A = self._leakage_operators
        Bs = stack_real(np.broadcast_to(B, self.shape))
        R = Bs - (M @ Xs.reshape(6, -1)).reshape(Xs.shape)  # (6, n_e, 2 n_l) unweighted
        r = (np.einsum("ikl,kl,sl->iks", R, wf, Sh) if wf is not None
             else np.einsum("ikl,sl->iks", R, Sh))
        return np.asarray(np.linalg.solve(A[None], r[..., None])[..., 0])

    def residual_ss(self, theta: NDArray[np.float64], B: NDArray[np.complexfloating]) -> float:
        """Weighted, row-scaled sum of squares of ``B - M(theta) X`` left after the leakage
        shapes (the quantity the least squares minimises)."""
        n_e = self.shape[1]
        Bw = self._weighted(B).reshape(6, n_e, -1)
        if self._Q is not None:
            Bw = Bw - _project(Bw, self._Q)
        R = Bw.reshape(6, -1) - mass_matrix(theta) @ self._Xp
        s2 = np.ones(6) if self._row_scale is None else self._row_scale**2
        return float(np.sum(s2 * np.sum(R * R, axis=1)))

    def stacked(self, Z: NDArray[np.complexfloating], *, project: bool) -> NDArray[np.float64]:
        """Z (n, n_exc, n_lines) real-stacked and weighted as the equations are, (n, n_exc,
        2 n_lines); with ``project`` also without its components along the leakage shapes."""
        Zr = stack_real(Z)
        if self._sw is not None:
            Zr = Zr * self._sw
        if project and self._Q is not None:
            Zr = Zr - _project(Zr, self._Q)
        return np.asarray(Zr)

    def column_normals(self) -> NDArray[np.float64]:
        """The normal matrix's share of each excitation column, (n_exc, 10, 10) (they sum to
        :attr:`normal`)."""
        n_e = self.shape[1]
        Xk = self._Xp.reshape(6, n_e, -1)
        G = np.einsum("akc,bkc->kab", Xk, Xk)
        s2 = np.ones(6) if self._row_scale is None else self._row_scale**2
        return np.asarray((_normal_operator_cached(s2) @ G.reshape(n_e, 36).T).T
                          .reshape(n_e, 10, 10))

    @property
    def n_free(self) -> int:
        """Unknowns of the fit: the ten parameters and the free leakage coefficients (one per
        equation row, excitation column and kept shape)."""
        n_s = 0 if self.shapes is None else self.shapes.shape[0]
        return 10 + 6 * self.shape[1] * n_s

    def line_scores(self, theta: NDArray[np.float64], B: NDArray[np.complexfloating]) -> (
        NDArray[np.float64]
    ):
        """Gradient terms of the least squares at theta per excitation column and line,
        (10, n_exc, n_lines).

        Entry (p, k, j) is ``sum_c a_pc r_c`` over the (weighted, row-scaled, projected)
        equations c of column k on line j (real and imaginary parts), with ``a_p = M_p X``
        the regressor of parameter p and ``r = B - M(theta) X`` the residual: they sum to
        zero at the solution, and their scatter over lines and columns is what a
        heteroscedasticity- and correlation-robust (sandwich) covariance needs.
        """
        n_e, n_l = self.shape[1], self.shape[2]
        Bw = self._weighted(B).reshape(6, n_e, -1)
        if self._Q is not None:
            Bw = Bw - _project(Bw, self._Q)
        R = Bw.reshape(6, -1) - mass_matrix(theta) @ self._Xp  # (6, n_cols)
        # sum_i s2_i (M_p Xp)_ic R_ic = sum_ia MBs_p[i, a] R_ic Xp_ac
        MBs = self._MBs.reshape(10, 6, 6)
        per_col = np.einsum("pia,ic,ac->pc", MBs, R, self._Xp, optimize=True)
        return np.asarray(per_col.reshape(10, n_e, 2, n_l).sum(axis=2))

    def solve(self, B: NDArray[np.complexfloating]) -> MassLineFit:
        """Ten parameters from ``M(theta) X_j (+ Z b_j) = B_j``, B broadcastable to X."""
        return self._finish(self._weighted(B) @ self._Xp.T, B)

    def solve_kc(
        self,
        T: NDArray[np.float64],
        K: NDArray[np.float64],
        C: NDArray[np.float64],
        Xc: NDArray[np.complex128],
        w: NDArray[np.float64],
        D: NDArray[np.float64] | None = None,
        stiffening: NDArray[np.float64] | None = None,
    ) -> MassLineFit:
        """:meth:`solve` for ``B = T + (g(w) (K + j D) + j w C) Xc / w^2`` (the iteration of
        section 2.2; ``D`` the structural damping, none when omitted; ``stiffening`` the
        mounts' ``g(w) = K(w) / K`` on these lines, 1 when omitted).

        The moments of ``Xc`` are kept while the same arrays are passed again, so
        each further iteration is 6x6 algebra.
        """
        g = 1.0 if stiffening is None else stiffening
        if self._Q is not None:  # leakage coefficients need B itself
            Xf = Xc.reshape(6, -1)
            KD = K if D is None else K + 1j * D
            KX = g * (KD @ Xf).reshape(Xc.shape) + 1j * w * (C @ Xf).reshape(Xc.shape)
            return self.solve(T[:, :, None] + KX / w**2)
        if (self._kc_key is None or self._kc_key[0] is not Xc
                or self._kc_key[1] is not stiffening or self._kc is None):
            WT = self._weighted(T[:, :, None] + 0j) @ self._Xp.T
            P2 = self._weighted(Xc * (g / w**2)) @ self._Xp.T
            P1 = self._weighted(1j * Xc / w) @ self._Xp.T
            P0 = self._weighted(1j * Xc * (g / w**2)) @ self._Xp.T
            self._kc_key, self._kc = (Xc, stiffening), (WT, P2, P1, P0)
        WT, P2, P1, P0 = self._kc
        W = WT + K @ P2 + C @ P1
        return self._finish(W if D is None else W + D @ P0, None)


    def fixed_point_affine(
        self,
        T: NDArray[np.float64],
        w2: float,
        KB: NDArray[np.float64],
        C: NDArray[np.float64],
        w: NDArray[np.float64],
    ) -> MassLineFit:
        """The limit of ``theta -> solve_kc(T, w2 M(theta) - KB, C, X, w)``, solved directly.

        With the article's stiffness step (eq. 14 averaged over lines), K is affine in
        M and C does not depend on it, so the iteration of section 2.2 is an affine
        map of theta whose fixed point is one 10x10 solve. No leakage shapes.
        """
        if self._Q is not None:
            raise ValueError("fixed_point_affine is for problems without leakage shapes")
        self.solve_kc(T, np.zeros((6, 6)), np.zeros((6, 6)), self.X, w)  # moments of X
        assert self._kc is not None
        WT, P2, P1, _ = self._kc
        a = self._solver @ (WT - KB @ P2 + C @ P1).ravel()
        J = w2 * (self._solver @ (MASS_BASIS @ P2).reshape(10, 36).T)
        theta = np.linalg.solve(np.eye(10) - J, a)
        return MassLineFit(theta, self.normal, self.n_equations, None)


def _independent(shapes: NDArray[np.float64], rtol: float = 1e-3) -> NDArray[np.int64]:
    """Indices of the shapes (rows) independent of the ones before them over these lines.

    A shape is dropped when, with the kept ones, the smallest singular value of the
    normalised set falls under ``rtol`` times the largest (about: it lies within
    ``rtol`` radians of their span). Modes far above the mass line and the ``w^2``
    term are nearly one shape there; keeping them all makes the leakage
    coefficients, hence the cleaned accelerances, blow up.
    """
    keep: list[int] = []
    for k in range(shapes.shape[0]):
        trial = shapes[[*keep, k]]
        s = np.linalg.svd(trial / np.linalg.norm(trial, axis=1, keepdims=True),
                          compute_uv=False)
        if s[-1] > rtol * s[0]:
            keep.append(k)
    return np.array(keep, dtype=np.int64)


def _normal_operator(s2: NDArray[np.float64]) -> NDArray[np.float64]:
    """(100, 36) map from vec(G) to the 10x10 normal matrix for row scales s2."""
    MB = MASS_BASIS
    return np.einsum("pia,qib->pqab", MB * s2[None, :, None], MB).reshape(100, 36)


_NORMAL_CACHE: dict[bytes, NDArray[np.float64]] = {}


def _normal_operator_cached(s2: NDArray[np.float64]) -> NDArray[np.float64]:
    key = s2.tobytes()
    op = _NORMAL_CACHE.get(key)
    if op is None:
        if len(_NORMAL_CACHE) > 64:
            _NORMAL_CACHE.clear()
        op = _NORMAL_CACHE[key] = _normal_operator(s2)
    return op


def fit_inertia(
    X: NDArray[np.complex128],
    B: NDArray[np.complex128],
    *,
    weights: NDArray[np.float64] | None = None,
    row_scale: NDArray[np.float64] | None = None,
    shapes: NDArray[np.float64] | None = None,
) -> MassLineFit:
    """Least-squares ten parameters from ``M(theta) X_j (+ Z b_j) = B_j`` (one solve).

    Parameters as :class:`MassLineProblem`; ``B`` (6, n_exc, n_lines) complex
    right-hand sides ``T + K*_j X_j / w_j^2`` (eq. 8), broadcastable.
    """
    return MassLineProblem(X, weights=weights, row_scale=row_scale, shapes=shapes).solve(B)
