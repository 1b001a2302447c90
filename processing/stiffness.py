"""System dynamic stiffness at O (article eqs. 12-14) and its fit to K + j w C.

``K*(w) X(w) = w^2 (M X(w) - T)``: per line, ``K*`` follows by a right
pseudo-inverse of X (eq. 14). Over a band, the real ``K`` and ``C`` of
``K* = K + j w C`` are fitted directly to these equations in the
least-squares sense (optionally symmetric), from 6x6 moments of X.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "LineOperators",
    "MeanStiffness",
    "StiffnessFit",
    "StiffnessMoments",
    "dynamic_stiffness",
    "fit_stiffness",
    "line_operators",
    "stiffness_moments",
]


@dataclass(frozen=True)
class LineOperators:
    """Per-line operators of eq. 14: ``K*_j = w_j^2 (M - B_j)`` for any mass matrix M.

    ``B_j = T X_j^+`` is the apparent mass of line j, with the least-squares right
    inverse ``X^+ = X^H (X X^H)^-1`` (so ``X_j X_j^+ = I``); (n_lines, 6, 6)
    complex. ``w`` in rad/s.
    """

    B: NDArray[np.complex128]
    w: NDArray[np.float64]

    def stiffness(self, M: NDArray[np.float64]) -> NDArray[np.complex128]:
        """K*(w) per line (n_lines, 6, 6) for the mass matrix M."""
        return (self.w**2)[:, None, None] * (M[None] - self.B)

    def mean_kc(self, lines: NDArray[np.bool_] | None = None) -> MeanStiffness:
        """The article's K and C (mean over lines of Re K*_j and Im K*_j / w_j), as a map of M."""
        sel = slice(None) if lines is None else lines
        w, B = self.w[sel], self.B[sel]
        return MeanStiffness(
            float(np.mean(w**2)),
            np.mean((w**2)[:, None, None] * B.real, axis=0),
            -np.mean(w[:, None, None] * B.imag, axis=0),
        )


@dataclass(frozen=True)
class MeanStiffness:
    """``K = w2 M - KB`` and ``C`` (independent of M): the line average of eq. 14."""

    w2: float
    KB: NDArray[np.float64]
    C: NDArray[np.float64]

    def __call__(self, M: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return self.w2 * M - self.KB, self.C


def line_operators(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64]
) -> LineOperators:
    """:class:`LineOperators` of X (6, n_exc, n_lines) and T (6, n_exc), w (n_lines,) rad/s."""
    Xl = np.moveaxis(X, -1, 0)  # (n_l, 6, n_e)
    Xh = np.conj(np.swapaxes(Xl, 1, 2))
    G = Xl @ Xh  # X X^H (n_l, 6, 6), Hermitian
    # B = T X^H G^-1: solve G^T B^T = (T X^H)^T
    try:
        B = np.swapaxes(np.linalg.solve(np.swapaxes(G, 1, 2), np.swapaxes(T[None] @ Xh, 1, 2)),
                        1, 2)
    except np.linalg.LinAlgError:  # X of rank < 6 on some line (e.g. zero above a filter)
        B = T[None] @ np.linalg.pinv(Xl)
    return LineOperators(B, np.asarray(w, dtype=float))


def dynamic_stiffness(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
    M: NDArray[np.float64],
) -> NDArray[np.complex128]:
    """Complex dynamic stiffness K*(w) per line, (n_lines, 6, 6) (eq. 14).

    Uses the least-squares right inverse ``X^H (X X^H)^-1`` (the article writes
    the plain transpose; both are exact on noise-free data, this one is the
    least-squares solution on noisy data).

    Parameters
    ----------
    X : (6, n_exc, n_lines) rigid-body accelerances at O
    T : (6, n_exc) generalised unit forces
    w : (n_lines,) rad/s
    M : (6, 6) mass matrix at O
    """
    return line_operators(X, T, w).stiffness(M)


def _duplication() -> NDArray[np.float64]:
    """vec (row-major) of a symmetric 6x6 from its 21 upper-triangle entries."""
    iu = np.triu_indices(6)
    D = np.zeros((36, 21))
    for n, (i, j) in enumerate(zip(*iu, strict=True)):
        D[6 * i + j, n] = 1.0
        D[6 * j + i, n] = 1.0
    return D


_DUP = _duplication()
_DUP2 = np.zeros((72, 42))
_DUP2[:36, :21] = _DUP
_DUP2[36:, 21:] = _DUP


@dataclass(frozen=True)
class StiffnessFit:
    """K and C at O fitted over a band, from ``n_equations`` real equations."""

    K: NDArray[np.float64]
    C: NDArray[np.float64]
    n_equations: int


@dataclass(frozen=True)
class StiffnessMoments:
    """6x6 moments of X over a band; with them each fit for a new M is 6x6 algebra.

    ``Gp = sum wt w^p conj(x) x^T`` and ``Qp = sum wt w^p conj(x) t^T`` over
    columns and lines, so that ``sum wt w^q conj(x) y^T = G(q+2) M^T - Q(q+2)``
    for ``y = w^2 (M x - t)``.
    """

    G0: NDArray[np.complex128]
    G1: NDArray[np.complex128]
    G2: NDArray[np.complex128]
    G3: NDArray[np.complex128]
    Q2: NDArray[np.complexfloating]
    Q3: NDArray[np.complexfloating]
    n_equations: int
    #: solvers of the normal equations per (row scale, symmetric), filled on first use
    _solvers: dict[tuple[bytes, bool], NDArray[np.float64]] = field(
        default_factory=dict, compare=False, repr=False)

    def solver(self, s2: NDArray[np.float64], symmetric: bool) -> NDArray[np.float64]:
        """Matrix S with ``[vec K; vec C] = S [vec rK; vec rC]`` (row-major vecs)."""
        key = (s2.tobytes(), symmetric)
        S = self._solvers.get(key)
        if S is None:
            Nb = np.block([[self.G0.real, -self.G1.imag], [self.G1.imag, self.G2.real]])
            # full normal matrix over [vec K; vec C] (row-major): row blocks s2_i * Nb
            Nfull = np.einsum("i,ij,taub->tiaujb", s2, np.eye(6), Nb.reshape(2, 6, 2, 6))
            Nfull = Nfull.reshape(72, 72)
            if symmetric:  # unknowns [vech K; vech C] through the duplication matrix
                S = _DUP2 @ np.linalg.solve(_DUP2.T @ Nfull @ _DUP2, _DUP2.T)
            else:
                S = np.linalg.inv(Nfull)
            self._solvers[key] = S
        return S


def stiffness_moments(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
    weights: NDArray[np.float64] | None = None,
) -> StiffnessMoments:
    """Moments of the stiffness equations (see :class:`StiffnessMoments`)."""
    n_e, n_l = X.shape[1:]
    wt = np.ones((n_e, n_l)) if weights is None else np.asarray(weights, float)
    Xf = X.reshape(6, -1)
    wl = np.broadcast_to(w, (n_e, n_l)).ravel()
    Tf = np.broadcast_to(T[:, :, None], X.shape).reshape(6, -1)
    Xw = np.conj(Xf) * wt.ravel()
    G = []
    for _ in range(4):  # powers 0..3 of w
        G.append(Xw @ Xf.T)
        Xw = Xw * wl
    Xw2 = np.conj(Xf) * (wt.ravel() * wl**2) + 0j
    return StiffnessMoments(G[0], G[1], G[2], G[3], Xw2 @ Tf.T, (Xw2 * wl) @ Tf.T,
                            2 * 6 * n_e * n_l)


def fit_stiffness(
    X: NDArray[np.complex128] | StiffnessMoments,
    T: NDArray[np.float64],
    w: NDArray[np.float64],
    M: NDArray[np.float64],
    *,
    weights: NDArray[np.float64] | None = None,
    row_scale: NDArray[np.float64] | None = None,
    symmetric: bool = True,
) -> StiffnessFit:
    """Real K, C with ``(K + j w C) X_j = w_j^2 (M X_j - T)`` over the lines given.

    Parameters
    ----------
    X : (6, n_exc, n_lines) complex rigid-body accelerances at O, or their
        precomputed :class:`StiffnessMoments` (then ``T``, ``w``, ``weights`` unused)
    T : (6, n_exc) generalised unit forces
    w : (n_lines,) rad/s
    M : (6, 6) identified mass matrix at O
    weights : (n_exc, n_lines), optional non-negative weights
    row_scale : (6,), optional scale of each equation row
    symmetric : fit symmetric K and C (21 + 21 unknowns) instead of general 36 + 36
    """
    mom = X if isinstance(X, StiffnessMoments) else stiffness_moments(X, T, w, weights)
    R0 = mom.G2 @ M.T - mom.Q2  # (a, i)
    R1 = mom.G3 @ M.T - mom.Q3
    s2 = np.ones(6) if row_scale is None else np.asarray(row_scale, float) ** 2
    rK = R0.real * s2[None, :]  # (a, i)
    rC = R1.imag * s2[None, :]
    v = mom.solver(s2, symmetric) @ np.concatenate([rK.T.ravel(), rC.T.ravel()])
    return StiffnessFit(v[:36].reshape(6, 6), v[36:].reshape(6, 6), mom.n_equations)
