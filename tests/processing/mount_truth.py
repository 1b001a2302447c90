"""An independent truth for the mount tests: a cuboid of point masses on inclined springs.

Nothing here comes from ``processing/``: the mass matrix is the kinetic energy of point
masses, the stiffness the potential energy of springs, both from the rigid-body velocity /
displacement field ``u(r) = u_O + theta x r`` written with ``np.cross``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


def rotation(axis: str, deg: float) -> NDArray[np.float64]:
    """Rotation matrix about a global axis (columns: the rotated x, y, z axes)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i = "xyz".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    R = np.eye(3)
    R[j, j], R[j, k], R[k, j], R[k, k] = c, -s, s, c
    return R


def point_map(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """3x6 map from q = [u_O, theta] to the displacement of point p, column by column."""
    cols = []
    for n in range(6):
        q = np.zeros(6)
        q[n] = 1.0
        cols.append(q[:3] + np.cross(q[3:], p))
    return np.array(cols).T


@dataclass(frozen=True)
class Spring:
    """One mount: position, axes (rows u, v, w), rates k (N/m) and viscous rates c (N s/m)."""

    name: str
    position: NDArray[np.float64]
    axes: NDArray[np.float64]
    k: NDArray[np.float64]
    c: NDArray[np.float64]


@dataclass(frozen=True)
class Truth:
    masses: NDArray[np.float64]  # (n,)
    points: NDArray[np.float64]  # (n, 3)
    springs: tuple[Spring, ...]

    @property
    def mass(self) -> float:
        return float(self.masses.sum())

    @property
    def cog(self) -> NDArray[np.float64]:
        return np.asarray(self.masses @ self.points / self.mass)

    @property
    def M(self) -> NDArray[np.float64]:
        """Kinetic energy 1/2 qdot^T M qdot = sum 1/2 m_i |v_i|^2."""
        M = np.zeros((6, 6))
        for m, p in zip(self.masses, self.points, strict=True):
            P = point_map(p)
            M += m * P.T @ P
        return M

    def M_about(self, c: NDArray[np.float64]) -> NDArray[np.float64]:
        """Mass matrix with the reference point at c (same axes)."""
        M = np.zeros((6, 6))
        for m, p in zip(self.masses, self.points, strict=True):
            P = point_map(p - c)
            M += m * P.T @ P
        return M

    @property
    def inertia_cog(self) -> NDArray[np.float64]:
        r = self.points - self.cog
        return np.asarray(sum(m * (x @ x * np.eye(3) - np.outer(x, x))
                              for m, x in zip(self.masses, r, strict=True)))

    def _spring_matrix(self, which: str) -> NDArray[np.float64]:
        """Potential 1/2 sum k_a (a . u(p))^2 (or the dissipation with c)."""
        S = np.zeros((6, 6))
        for s in self.springs:
            P = point_map(s.position)
            for a, k in zip(s.axes, getattr(s, which), strict=True):
                row = a @ P
                S += k * np.outer(row, row)
        return S

    @property
    def K(self) -> NDArray[np.float64]:
        return self._spring_matrix("k")

    @property
    def C(self) -> NDArray[np.float64]:
        return self._spring_matrix("c")


def cuboid_points(dims: tuple[float, float, float], corner: tuple[float, float, float],
                  n: int = 4) -> NDArray[np.float64]:
    """Centres of an n x n x n grid of equal cells filling a cuboid."""
    axes = [corner[i] + (np.arange(n) + 0.5) * dims[i] / n for i in range(3)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    return np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)


#: loss factor of every truth spring at ETA_HZ: c = eta k / (2 pi f)
ETA_HZ = 12.0


def engine_on_four_mounts() -> Truth:
    """A 120 kg cuboid (0.5 x 0.4 x 0.35 m) with an extra 20 kg lump, on four mounts
    inclined about different axes at unsymmetric places (every rate identifiable)."""
    pts = cuboid_points((0.5, 0.4, 0.35), (-0.2, -0.18, 0.02))
    masses = np.full(len(pts), 100.0 / len(pts))
    pts = np.vstack([pts, [[0.18, 0.1, 0.3]]])
    masses = np.append(masses, 20.0)
    spec = (
        ("front left", (-0.22, -0.16, -0.02), rotation("y", 25.0) @ rotation("z", 10.0),
         (3.0e5, 1.5e5, 6.0e5), 0.20),
        ("front right", (0.24, -0.17, 0.01), rotation("y", -30.0), (2.5e5, 1.2e5, 5.0e5), 0.15),
        ("rear left", (-0.19, 0.21, 0.03), rotation("x", 20.0) @ rotation("z", -15.0),
         (1.8e5, 2.2e5, 4.0e5), 0.25),
        ("rear right", (0.2, 0.18, -0.04), rotation("x", -35.0), (1.0e5, 2.0e5, 3.5e5), 0.10),
    )
    springs = []
    for name, p, R, k, eta in spec:
        k_a = np.array(k)
        springs.append(Spring(name, np.array(p), R.T, k_a, eta * k_a / (2 * np.pi * ETA_HZ)))
    return Truth(masses, pts, tuple(springs))
