"""The ten rigid-body inertia parameters and the 6x6 mass matrix at O.

``theta = [m, m xc, m yc, m zc, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz]`` with the inertia
about O; tensor convention of the article's eq. (2):
``J = [[Jxx, -Jxy, -Jxz], [-Jxy, Jyy, -Jyz], [-Jxz, -Jyz, Jzz]]``, products
``Jxy = integral of x y dm``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.geometry import skew

__all__ = [
    "MASS_BASIS",
    "InertiaProperties",
    "from_pseudo_inertia",
    "inertia_properties",
    "mass_matrix",
    "pseudo_inertia",
    "tensor_from_theta",
    "theta_from_body",
]


def _basis() -> NDArray[np.float64]:
    B = np.zeros((10, 6, 6))
    B[0, :3, :3] = np.eye(3)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        S = skew(e)
        B[1 + k, :3, 3:] = -S
        B[1 + k, 3:, :3] = S
    for k in range(3):
        B[4 + k, 3 + k, 3 + k] = 1.0
    for n, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
        B[7 + n, 3 + i, 3 + j] = -1.0
        B[7 + n, 3 + j, 3 + i] = -1.0
    return B


#: M(theta) = sum_p theta_p MASS_BASIS[p]; shape (10, 6, 6).
MASS_BASIS: NDArray[np.float64] = _basis()
MASS_BASIS.setflags(write=False)
_BASIS_FLAT = MASS_BASIS.reshape(10, 36)


def mass_matrix(theta: ArrayLike) -> NDArray[np.float64]:
    """6x6 mass matrix at O (article eq. 2) from the ten parameters.

    Examples
    --------
    >>> M = mass_matrix([2.0, 0, 0, 0, 1, 1, 1, 0, 0, 0])
    >>> M[0, 0], M[3, 3]
    (np.float64(2.0), np.float64(1.0))
    """
    return (np.asarray(theta, dtype=float) @ _BASIS_FLAT).reshape(6, 6)


def tensor_from_theta(theta: ArrayLike) -> NDArray[np.float64]:
    """3x3 inertia tensor about O (diagonal moments, off-diagonal minus products)."""
    t = np.asarray(theta, dtype=float)
    Jxx, Jyy, Jzz, Jxy, Jxz, Jyz = t[4:10]
    return np.array([[Jxx, -Jxy, -Jxz], [-Jxy, Jyy, -Jyz], [-Jxz, -Jyz, Jzz]])


def theta_from_body(mass: float, cog: ArrayLike, inertia_cog: ArrayLike) -> NDArray[np.float64]:
    """Ten parameters about O from mass, CoG (m) and the tensor about the CoG (kg m^2)."""
    c = np.asarray(cog, dtype=float)
    JG = np.asarray(inertia_cog, dtype=float)
    JO = JG + mass * (c @ c * np.eye(3) - np.outer(c, c))
    return np.array(
        [mass, *(mass * c), JO[0, 0], JO[1, 1], JO[2, 2], -JO[0, 1], -JO[0, 2], -JO[1, 2]]
    )


def pseudo_inertia(theta: ArrayLike) -> NDArray[np.float64]:
    """4x4 pseudo-inertia matrix ``[[Sigma, h], [h^T, m]]`` (Wensing et al., 2017).

    ``Sigma = tr(J)/2 I - J`` is the second moment of the mass distribution about
    O. The parameters are physically consistent iff this matrix is positive
    definite, which implies a positive mass, a positive-definite tensor and the
    strict triangle inequality of the principal moments.
    """
    t = np.asarray(theta, dtype=float)
    J = tensor_from_theta(t)
    P = np.empty((4, 4))
    P[:3, :3] = 0.5 * np.trace(J) * np.eye(3) - J
    P[:3, 3] = P[3, :3] = t[1:4]
    P[3, 3] = t[0]
    return P


def from_pseudo_inertia(P: ArrayLike) -> NDArray[np.float64]:
    """Inverse of :func:`pseudo_inertia`."""
    P = np.asarray(P, dtype=float)
    Sigma = P[:3, :3]
    J = np.trace(Sigma) * np.eye(3) - Sigma
    return np.array(
        [P[3, 3], *P[:3, 3], J[0, 0], J[1, 1], J[2, 2], -J[0, 1], -J[0, 2], -J[1, 2]]
    )


@dataclass(frozen=True)
class InertiaProperties:
    """Derived inertia results. Lengths in m, moments in kg m^2."""

    mass: float
    cog: NDArray[np.float64]
    inertia_origin: NDArray[np.float64]
    inertia_cog: NDArray[np.float64]
    principal_moments: NDArray[np.float64]
    principal_axes: NDArray[np.float64]
    positive_definite: bool
    triangle_inequality: bool
    #: min over permutations of (J1 + J2 - J3) / J3; negative when the inequality is broken
    triangle_margin: float

    @property
    def physically_consistent(self) -> bool:
        return self.mass > 0 and self.positive_definite and self.triangle_inequality


def inertia_properties(theta: ArrayLike) -> InertiaProperties:
    """Mass, CoG, tensors about O and the CoG, principal moments/axes and consistency checks."""
    t = np.asarray(theta, dtype=float)
    m = float(t[0])
    JO = tensor_from_theta(t)
    c = t[1:4] / m if m != 0 else np.full(3, np.nan)
    JG = JO - m * (c @ c * np.eye(3) - np.outer(c, c))
    if np.all(np.isfinite(JG)):
        w, V = np.linalg.eigh(JG)
        # deterministic sign: largest component of each axis positive
        idx = np.argmax(np.abs(V), axis=0)
        V = V * np.sign(V[idx, np.arange(3)])
    else:
        w, V = np.full(3, np.nan), np.full((3, 3), np.nan)
    pd = bool(np.all(w > 0))
    margin = float((w[0] + w[1] - w[2]) / w[2]) if w[2] != 0 else float("nan")
    return InertiaProperties(
        mass=m,
        cog=c,
        inertia_origin=JO,
        inertia_cog=JG,
        principal_moments=w,
        principal_axes=V,
        positive_definite=pd,
        triangle_inequality=bool(margin >= 0),
        triangle_margin=margin,
    )
