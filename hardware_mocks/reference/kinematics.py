"""Rigid-body kinematics and mass properties from point masses, written from first principles.

Conventions (``docs/conventions.md``): generalised coordinates at the origin O are
``q = [x, y, z, rx, ry, rz]`` (translations of O, small rotations about the global axes).
A point at ``r`` of a rigid body moves by ``u = u_O + theta x r = u_O - [r]x theta``; this
module calls ``G(r) = [I, -[r]x]`` (3 x 6) the point's rigid map. A products of inertia
``Jxy = sum m x y``; the inertia tensor holds minus the products off its diagonal.

Nothing here is shared with ``processing/``: this package is the independent reference.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "cross_matrix",
    "inertia_tensor",
    "mass_matrix_6",
    "rigid_map",
    "rotation",
    "theta_from_masses",
]


def cross_matrix(v: ArrayLike) -> NDArray[np.float64]:
    """Matrices ``[v]x`` with ``[v]x w = v x w`` for vectors ``v`` (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def rigid_map(r: ArrayLike) -> NDArray[np.float64]:
    """Rigid maps ``G(r) = [I, -[r]x]`` (..., 3, 6): displacement of the points ``r`` (..., 3), m.

    ``G(r) @ q`` is the displacement of a point at ``r`` for a rigid motion ``q`` at O;
    ``G(r).T @ f`` is the generalised force at O, ``[f; r x f]``, of a force ``f`` at ``r``.
    """
    r = np.asarray(r, dtype=float)
    eye = np.broadcast_to(np.eye(3), (*r.shape[:-1], 3, 3))
    return np.concatenate([eye, -cross_matrix(r)], axis=-1)


def rotation(rotvec: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrix of a rotation vector (axis times angle in rad), Rodrigues' formula."""
    v = np.asarray(rotvec, dtype=float).reshape(3)
    angle = float(np.linalg.norm(v))
    if angle == 0.0:
        return np.eye(3)
    k = cross_matrix(v / angle)
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def inertia_tensor(masses: ArrayLike, points: ArrayLike, about: ArrayLike = (0.0, 0.0, 0.0),
                   ) -> NDArray[np.float64]:
    """Inertia tensor (3 x 3, kg m^2) of point masses about the point ``about``.

    ``J = sum m (|r|^2 I - r r^T)`` with ``r`` measured from ``about``: moments on the
    diagonal, minus the products ``Jxy = sum m x y`` off it.
    """
    m = np.asarray(masses, dtype=float).ravel()
    r = np.asarray(points, dtype=float).reshape(-1, 3) - np.asarray(about, dtype=float)
    rr = np.einsum("n,ni,nj->ij", m, r, r)
    return np.trace(rr) * np.eye(3) - rr


def theta_from_masses(masses: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """The ten inertia parameters ``[m, m xc, m yc, m zc, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz]`` about O.

    ``Jxy = sum m x y`` etc. are the products (not the tensor's off-diagonal entries).
    """
    m = np.asarray(masses, dtype=float).ravel()
    r = np.asarray(points, dtype=float).reshape(-1, 3)
    J = inertia_tensor(m, r)
    first = m @ r
    return np.array([m.sum(), *first, J[0, 0], J[1, 1], J[2, 2], -J[0, 1], -J[0, 2], -J[1, 2]])


def mass_matrix_6(masses: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """6 x 6 rigid-body mass matrix at O, ``sum m G(r)^T G(r)`` over the point masses."""
    m = np.asarray(masses, dtype=float).ravel()
    G = rigid_map(np.asarray(points, dtype=float).reshape(-1, 3))
    return np.einsum("n,nki,nkj->ij", m, G, G)
