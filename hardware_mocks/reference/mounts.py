"""Resilient mounts: three principal rates along their own axes, each with its loss factor.

A mount joins a body node at ``position`` to the ground. In its local frame (axes u, v, w,
the rows of ``axes`` in the global frame) its complex stiffness is
``diag(k_u (1 + j eta_u), k_v (1 + j eta_v), k_w (1 + j eta_w))`` (hysteretic damping), so in
the global frame ``k = A^T diag(...) A`` with ``A = axes``. As viscous dampers instead
(:meth:`Mount.damping_3`), ``c_i = eta_i k_i / w_ref``: the same loss at ``f_ref``. A rigid
motion ``q`` at O moves the mount's body end by ``G(p) q`` (``G`` of :mod:`.kinematics`), hence
its 6 x 6 stiffness at O is ``G(p)^T k G(p)``.

Elastomer mounts stiffen with frequency: with a rise of ``s`` per decade
(:func:`stiffening_factor`) every rate (and, loss factors being constant, every loss part)
is ``k(f) = k (f / f_ref)^alpha`` with ``alpha = log10(1 + s)``, ``k`` the rate at the
stated frequency ``f_ref``, and constant below ``f_ref / 100`` (the rubbery plateau).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hardware_mocks.reference.kinematics import rigid_map

__all__ = ["Mount", "damping_at_origin", "mounts_at_origin", "mounts_toml", "stiffening_factor"]


#: below this fraction of the stated frequency the rates no longer fall (rubbery plateau)
PLATEAU = 0.01


def stiffening_factor(freq_hz: ArrayLike, per_decade: float, reference_hz: float) -> (
    NDArray[np.float64]
):
    """``k(f) / k(f_ref)`` of a mount whose rates rise by ``per_decade`` (0.25: +25 %) per
    decade of frequency: ``(f / f_ref)^log10(1 + per_decade)``, constant below
    ``PLATEAU f_ref``; 1 everywhere when ``per_decade`` is 0."""
    f = np.maximum(np.asarray(freq_hz, dtype=float), PLATEAU * reference_hz)
    return np.asarray((f / reference_hz) ** np.log10(1.0 + per_decade), dtype=np.float64)


@dataclass(frozen=True)
class Mount:
    """One mount (global frame, SI).

    Attributes
    ----------
    node : index of the body node it is attached to
    position : (3,) m, the node's position (the mount's elastic centre)
    axes : (3, 3) rows are the local u, v, w unit axes in the global frame
    rates : (3,) N/m along u, v, w
    loss_factors : (3,) hysteretic loss factors along u, v, w
    """

    node: int
    position: NDArray[np.float64]
    axes: NDArray[np.float64]
    rates: NDArray[np.float64]
    loss_factors: NDArray[np.float64]

    def __post_init__(self) -> None:
        A = np.asarray(self.axes, dtype=float).reshape(3, 3)
        if not np.allclose(A @ A.T, np.eye(3), atol=1e-9) or np.linalg.det(A) < 0:
            raise ValueError("mount axes must be a right-handed orthonormal set of rows")
        object.__setattr__(self, "axes", A)
        object.__setattr__(self, "position", np.asarray(self.position, dtype=float).reshape(3))
        object.__setattr__(self, "rates", np.asarray(self.rates, dtype=float).reshape(3))
        object.__setattr__(self, "loss_factors",
                           np.asarray(self.loss_factors, dtype=float).reshape(3))

    def stiffness_3(self) -> NDArray[np.complex128]:
        """Complex 3 x 3 stiffness in the global frame, N/m."""
        k = self.rates * (1 + 1j * self.loss_factors)
        return np.asarray(self.axes.T @ (k[:, None] * self.axes), dtype=np.complex128)

    def damping_3(self, reference_hz: float) -> NDArray[np.float64]:
        """Viscous 3 x 3 damping in the global frame, ``c_i = eta_i k_i / w_ref``, N s/m."""
        c = self.loss_factors * self.rates / (2 * np.pi * reference_hz)
        return np.asarray(self.axes.T @ (c[:, None] * self.axes), dtype=np.float64)

    def stiffness_at_origin(self) -> NDArray[np.complex128]:
        """Complex 6 x 6 stiffness at O, ``G(p)^T k G(p)`` (DOFs x, y, z, rx, ry, rz)."""
        G = rigid_map(self.position)
        out: NDArray[np.complex128] = G.T @ self.stiffness_3() @ G
        return out


def damping_at_origin(mounts: tuple[Mount, ...], reference_hz: float) -> NDArray[np.float64]:
    """Sum of the mounts' viscous 6 x 6 dampings at O, ``G(p)^T c G(p)`` (N s/m, ...)."""
    G = [rigid_map(m.position) for m in mounts]
    return np.asarray(np.sum([g.T @ m.damping_3(reference_hz) @ g for g, m in zip(G, mounts,
                                                                             strict=True)],
                             axis=0), dtype=np.float64)


def mounts_at_origin(mounts: tuple[Mount, ...]) -> NDArray[np.complex128]:
    """Sum of the mounts' complex 6 x 6 stiffnesses at O (real part K, imaginary part)."""
    out: NDArray[np.complex128] = np.sum([m.stiffness_at_origin() for m in mounts], axis=0)
    return out


def mounts_toml(mounts: tuple[Mount, ...], crank_axis: tuple[float, float, float] = (1.0, 0.0, 0.0),
                ) -> str:
    """The mounts as the text of a mounts file (``insitu identify --mounts FILE``, TOML).

    Positions in m and axes as rows (u, v, w) in the global frame, full precision; names
    ``mount 1``, ``mount 2``, ... in order.
    """

    def vec(v: NDArray[np.float64] | tuple[float, ...]) -> str:
        return "[" + ", ".join(repr(float(x)) for x in v) + "]"

    lines = [f"crank_axis = {vec(crank_axis)}"]
    for i, m in enumerate(mounts, 1):
        lines += ["", "[[mount]]", f'name = "mount {i}"', f"position = {vec(m.position)}",
                  "axes = [" + ", ".join(vec(row) for row in m.axes) + "]"]
    return "\n".join(lines) + "\n"
