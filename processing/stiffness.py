"""System dynamic stiffness at O (article eqs. 12-14) and its fit to K + j w C (+ j D).

``K*(w) X(w) = w^2 (M X(w) - T)``: per line, ``K*`` follows by a right
pseudo-inverse of X (eq. 14). Over a band, the real ``K``, ``C`` (viscous) and
``D`` (structural, hysteretic) of ``K* = K + j w C + j D`` are fitted directly to
these equations in the least-squares sense (optionally symmetric), from 6x6
moments of X. Which damping terms enter (:data:`DAMPING_MODELS`) is chosen from
the data by :func:`choose_damping` (docs/mounts.md).

Mounts that stiffen with frequency: ``K* = g(w) (K + j D) + j w C`` with a known
``g(w) = (w / w_k)^alpha`` (K, D then hold at ``w_k``) is the same least squares with
``g x`` for the regressor of K and D; the moments carry g (:func:`stiffness_moments`).
:func:`choose_stiffening` reads alpha from the data (docs/mounts.md).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DAMPING_BLOCKS",
    "DAMPING_MODELS",
    "DUPLICATION",
    "DampingChoice",
    "DampingModel",
    "LeakageMoments",
    "LineOperators",
    "MeanStiffness",
    "Stiffening",
    "StiffeningChoice",
    "StiffnessFit",
    "StiffnessMoments",
    "choose_damping",
    "choose_stiffening",
    "dynamic_stiffness",
    "fit_stiffness",
    "line_functions",
    "line_operators",
    "stiffening_factor",
    "stiffness_moments",
    "stiffness_normal",
    "stiffness_residual",
    "vech_index",
    "vech_normal",
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


#: the duplication matrix: vech of a symmetric 6x6 -> its vec
DUPLICATION = _duplication()

#: the damping terms of ``K* = K + j w C + j D`` a fit may hold: viscous C, structural
#: (hysteretic) D, or both
DampingModel = Literal["viscous", "hysteretic", "both"]
DAMPING_MODELS: tuple[DampingModel, ...] = ("viscous", "hysteretic", "both")
#: the unknown blocks of each model, indices into (K, C, D)
DAMPING_BLOCKS: dict[str, tuple[int, ...]] = {"viscous": (0, 1), "hysteretic": (0, 2),
                                              "both": (0, 1, 2)}


@functools.cache
def vech_index(k: int) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_],
                                NDArray[np.intp]]:
    """The duplication matrix of ``k`` stacked symmetric 6x6 blocks,
    ``kron(eye(k), DUPLICATION)``, as indices: each vech entry's first and second place in
    the vec (equal on the diagonal), whether they differ, and each vec entry's vech entry.
    Products with it are then gathers and sums of the same terms the matrix product adds."""
    iu, il = np.triu_indices(6)
    first = np.concatenate([36 * t + 6 * iu + il for t in range(k)])
    second = np.concatenate([36 * t + 6 * il + iu for t in range(k)])
    back = np.empty(36 * k, dtype=np.intp)
    back[first], back[second] = np.arange(21 * k), np.arange(21 * k)
    return first, second, first != second, back


@functools.cache
def _dup_t(k: int) -> NDArray[np.float64]:
    """``kron(eye(k), DUPLICATION).T`` (read only)."""
    out = np.asarray(np.kron(np.eye(k), DUPLICATION).T, dtype=np.float64)
    out.flags.writeable = False
    return out


def vech_normal(N: NDArray[np.float64]) -> NDArray[np.float64]:
    """``dup.T @ N @ dup`` for the duplication matrix ``dup`` of :func:`vech_index` (N
    (..., 36 k, 36 k)), the rows summed first then the columns, as the product does."""
    first, second, off, _ = vech_index(N.shape[-1] // 36)
    R = N[..., first, :] + np.where(off[:, None], N[..., second, :], 0.0)
    return np.asarray(R[..., first] + np.where(off, R[..., second], 0.0))


def stiffness_normal(G0: NDArray[np.complex128], G1: NDArray[np.complex128],
                     G2: NDArray[np.complex128], s2: NDArray[np.float64],
                     model: DampingModel) -> NDArray[np.float64]:
    """The normal matrix (..., 36 k, 36 k) of the stiffness fit of ``model``'s k blocks over
    their stacked row-major vecs, from the moments G0..G2 (..., 6, 6) of
    :class:`StiffnessMoments` (any leading axes) and the row scales ``s2``: row block i
    holds ``s2_i`` times the Gram matrix of the regressors x (K), j w x (C), j x (D)."""
    G0r, G0i, G1r, G1i = G0.real, G0.imag, G1.real, G1.imag
    full = [[G0r, -G1i, -G0i], [G1i, G2.real, G1r], [G0i, G1r, G0r]]
    b = DAMPING_BLOCKS[model]
    k = len(b)
    Nb = np.concatenate([np.concatenate([full[r][c] for c in b], axis=-1) for r in b],
                        axis=-2)
    Nb = Nb.reshape(*Nb.shape[:-2], k, 6, k, 6)
    N = np.zeros((*Nb.shape[:-4], k, 6, 6, k, 6, 6))
    for i in range(6):
        N[..., :, i, :, :, i, :] = s2[i] * Nb
    return np.asarray(N.reshape(*Nb.shape[:-4], 36 * k, 36 * k), dtype=np.float64)


@dataclass(frozen=True)
class StiffnessFit:
    """K and C (and D) at O fitted over a band, from ``n_equations`` real equations.

    ``D`` is the structural (hysteretic) damping of ``K* = K + j w C + j D`` (zero unless
    ``model`` holds it; ``C`` is zero for the ``"hysteretic"`` model).
    """

    K: NDArray[np.float64]
    C: NDArray[np.float64]
    n_equations: int
    D: NDArray[np.float64] = field(default_factory=lambda: np.zeros((6, 6)))
    model: DampingModel = "viscous"


@dataclass(frozen=True)
class StiffnessMoments:
    """6x6 moments of X over a band; with them each fit for a new M is 6x6 algebra.

    ``Gp = sum wt w^p conj(x) x^T`` and ``Qp = sum wt w^p conj(x) t^T`` over
    columns and lines, so that ``sum wt w^q conj(x) y^T = G(q+2) M^T - Q(q+2)``
    for ``y = w^2 (M x - t)``.

    With the mounts' stiffening ``g`` (:attr:`stiffened`), the moments the fit of K, C, D
    uses carry it: G0 ``g^2``, G1 ``g w``, G2 and Q2 ``g w^2`` (the right-hand side of K
    and D), G3 and Q3 ``w^3`` (that of C) and ``G2c`` ``w^2`` (C with C); Q0 and Q1 are
    then not formed (no exponential window's correction).
    """

    G0: NDArray[np.complex128]
    G1: NDArray[np.complex128]
    G2: NDArray[np.complex128]
    G3: NDArray[np.complex128]
    Q0: NDArray[np.complexfloating]
    Q1: NDArray[np.complexfloating]
    Q2: NDArray[np.complexfloating]
    Q3: NDArray[np.complexfloating]
    n_equations: int
    #: the C-with-C moment ``sum wt w^2 conj(x) x^T`` where it differs from G2 (stiffening)
    G2c: NDArray[np.complex128] | None = None
    #: solvers of the normal equations per (row scale, symmetric), filled on first use
    _solvers: dict[tuple[bytes, bool, str], NDArray[np.float64]] = field(
        default_factory=dict, compare=False, repr=False)

    @property
    def stiffened(self) -> bool:
        """The moments carry the mounts' stiffening (they have their own C-with-C moment)."""
        return self.G2c is not None

    def solver(self, s2: NDArray[np.float64], symmetric: bool,
               model: DampingModel = "viscous") -> NDArray[np.float64]:
        """Matrix S with ``[vec K; vec C] = S [vec rK; vec rC]`` (row-major vecs), the
        blocks of ``model`` (``[vec K; vec D]`` for ``"hysteretic"``, ``[.. C; .. D]`` for
        ``"both"``)."""
        key = (s2.tobytes(), symmetric, model)
        S = self._solvers.get(key)
        if S is None:
            n = len(DAMPING_BLOCKS[model])
            Nfull = stiffness_normal(self.G0, self.G1,
                                     self.G2 if self.G2c is None else self.G2c, s2, model)
            if symmetric:  # unknowns [vech K; vech C; ...] through the duplication matrix
                back = vech_index(n)[3]
                S = np.asarray(np.linalg.solve(vech_normal(Nfull), _dup_t(n))[..., back, :],
                               dtype=float)
            else:
                S = np.asarray(np.linalg.inv(Nfull), dtype=float)
            self._solvers[key] = S
        return S


def line_functions(w: NDArray[np.float64], stiffening: NDArray[np.float64] | None,
                   ) -> NDArray[np.float64]:
    """The per-line factors (5, n_l) of the moments G0..G3 and G2c of
    :class:`StiffnessMoments` (Q0..Q3 take the first four): ``1, w, w^2, w^3, w^2``, or with
    the mounts' stiffening g ``g^2, g w, g w^2, w^3, w^2``."""
    w = np.asarray(w, dtype=float)
    if stiffening is None:
        return np.stack([np.ones_like(w), w, w**2, w**3, w**2])
    g = np.asarray(stiffening, dtype=float)  # (..., n_l): one row per stiffening tried
    return np.stack(np.broadcast_arrays(g**2, g * w, g * w**2, w**3, w**2))


def stiffness_moments(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
    weights: NDArray[np.float64] | None = None,
    stiffening: NDArray[np.float64] | None = None,
) -> StiffnessMoments:
    """Moments of the stiffness equations (see :class:`StiffnessMoments`); ``stiffening``:
    the mounts' ``g(w)`` on the lines, when K and D stiffen with frequency."""
    n_e, n_l = X.shape[1:]
    wt = np.ones((n_e, n_l)) if weights is None else np.asarray(weights, float)
    Xf = X.reshape(6, -1)
    wl = np.broadcast_to(w, (n_e, n_l)).ravel()
    Tf = np.broadcast_to(T[:, :, None], X.shape).reshape(6, -1)
    Xw = np.conj(Xf) * wt.ravel() + 0j
    n_eq = 2 * 6 * n_e * n_l
    if stiffening is not None:
        F = np.broadcast_to(line_functions(w, stiffening)[:, None, :], (5, n_e, n_l))
        G = [(Xw * f.ravel()) @ Xf.T for f in F]
        Q = [(Xw * f.ravel()) @ Tf.T for f in F[:4]]
        return StiffnessMoments(G[0], G[1], G[2], G[3], Q[0], Q[1], Q[2], Q[3], n_eq, G[4])
    G, Q = [], []
    for _ in range(4):  # powers 0..3 of w
        G.append(Xw @ Xf.T)
        Q.append(Xw @ Tf.T)
        Xw = Xw * wl
    return StiffnessMoments(G[0], G[1], G[2], G[3], Q[0], Q[1], Q[2], Q[3], n_eq)


def _line_sums(X: NDArray[np.complex128], T: NDArray[np.float64],
               weights: NDArray[np.float64] | None) -> tuple[NDArray[np.complex128], ...]:
    """The moments' terms summed over the excitations, per line: ``sum wt conj(x) x^T`` and
    ``sum wt conj(x) t^T``, each (n_lines, 36) (row-major 6x6): the moments of any per-line
    factors f (:func:`line_functions`) are then ``f @`` them."""
    n_e, n_l = X.shape[1:]
    wt = np.ones((n_e, n_l)) if weights is None else np.asarray(weights, float)
    Xw = np.conj(X) * wt  # (6, n_e, n_l)
    G = np.einsum("iel,jel->lij", Xw, X).reshape(n_l, 36)
    Q = np.einsum("iel,je->lij", Xw, T + 0j).reshape(n_l, 36)
    return G, Q


@dataclass(frozen=True)
class LeakageMoments:
    """The moments of ``X - Y S`` (:func:`stiffness_moments`) for any leakage amplitudes
    ``Y`` (6, n_exc, n_s) on fixed line shapes ``S`` (n_s, n_lines): quadratic in Y, so the
    sums over the lines are formed once (:meth:`of`) and each Y costs small sums over the
    excitations (:meth:`at`).

    With ``W_p`` the p-th moment's weight per excitation and line (real), ``G_p(Y) = G_p -
    A_p Y^T - conj(A_p Y^T)^T + conj(Y) B_p Y^T`` and ``Q_p(Y) = Q_p - conj(Y) c_p T^T``,
    ``A_p = sum_l conj(x) W_p S^T`` (per excitation), ``B_p = sum_l conj(S) W_p S^T``,
    ``c_p = sum_l conj(S) W_p``.
    """

    base: StiffnessMoments
    A: NDArray[np.complex128]  # (n_G, 6, n_exc, n_s)
    B: NDArray[np.complex128]  # (n_G, n_exc, n_s, n_s)
    c: NDArray[np.complex128]  # (4, n_exc, n_s)
    T: NDArray[np.float64]

    @classmethod
    def of(cls, X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
           S: NDArray[np.complex128], weights: NDArray[np.float64] | None = None,
           stiffening: NDArray[np.float64] | None = None) -> LeakageMoments:
        n_e, n_l = X.shape[1:]
        wt = np.ones((n_e, n_l)) if weights is None else np.asarray(weights, float)
        F = line_functions(w, stiffening)[: 4 if stiffening is None else 5]
        W = wt[None] * F[:, None, :]  # (n_G, n_exc, n_lines)
        St = np.ascontiguousarray(S.T)
        A = (np.conj(X)[None] * W[:, None]) @ St
        B = (np.conj(S)[None, None] * W[:, :, None, :]) @ St
        c = (W[:4] @ np.conj(St)).astype(complex)
        return cls(stiffness_moments(X, T, w, weights, stiffening), A, B, c, T)

    def at(self, Y: NDArray[np.complex128]) -> StiffnessMoments:
        """The moments of ``X - Y S``."""
        Yc = np.conj(Y)
        cross = np.einsum("pies,jes->pij", self.A, Y)
        G = ([getattr(self.base, f"G{p}") for p in range(4)]
             + ([] if self.base.G2c is None else [self.base.G2c]))
        quad = np.einsum("iet,pejt->pij", Yc, np.einsum("pest,jet->pejs", self.B, Y))
        Gy = np.asarray(G) - cross - np.conj(cross).transpose(0, 2, 1) + quad
        Qy = (np.asarray([getattr(self.base, f"Q{p}") for p in range(4)])
              - np.einsum("ies,pes,je->pij", Yc, self.c, self.T))
        return StiffnessMoments(Gy[0], Gy[1], Gy[2], Gy[3], Qy[0], Qy[1], Qy[2], Qy[3],
                                self.base.n_equations, None if self.base.G2c is None else Gy[4])


def fit_stiffness(
    X: NDArray[np.complex128] | StiffnessMoments,
    T: NDArray[np.float64],
    w: NDArray[np.float64],
    M: NDArray[np.float64],
    *,
    weights: NDArray[np.float64] | None = None,
    row_scale: NDArray[np.float64] | None = None,
    symmetric: bool = True,
    model: DampingModel = "viscous",
    decay: float = 0.0,
) -> StiffnessFit:
    """Real K, C (, D) with ``(K + j w C + j D) X_j = w_j^2 (M X_j - T)`` over the lines given.

    With an exponential window of decay rate ``a`` (``decay``, 1/s) on the records, X is
    the accelerance at ``s = j w + a`` and the equations are ``(K + a C + j w C) X_j =
    -s_j^2 (M X_j - T)``: the same least squares with ``K + a C`` for K and the right-hand
    side's factor ``-s^2 = w^2 - a^2 - 2 j a w`` for ``w^2`` (viscous model only; the
    window's correction holds for damping analytic in s).

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
    model : the damping terms fitted (:data:`DAMPING_MODELS`): viscous C (default),
        structural D, or both; the absent one is returned as zeros
    decay : decay rate of an exponential window on the records, 1/s (0: none)
    """
    if decay and model != "viscous":
        raise ValueError(f"an exponential window's correction needs viscous damping, not {model}")
    mom = X if isinstance(X, StiffnessMoments) else stiffness_moments(X, T, w, weights)
    if decay and mom.stiffened:
        raise ValueError("an exponential window's correction is for a constant K")
    a = decay
    # sum wt w^q conj(x) (-s^2) (M x - t)^T with -s^2 = w^2 - a^2 - 2 j a w (q = 0, 1)
    G = (mom.G0, mom.G1, mom.G2, mom.G3)
    Q = (mom.Q0, mom.Q1, mom.Q2, mom.Q3)
    R0, R1 = ((G[q + 2] - a**2 * G[q] - 2j * a * G[q + 1]) @ M.T
              - (Q[q + 2] - a**2 * Q[q] - 2j * a * Q[q + 1]) for q in (0, 1))
    s2 = np.ones(6) if row_scale is None else np.asarray(row_scale, float) ** 2
    rhs = (R0.real, R1.imag, R0.imag)  # right-hand sides of K, C, D: Re of conj(regressor) y
    lead = R0.shape[:-2]  # moments of several stiffenings at once: one fit each
    r = np.concatenate([np.swapaxes(rhs[b] * s2[None, :], -1, -2).reshape(*lead, 36)
                        for b in DAMPING_BLOCKS[model]], axis=-1)
    v = (mom.solver(s2, symmetric, model) @ r[..., None])[..., 0]
    parts = [np.zeros((*lead, 6, 6))] * 3
    for k, b in enumerate(DAMPING_BLOCKS[model]):
        parts[b] = v[..., 36 * k:36 * (k + 1)].reshape(*lead, 6, 6)
    K = parts[0] - a * parts[1]  # the fit's K is K + a C with a window
    return StiffnessFit(K, parts[1], mom.n_equations, parts[2], model)


def stiffness_residual(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
    M: NDArray[np.float64], sf: StiffnessFit, *,
    weights: NDArray[np.float64] | None = None,
    row_scale: NDArray[np.float64] | None = None,
    stiffening: NDArray[np.float64] | None = None,
) -> tuple[float, float]:
    """Weighted sums of squares of ``(g (K + j D) + j w C) X_j - w_j^2 (M X_j - T)`` and of
    the right-hand side ``w_j^2 (M X_j - T)``, over the lines (the quantities
    :func:`fit_stiffness` compares), for X (6, n_exc, n_lines); g the mounts' stiffening on
    the lines (1 when omitted)."""
    Xf = X.reshape(6, -1)
    shape = X.shape
    g = 1.0 if stiffening is None else stiffening
    Y = (w**2) * ((M @ Xf).reshape(shape) - T[:, :, None])
    R = (g * ((sf.K + 1j * sf.D) @ Xf).reshape(shape) + 1j * w * (sf.C @ Xf).reshape(shape)
         - Y)
    wt = np.ones(shape[1:]) if weights is None else np.asarray(weights, float)
    s2 = np.ones(6) if row_scale is None else np.asarray(row_scale, float) ** 2
    rss = float(np.einsum("i,iel,el->", s2, np.abs(R) ** 2, wt))
    yss = float(np.einsum("i,iel,el->", s2, np.abs(Y) ** 2, wt))
    return rss, yss


@dataclass(frozen=True)
class DampingChoice:
    """The damping model chosen for ``K*`` and the evidence, in words (``reason``)."""

    model: DampingModel
    bic: dict[str, float]
    reason: str


#: relative residual below which a fit counts as exact (the BIC then compares this floor)
_RSS_FLOOR = 1e-12
#: BIC margin an alternative must gain over the viscous model (strong evidence)
_BIC_MARGIN = 10.0


def choose_damping(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
    M: NDArray[np.float64], *,
    weights: NDArray[np.float64] | None = None,
    row_scale: NDArray[np.float64] | None = None,
    symmetric: bool = True,
    moments: StiffnessMoments | None = None,
    stiffening: NDArray[np.float64] | None = None,
) -> DampingChoice:
    """Viscous C, structural D or both in ``K*``, by the Bayesian information criterion of the
    stiffness fit over the lines given.

    ``BIC = n ln(RSS / n) + p ln n`` with ``n`` the real equations of non-zero weight, ``p``
    the unknowns (21 per symmetric 6x6 block) and RSS floored at ``1e-12`` of the
    right-hand side's sum of squares (fits below it are exact to rounding and count as
    equal). The viscous model (the article's) is kept unless another's BIC is lower by
    more than 10 (strong evidence): a stiffness band too narrow to tell ``w C`` from a
    constant gives nearly equal residuals and keeps it.
    """
    mom = (moments if moments is not None
           else stiffness_moments(X, T, w, weights, stiffening))
    wt = np.ones(X.shape[1:]) if weights is None else np.asarray(weights, float)
    n = 2 * 6 * int(np.count_nonzero(wt))
    per_block = 21 if symmetric else 36
    bic: dict[str, float] = {}
    for model in DAMPING_MODELS:
        sf = fit_stiffness(mom, T, w, M, row_scale=row_scale, symmetric=symmetric, model=model)
        rss, yss = stiffness_residual(X, T, w, M, sf, weights=weights, row_scale=row_scale,
                                      stiffening=stiffening)
        rss = max(rss, _RSS_FLOOR * yss, 1e-300)
        bic[model] = n * float(np.log(rss / n)) + per_block * len(DAMPING_BLOCKS[model]) * np.log(n)
    best = min(DAMPING_MODELS, key=lambda m: bic[m])
    chosen: DampingModel = best if bic[best] < bic["viscous"] - _BIC_MARGIN else "viscous"
    names = {"viscous": "viscous C", "hysteretic": "structural D", "both": "C and D"}
    words = {"viscous": "viscous (K + jwC)", "hysteretic": "structural (K + jD)",
             "both": "viscous and structural (K + jwC + jD)"}
    others = ", ".join(f"{names[m]} {bic[m] - bic['viscous']:+.4g}"
                       for m in DAMPING_MODELS if m != "viscous")
    reason = (f"damping {words[chosen]}: BIC over the stiffness lines relative to viscous C: "
              f"{others} (another model is taken when lower by more than {_BIC_MARGIN:g})")
    return DampingChoice(chosen, bic, reason)


@dataclass(frozen=True)
class Stiffening:
    """The mounts' stiffening with frequency: ``K(w) = K (w / w_k)^alpha``, K (and D) stated
    at ``reference_hz`` = ``w_k / 2 pi``."""

    alpha: float
    reference_hz: float

    @property
    def per_decade(self) -> float:
        """Rise of K per decade of frequency (0.25: +25 %)."""
        return float(10.0**self.alpha - 1.0)

    def factor(self, w: NDArray[np.float64]) -> NDArray[np.float64]:
        """``K(w) / K`` at angular frequencies w, rad/s (held below ``reference_hz / 1000``,
        which no test's line reaches, so that K stays positive at 0 Hz)."""
        w_k = 2 * np.pi * self.reference_hz
        return np.asarray((np.maximum(np.asarray(w, dtype=float), 1e-3 * w_k) / w_k)
                          ** self.alpha, dtype=np.float64)


def stiffening_factor(stiffening: Stiffening | None, w: NDArray[np.float64],
                      ) -> NDArray[np.float64] | None:
    """``K(w) / K`` at w (rad/s) of ``stiffening``; None for a constant K (None)."""
    return None if stiffening is None else stiffening.factor(w)


@dataclass(frozen=True)
class StiffeningChoice:
    """The mounts' stiffening read from the stiffness lines (None: K constant), and why."""

    stiffening: Stiffening | None
    bic: dict[str, float]
    reason: str


#: largest rise per decade searched: a factor 2 a decade
STIFFENING_MAX = 1.0
#: least rise per decade taken: elastomer mounts rise 10-40 %; a smaller rise changes the
#: mass line's K term less than K's own uncertainty, and is what other trends on the lines
#: (an elastic mode's residual, a small error of the mass matrix) read as
STIFFENING_MIN = 0.05
#: fewest stiffness lines, and the least frequency ratio they span (half a decade: a
#: narrower span reads a slope per decade from noise), to read a stiffening from
STIFFENING_MIN_LINES, STIFFENING_MIN_SPAN = 8, 3.0


def _minimise(f: Callable[[NDArray[np.float64]], NDArray[np.float64]], bound: float,
              ) -> tuple[float, float]:
    """The minimum of a smooth f over [0, bound]: a grid of 31, a finer one of 11 around its
    least point, then the vertex of the parabola through the least point and its two
    neighbours (numpy only: scipy.optimize costs the command line 0.1 s to import). f
    takes the points of a grid at once and returns its values there."""
    coarse = np.linspace(0.0, bound, 31)
    k = int(np.argmin(f(coarse)))
    h = coarse[1] - coarse[0]
    x = np.linspace(max(coarse[k] - h, 0.0), min(coarse[k] + h, bound), 11)
    y = f(x)
    k = int(np.argmin(y))
    h = x[1] - x[0]
    if 0 < k < x.size - 1:
        a, b, c = y[k - 1], y[k], y[k + 1]
        den = a - 2 * b + c
        if den > 0:
            v = float(x[k] + 0.5 * h * (a - c) / den)
            fv = float(f(np.array([v]))[0])
            if fv < b:
                return v, fv
    return float(x[k]), float(y[k])


def choose_stiffening(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
    M: NDArray[np.float64], *,
    weights: NDArray[np.float64] | None = None,
    row_scale: NDArray[np.float64] | None = None,
    symmetric: bool = True,
    model: DampingModel = "viscous",
) -> StiffeningChoice:
    """A constant K, or one rising as ``(w / w_k)^alpha``, by the Bayesian information
    criterion of the stiffness fit over the lines given (as :func:`choose_damping`).

    ``w_k`` is the lines' weighted geometric mean frequency (the weight of a line: its
    columns' weights), where K is then stated; alpha minimises the residual of the fit with
    ``g(w) = (w / w_k)^alpha`` for K and D (a search over a rise of at most
    :data:`STIFFENING_MAX` a decade: :func:`_minimise`). The stiffening is taken when its
    BIC (one unknown more) is lower than the constant K's by more than 10 and alpha is not
    at the search's bound, and the rise is at least :data:`STIFFENING_MIN` a decade; the
    reason gives the rise found either way.

    Only a rise is searched: mounts stiffen with frequency. An apparent fall is the body's
    flexibility in series with the mounts (its elastic modes above the band soften what the
    stiffness lines show as they come nearer), which is no property of the mounts and must
    not be carried into the mass line.
    """
    wt = np.ones(X.shape[1:]) if weights is None else np.asarray(weights, float)
    line = wt.sum(axis=0)
    used = line > 0
    if np.count_nonzero(used) < STIFFENING_MIN_LINES:
        return StiffeningChoice(None, {}, f"stiffness constant over frequency: "
                                f"{np.count_nonzero(used)} stiffness lines (at least "
                                f"{STIFFENING_MIN_LINES} to read a rise from)")
    if w[used].max() < STIFFENING_MIN_SPAN * w[used].min():
        return StiffeningChoice(None, {}, "stiffness constant over frequency: the stiffness "
                                f"lines span less than {STIFFENING_MIN_SPAN:g} times in "
                                "frequency")
    w_k = float(np.exp(np.sum(line[used] * np.log(w[used])) / np.sum(line[used])))
    f_k = w_k / (2 * np.pi)

    # the moments' sums over the excitations, per line: each stiffening tried then weighs
    # the lines only
    per_line = _line_sums(X, T, weights)

    def rss(alpha: NDArray[np.float64]) -> NDArray[np.float64]:
        g = (w / w_k) ** alpha[:, None]  # (n_alpha, n_lines)
        F = line_functions(w, g)  # (5, n_alpha, n_lines)
        G, Q = F @ per_line[0], F[:4] @ per_line[1]  # (5, n_alpha, 36), (4, ...)
        G6, Q6 = G.reshape(5, -1, 6, 6), Q.reshape(4, -1, 6, 6)
        mom = StiffnessMoments(G6[0], G6[1], G6[2], G6[3], Q6[0], Q6[1], Q6[2], Q6[3],
                               2 * 6 * X.shape[1] * X.shape[2], G6[4])
        sf = fit_stiffness(mom, T, w, M, row_scale=row_scale, symmetric=symmetric, model=model)
        # the residuals one stiffening at a time: all at once would hold n_alpha copies of X
        r = [stiffness_residual(X, T, w, M, StiffnessFit(sf.K[k], sf.C[k], sf.n_equations,
                                                         sf.D[k], model),
                                weights=weights, row_scale=row_scale, stiffening=g[k])
             for k in range(alpha.size)]
        return np.array([max(rk, _RSS_FLOOR * yk, 1e-300) for rk, yk in r])

    bound = float(np.log10(1.0 + STIFFENING_MAX))
    alpha, best_rss = _minimise(rss, bound)
    n = 2 * 6 * int(np.count_nonzero(wt))
    p = (21 if symmetric else 36) * len(DAMPING_BLOCKS[model])
    bic = {"constant": n * float(np.log(rss(np.zeros(1))[0] / n)) + p * np.log(n),
           "rising": n * float(np.log(best_rss / n)) + (p + 1) * np.log(n)}
    rise = 10.0**alpha - 1.0
    gain = bic["rising"] - bic["constant"]
    span = f"{w[used].min() / (2 * np.pi):.3g}-{w[used].max() / (2 * np.pi):.3g} Hz"
    if gain < -_BIC_MARGIN and STIFFENING_MIN <= rise and alpha < 0.98 * bound:
        return StiffeningChoice(Stiffening(alpha, f_k), bic, (
            f"stiffness rising {rise:+.1%} per decade over the stiffness lines ({span}; BIC "
            f"{gain:+.4g} against a constant K): K stated at {f_k:.3g} Hz, and carried into "
            f"the mass line as K (f / {f_k:.3g} Hz)^{alpha:.4f}"))
    return StiffeningChoice(None, bic, (
        f"stiffness constant over frequency: a rise of {rise:+.1%} per decade fits the "
        f"stiffness lines ({span}) with BIC {gain:+.4g} against a constant K (taken when "
        f"lower by more than {_BIC_MARGIN:g}, a rise of {STIFFENING_MIN:.0%} to "
        f"{STIFFENING_MAX:.0%} a decade)"))
