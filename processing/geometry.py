"""Measurement geometry: response matrix E and excitation matrix T.

Conventions (docs/conventions.md): generalised coordinates at the origin O are
``q = [x, y, z, rx, ry, rz]``. A sensor at ``r`` measuring along the unit vector
``d`` reads ``d . (a_O + alpha x r)``, i.e. the row ``d^T [I, -[r]x]`` of E. A
unit force along ``e`` at ``p`` is the generalised force ``[e; p x e]``, one
column of T.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "GeometryError",
    "GeometryReport",
    "check_geometry",
    "excitation_matrix",
    "excitation_rank",
    "response_matrix",
    "skew",
]

#: The article asks cond(T) < 20 (section 3).
DEFAULT_MAX_COND_T = 20.0
#: E is better conditioned in practice; beyond this the rigid-body fit is unreliable.
DEFAULT_MAX_COND_E = 1000.0


class GeometryError(ValueError):
    """The measurement geometry cannot identify the six rigid-body degrees of freedom."""


def skew(v: ArrayLike) -> NDArray[np.float64]:
    """Cross-product matrices ``[v]x`` of vectors ``v`` (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def _unit(dirs: ArrayLike, what: str) -> NDArray[np.float64]:
    d = np.atleast_2d(np.asarray(dirs, dtype=float))
    if d.shape[-1] != 3:
        raise GeometryError(f"{what} directions must be 3-vectors, got shape {d.shape}")
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    if not np.all(np.isfinite(d)) or np.any(n < 1e-12):
        raise GeometryError(f"{what} directions contain a zero or non-finite vector")
    return d / n


def _points(xyz: ArrayLike, n: int, what: str) -> NDArray[np.float64]:
    p = np.atleast_2d(np.asarray(xyz, dtype=float))
    if p.shape != (n, 3):
        raise GeometryError(f"{what} coordinates must have shape ({n}, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise GeometryError(f"{what} coordinates contain NaN or infinite values")
    return p


def response_matrix(xyz: ArrayLike, dirs: ArrayLike) -> NDArray[np.float64]:
    """E (n_dof, 6): rows ``d^T [I, -[r]x]`` for sensors at ``xyz`` along ``dirs``.

    Parameters
    ----------
    xyz : (n_dof, 3) array, m
        Location of each measured degree of freedom.
    dirs : (n_dof, 3) array
        Measured direction of each degree of freedom (normalised here).

    Examples
    --------
    >>> response_matrix([[0, 1, 0]], [[1, 0, 0]])  # x-acceleration 1 m along y
    array([[1., 0., 0., 0., 0., 1.]])
    """
    d = _unit(dirs, "response")
    r = _points(xyz, d.shape[0], "response")
    # d^T(-[r]x) = (r x d)^T
    return np.concatenate([d, np.cross(r, d)], axis=1)


def excitation_matrix(xyz: ArrayLike, dirs: ArrayLike) -> NDArray[np.float64]:
    """T (6, n_exc): columns ``[e; p x e]``, the generalised unit forces at O.

    Examples
    --------
    >>> excitation_matrix([[0, 1, 0]], [[1, 0, 0]]).ravel()
    array([ 1.,  0.,  0.,  0.,  0., -1.])
    """
    e = _unit(dirs, "excitation")
    p = _points(xyz, e.shape[0], "excitation")
    return np.concatenate([e, np.cross(p, e)], axis=1).T


def _scaled_cond(A: NDArray[np.float64], length: float) -> tuple[int, float]:
    """Rank and condition number of a 6-column/row matrix with rotations scaled by ``length``."""
    s = np.linalg.svd(A, compute_uv=False)
    tol = s[0] * max(A.shape) * 1e-10 if s.size and s[0] > 0 else 0.0
    rank = int(np.sum(s > tol))
    cond = float(s[0] / s[5]) if rank >= 6 else float("inf")
    return rank, cond


def excitation_rank(xyz: ArrayLike, dirs: ArrayLike) -> int:
    """Rank of the excitations' T (rotations scaled by the points' characteristic length),
    by the rule :func:`check_geometry` refuses a geometry with."""
    T = excitation_matrix(xyz, dirs)
    L = characteristic_length(xyz)
    return _scaled_cond(T / scaling(L)[:, None], L)[0]


@dataclass(frozen=True)
class GeometryReport:
    """Rank and condition of E and T, and the characteristic length used to scale rotations."""

    rank_E: int
    cond_E: float
    rank_T: int
    cond_T: float
    length: float
    ok: bool
    messages: tuple[str, ...]


def characteristic_length(*point_sets: ArrayLike) -> float:
    """RMS distance of all points from their centroid, m (at least 1 mm)."""
    pts = np.concatenate([np.atleast_2d(np.asarray(p, dtype=float)) for p in point_sets])
    c = pts.mean(axis=0)
    return float(max(np.sqrt(np.mean(np.sum((pts - c) ** 2, axis=1))), 1e-3))


def scaling(length: float) -> NDArray[np.float64]:
    """Diagonal DOF scaling ``diag(1, 1, 1, L, L, L)`` that makes rotations comparable."""
    return np.array([1.0, 1.0, 1.0, length, length, length])


def check_geometry(
    resp_xyz: ArrayLike,
    resp_dirs: ArrayLike,
    exc_xyz: ArrayLike,
    exc_dirs: ArrayLike,
    *,
    max_cond_T: float = DEFAULT_MAX_COND_T,
    max_cond_E: float = DEFAULT_MAX_COND_E,
) -> GeometryReport:
    """Check that responses and excitations span the six rigid-body DOFs.

    Condition numbers are computed with rotations scaled by the characteristic
    length of the point cloud, so they do not depend on the unit of length.
    Fatal problems (rank below 6) are reported with ``ok=False``; a high
    condition number gives a message but ``ok`` stays True.
    """
    E = response_matrix(resp_xyz, resp_dirs)
    T = excitation_matrix(exc_xyz, exc_dirs)
    L = characteristic_length(resp_xyz, exc_xyz)
    S = scaling(L)
    rank_E, cond_E = _scaled_cond(E / S, L)
    rank_T, cond_T = _scaled_cond(T / S[:, None], L)
    msgs: list[str] = []
    ok = True
    if E.shape[0] < 6 or rank_E < 6:
        ok = False
        msgs.append(
            f"response geometry has rank {rank_E} < 6 (are the response points collinear?): "
            "add triaxial response points that are not on one line"
        )
    elif cond_E > max_cond_E:
        msgs.append(f"response geometry is ill-conditioned (cond(E) = {cond_E:.0f})")
    if T.shape[1] < 6 or rank_T < 6:
        ok = False
        msgs.append(
            f"excitation geometry has rank {rank_T} < 6 ({T.shape[1]} excitations): "
            "add excitations in independent directions and points (at least 6)"
        )
    elif cond_T > max_cond_T:
        msgs.append(
            f"excitation geometry is ill-conditioned (cond(T) = {cond_T:.1f} > {max_cond_T:g})"
        )
    return GeometryReport(rank_E, cond_E, rank_T, cond_T, L, ok, tuple(msgs))
