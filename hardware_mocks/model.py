"""Physical model of the bench: a rigid body on resilient mounts plus elastic modes.

The model gives exact accelerance FRFs between any sensor (point, direction) and
any force (point, direction), exact time responses to any force history, and
its own truth: the mass, stiffness and damping matrices at O and the rigid-body
modes. Tests, the demo and the mock devices are all driven by it.

Rigid part: ``(K + j w C - w^2 M) Q = F`` at O, accelerance ``-w^2 Q``; each
mount adds ``G^T R diag(k) R^T G`` with ``G = [I, -[p]x]`` its kinematic map.
Elastic part: mass-normalised modes whose shape is a smooth quadratic field over
the body (not representable by a rigid motion), superposed modally:
``-w^2 phi_i phi_j / (w_r^2 - w^2 + 2 j zeta w_r w)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from processing.geometry import excitation_matrix, response_matrix, skew
from processing.inertia import mass_matrix, theta_from_body

__all__ = ["BodyOnMounts", "ElasticMode", "Mount", "RigidModes"]


def _vec(v: ArrayLike, n: int = 3) -> NDArray[np.float64]:
    a = np.asarray(v, dtype=float).reshape(n)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Mount:
    """A resilient mount: three stiffnesses and dampings along its local axes.

    ``axes`` holds the local axes as columns, in the global frame.
    """

    position: NDArray[np.float64]
    stiffness: NDArray[np.float64]
    damping: NDArray[np.float64]
    axes: NDArray[np.float64] = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vec(self.position))
        object.__setattr__(self, "stiffness", _vec(self.stiffness))
        object.__setattr__(self, "damping", _vec(self.damping))
        R = np.asarray(self.axes, dtype=float).reshape(3, 3)
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
            raise ValueError("mount axes must be orthonormal columns")
        object.__setattr__(self, "axes", R)

    def matrices(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """This mount's 6x6 stiffness and damping at O."""
        G = np.hstack([np.eye(3), -skew(self.position)])
        RG = self.axes.T @ G
        return RG.T @ (self.stiffness[:, None] * RG), RG.T @ (self.damping[:, None] * RG)


_QUAD = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@dataclass(frozen=True)
class ElasticMode:
    """A mass-normalised elastic mode of the body.

    The shape is ``phi(p) = coefficients @ [u^2, v^2, w^2, uv, uw, vw]`` with
    ``(u, v, w) = (p - center) / length``; ``coefficients`` (3, 6) in 1/sqrt(kg).
    """

    frequency: float
    damping: float
    coefficients: NDArray[np.float64]
    center: NDArray[np.float64]
    length: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "coefficients", np.asarray(self.coefficients, float).reshape(3, 6))
        object.__setattr__(self, "center", _vec(self.center))

    def shape(self, points: ArrayLike) -> NDArray[np.float64]:
        """Mode shape vectors (n, 3) at ``points`` (n, 3)."""
        u = (np.atleast_2d(np.asarray(points, float)) - self.center) / self.length
        mono = np.stack([u[:, i] * u[:, j] for i, j in _QUAD], axis=1)
        return np.asarray(mono @ self.coefficients.T)


@dataclass(frozen=True)
class RigidModes:
    """Undamped rigid-body modes: frequencies (Hz, ascending), modal damping ratios, shapes."""

    frequency: NDArray[np.float64]
    damping: NDArray[np.float64]
    shapes: NDArray[np.float64]


@dataclass(frozen=True)
class BodyOnMounts:
    """A rigid body (mass, CoG, inertia about the CoG) on mounts, with elastic modes."""

    mass: float
    cog: NDArray[np.float64]
    inertia_cog: NDArray[np.float64]
    mounts: tuple[Mount, ...]
    elastic_modes: tuple[ElasticMode, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "cog", _vec(self.cog))
        J = np.asarray(self.inertia_cog, dtype=float).reshape(3, 3)
        if not np.allclose(J, J.T) or np.any(np.linalg.eigvalsh(J) <= 0):
            raise ValueError("inertia tensor about the CoG must be symmetric positive definite")
        object.__setattr__(self, "inertia_cog", J)
        object.__setattr__(self, "mounts", tuple(self.mounts))
        object.__setattr__(self, "elastic_modes", tuple(self.elastic_modes))

    # --- truth ---------------------------------------------------------------------------------
    @property
    def theta(self) -> NDArray[np.float64]:
        """The ten inertia parameters about O."""
        return theta_from_body(self.mass, self.cog, self.inertia_cog)

    @property
    def M(self) -> NDArray[np.float64]:
        return mass_matrix(self.theta)

    @property
    def K(self) -> NDArray[np.float64]:
        return sum((m.matrices()[0] for m in self.mounts), np.zeros((6, 6)))

    @property
    def C(self) -> NDArray[np.float64]:
        return sum((m.matrices()[1] for m in self.mounts), np.zeros((6, 6)))

    def rigid_modes(self) -> RigidModes:
        w2, V = scipy.linalg.eigh(self.K, self.M)
        w = np.sqrt(np.clip(w2, 0.0, None))
        zeta = np.einsum("ir,ij,jr->r", V, self.C, V) / (2 * np.where(w > 0, w, np.inf))
        return RigidModes(w / (2 * np.pi), zeta, V)

    def with_elastic_modes(self, modes: tuple[ElasticMode, ...]) -> BodyOnMounts:
        return BodyOnMounts(self.mass, self.cog, self.inertia_cog, self.mounts, modes)

    # --- responses -----------------------------------------------------------------------------
    def accelerance_origin(self, freq: ArrayLike) -> NDArray[np.complex128]:
        """Rigid-body accelerance at O, (n_f, 6, 6): ``-w^2 (K + j w C - w^2 M)^-1``."""
        w = 2 * np.pi * np.asarray(freq, dtype=float)
        Z = self.K[None] + 1j * w[:, None, None] * self.C[None] - (w**2)[:, None, None] * self.M
        return -(w**2)[:, None, None] * np.linalg.inv(Z)

    def frf(
        self,
        freq: ArrayLike,
        resp_xyz: ArrayLike,
        resp_dirs: ArrayLike,
        exc_xyz: ArrayLike,
        exc_dirs: ArrayLike,
        *,
        elastic: bool = True,
    ) -> NDArray[np.complex128]:
        """Exact accelerance FRFs (n_resp, n_exc, n_f), (m/s^2)/N."""
        freq = np.asarray(freq, dtype=float)
        E = response_matrix(resp_xyz, resp_dirs)
        T = excitation_matrix(exc_xyz, exc_dirs)
        A = self.accelerance_origin(freq)
        H = np.einsum("ra,fab,be->ref", E, A, T)
        if elastic and self.elastic_modes:
            w = 2 * np.pi * freq
            rd = np.asarray(resp_dirs, float)
            rd = rd / np.linalg.norm(rd, axis=1, keepdims=True)
            ed = np.asarray(exc_dirs, float)
            ed = ed / np.linalg.norm(ed, axis=1, keepdims=True)
            for mode in self.elastic_modes:
                pr = np.sum(mode.shape(resp_xyz) * rd, axis=1)
                pe = np.sum(mode.shape(exc_xyz) * ed, axis=1)
                wr = 2 * np.pi * mode.frequency
                b = -(w**2) / (wr**2 - w**2 + 2j * mode.damping * wr * w)
                H += pr[:, None, None] * pe[None, :, None] * b[None, None, :]
        return H

    def time_response(
        self,
        force: ArrayLike,
        fs: float,
        resp_xyz: ArrayLike,
        resp_dirs: ArrayLike,
        exc_xyz: ArrayLike,
        exc_dirs: ArrayLike,
    ) -> NDArray[np.float64]:
        """Accelerations (n_resp, n_samples) for forces (n_exc, n_samples) sampled at ``fs`` Hz.

        Computed exactly in the frequency domain on a zero-padded grid twice the record
        length, so transients starting in the record are not wrapped around.
        """
        f = np.atleast_2d(np.asarray(force, dtype=float))
        n = f.shape[-1]
        nfft = 2 * n
        freq = np.fft.rfftfreq(nfft, 1.0 / fs)
        H = self.frf(freq, resp_xyz, resp_dirs, exc_xyz, exc_dirs)
        F = np.fft.rfft(f, nfft, axis=-1)
        A = np.einsum("ref,ef->rf", H, F)
        return np.fft.irfft(A, nfft, axis=-1)[:, :n]
