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

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.inertia import MASS_BASIS

__all__ = ["MassLineFit", "fit_inertia", "stack_real"]


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


def fit_inertia(
    X: NDArray[np.complex128],
    B: NDArray[np.complex128],
    *,
    weights: NDArray[np.float64] | None = None,
    row_scale: NDArray[np.float64] | None = None,
    shapes: NDArray[np.float64] | None = None,
) -> MassLineFit:
    """Least-squares ten parameters from ``M(theta) X_j (+ Z b_j) = B_j``.

    Parameters
    ----------
    X : (6, n_exc, n_lines) complex
        Rigid-body accelerances at O (eq. 6) on the selected lines, (m/s^2)/N.
    B : (6, n_exc, n_lines) complex
        Right-hand sides ``T + K*_j X_j / w_j^2`` (eq. 8), broadcastable.
    weights : (n_exc, n_lines), optional
        Non-negative weight of each column and line (0 drops it).
    row_scale : (6,), optional
        Scale of each equation row (e.g. ``1/L`` for the moment equations).
    shapes : (n_shapes, 2 n_lines), optional
        Real-stacked frequency shapes of free leakage terms (see :func:`stack_real`).
    """
    n6, n_e, n_l = X.shape
    B = np.broadcast_to(B, X.shape)
    Xr = stack_real(X)
    Br = stack_real(B)
    if weights is not None:
        sw = np.sqrt(np.concatenate([weights, weights], axis=-1))
        Xr = Xr * sw
        Br = Br * sw
    s2 = np.ones(6) if row_scale is None else np.asarray(row_scale, float) ** 2
    Q = None
    if shapes is not None and len(shapes):
        Sh = np.asarray(shapes, float)
        # per-column weighted shapes (n_e, 2 n_l, n_s), orthonormalised per column
        Sw = Sh.T[None, :, :] * (sw[:, :, None] if weights is not None else 1.0)
        Sw = np.broadcast_to(Sw, (n_e, *Sh.T.shape))
        Q, _ = np.linalg.qr(Sw)
        Xr = Xr - _project(Xr, Q)
        Br = Br - _project(Br, Q)
    Xf = Xr.reshape(6, -1)
    Bf = Br.reshape(6, -1)
    G = Xf @ Xf.T
    W = Bf @ Xf.T
    MB = MASS_BASIS
    MBs = MB * s2[None, :, None]
    N = np.einsum("pia,qib->pqab", MBs, MB).reshape(100, 36) @ G.ravel()
    N = N.reshape(10, 10)
    rhs = MBs.reshape(10, 36) @ W.ravel()
    theta = np.linalg.solve(N, rhs)
    M = np.tensordot(theta, MB, axes=1)
    leakage = None
    if Q is not None:
        # Z b = projection of (B - M X) onto the shapes, per column; coefficients in shape basis
        Xs = stack_real(X)
        Bs = stack_real(np.broadcast_to(B, X.shape))
        R = Bs - (M @ Xs.reshape(6, -1)).reshape(Xs.shape)  # (6, n_e, 2 n_l) unweighted
        Sh = np.asarray(shapes, float)
        if weights is not None:
            wf = np.concatenate([weights, weights], axis=-1)  # (n_e, 2 n_l)
            A = np.einsum("sl,kl,tl->kst", Sh, wf, Sh)
            r = np.einsum("ikl,kl,sl->iks", R, wf, Sh)
        else:
            A = np.broadcast_to(Sh @ Sh.T, (n_e, Sh.shape[0], Sh.shape[0]))
            r = np.einsum("ikl,sl->iks", R, Sh)
        leakage = np.linalg.solve(A[None], r[..., None])[..., 0]
    n_eq = 2 * n6 * n_e * n_l
    return MassLineFit(theta, N, n_eq, leakage)
