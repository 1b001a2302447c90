"""Physically consistent inertia parameters (log-Cholesky of the pseudo-inertia).

The ten parameters are physically consistent iff the 4x4 pseudo-inertia matrix
``P`` is positive definite. Writing ``P = U U^T`` with ``U`` upper triangular and
its diagonal ``exp(d)`` covers exactly the consistent set with ten free
parameters, so the constrained least-squares fit is an unconstrained one in
these ten numbers (Rucker & Wensing, 2022).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from processing.inertia import from_pseudo_inertia, pseudo_inertia

__all__ = ["constrain_physical", "is_physical"]

_IU = np.triu_indices(4)
_DIAG = np.array([k for k, (i, j) in enumerate(zip(*_IU, strict=True)) if i == j])


def is_physical(theta: NDArray[np.float64]) -> bool:
    """True when the pseudo-inertia matrix is positive definite."""
    return bool(np.all(np.linalg.eigvalsh(pseudo_inertia(theta)) > 0))


def _theta_of(params: NDArray[np.float64]) -> NDArray[np.float64]:
    U = np.zeros((4, 4))
    vals = params.copy()
    vals[_DIAG] = np.exp(vals[_DIAG])
    U[_IU] = vals
    return from_pseudo_inertia(U @ U.T)


def _params_of(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    P = pseudo_inertia(theta)
    w, V = np.linalg.eigh(P)
    floor = max(1e-6 * float(np.max(np.abs(w))), 1e-12)
    P = (V * np.maximum(w, floor)) @ V.T
    # upper-triangular U with P = U U^T: flip, lower Cholesky, flip back
    J = np.eye(4)[::-1]
    L = np.linalg.cholesky(J @ P @ J)
    U = J @ L @ J
    p = U[_IU].copy()
    p[_DIAG] = np.log(p[_DIAG])
    return p


def constrain_physical(
    theta_ls: NDArray[np.float64], normal: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Closest consistent parameters in the metric of the least-squares normal matrix.

    Minimises ``(theta - theta_ls)^T N (theta - theta_ls)`` over the consistent
    set; returns ``theta_ls`` itself when it is already consistent.
    """
    if is_physical(theta_ls):
        return np.asarray(theta_ls, dtype=float)
    import scipy.optimize  # 0.1 s to import; a physical estimate never needs it

    Nsym = 0.5 * (normal + normal.T)
    w, V = np.linalg.eigh(Nsym)
    Lt = (V * np.sqrt(np.clip(w, 1e-300, None))).T  # Lt^T Lt = N

    def resid(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(Lt @ (_theta_of(p) - theta_ls))

    sol = scipy.optimize.least_squares(resid, _params_of(theta_ls), method="lm", xtol=1e-14,
                                       ftol=1e-14, gtol=1e-14, max_nfev=2000)
    # the optimum lies on the boundary (a singular pseudo-inertia); step just inside it
    P = pseudo_inertia(_theta_of(sol.x))
    P += 1e-9 * float(np.max(np.linalg.eigvalsh(P))) * np.eye(4)
    return from_pseudo_inertia(P)
