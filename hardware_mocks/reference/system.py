"""The assembled reference system: a lattice body on mounts, its exact FRFs and its truth.

Equations of motion of the nodes' translations ``u`` (3n DOFs) under forces ``f``::

    (K_b (1 + j eta_b) + K_m - w^2 M) u = f

with ``M`` the diagonal of node masses, ``K_b`` the lattice (:mod:`.body`) and ``K_m`` the
mounts' complex 3 x 3 stiffnesses at their nodes (:mod:`.mounts`, hysteretic damping). With
``damping="viscous"`` the mounts are real springs with viscous dampers ``C_m``
(``c_i = eta_i k_i / w_ref``) and ``(K_b (1 + j eta_b) + K_m + j w C_m - w^2 M) u = f``. The
accelerance is ``-w^2 u / f``.

How the FRFs are computed (exactly, not by truncation): the complex symmetric matrix
``A = M^-1/2 K* M^-1/2`` is diagonalised once, ``A = V diag(lam) V^-1`` (all 3n modes kept),
so ``(K* - w^2 M)^-1 = M^-1/2 V diag(1 / (lam - w^2)) V^-1 M^-1/2`` at every line; with
viscous mounts the first-order form ``z = [u; s u]``, ``A = [[0, I], [-M^-1 K*, -M^-1 C]]``
(6n states) is diagonalised instead and ``u = [I 0] V diag(1 / (s - lam)) V^-1 [0; M^-1 f]``
with ``s = j w``. The decomposition is checked to reproduce ``A`` to 1e-9 relative, and
:meth:`ReferenceSystem.accelerance_direct` (one dense solve per line) is the test's
cross-check. A ``rigid=True`` system has an infinitely stiff body: its FRFs are the 6-DOF
rigid-body FRFs of its own truth (:meth:`Truth.accelerance`), exact by construction.

Mounts that stiffen with frequency (``stiffening`` > 0, :func:`.mounts.stiffening_factor`):
the mounts' stiffness at line ``w`` is ``g(w) K_m``, so the system is the one above plus a
change of rank ``3 n_mounts``, ``(g(w) - 1) U K_m U^T``; its receptance follows from the
decomposition's by the Woodbury identity at every line (a ``3 n_mounts`` square solve per
line), exact as well; the dense solve per line is again the tests' cross-check. The
system's natural frequencies, decay rates and mode shapes are those of the mounts at the
stated frequency.

The truth (:class:`Truth`) comes from the node masses and the mounts alone (point-mass sums,
spring kinematics), never from the identification code.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from hardware_mocks.reference.body import LatticeBody
from hardware_mocks.reference.kinematics import (
    inertia_tensor,
    mass_matrix_6,
    rigid_map,
    theta_from_masses,
)
from hardware_mocks.reference.mounts import (
    Mount,
    damping_at_origin,
    mounts_at_origin,
    stiffening_factor,
)

__all__ = ["ReferenceSystem", "Truth"]


def _through_modes(a: NDArray[np.complex128], b: NDArray[np.complex128],
                   factors: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """``a diag(factors[:, f]) b`` at every line f, (rows of a, columns of b, n_f): one
    product of the modes' outer products ``a[:, n] b[n, :]`` with the modes' line factors
    (N, n_f)."""
    ab = (a[:, None, :] * b.T[None, :, :]).reshape(-1, a.shape[1])
    return np.asarray((ab @ factors).reshape(a.shape[0], b.shape[1], -1), dtype=np.complex128)


@dataclass(frozen=True)
class Truth:
    """Exact rigid-body parameters of a reference system (global frame, SI).

    Attributes
    ----------
    mass : kg
    cog : (3,) m
    inertia_cog, inertia_origin : (3, 3) kg m^2, moments on the diagonal, minus products off it
    theta : (10,) ``[m, m xc, m yc, m zc, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz]`` about O (products)
    M : (6, 6) rigid-body mass matrix at O
    K : (6, 6) real stiffness of the mounts at O (N/m, N/rad, N m/m, N m/rad)
    K_loss : (6, 6) imaginary part of the mounts' hysteretic stiffness at O (same units;
        zero for viscous mounts)
    C : (6, 6) viscous damping of the mounts at O (N s/m, ...; zero for hysteretic mounts)
    stiffening : the mounts' rise of stiffness per decade of frequency (0.25: +25 %); K and
        K_loss are then the values at ``stiffness_hz``
    stiffness_hz : Hz, the frequency K and K_loss hold at (mounts that stiffen)
    """

    mass: float
    cog: NDArray[np.float64]
    inertia_cog: NDArray[np.float64]
    inertia_origin: NDArray[np.float64]
    theta: NDArray[np.float64]
    M: NDArray[np.float64]
    K: NDArray[np.float64]
    K_loss: NDArray[np.float64]
    C: NDArray[np.float64]
    stiffening: float = 0.0
    stiffness_hz: float = 10.0

    def stiffness_at(self, freq_hz: ArrayLike) -> NDArray[np.float64]:
        """Real K at O at each frequency (n_f, 6, 6): ``K`` times the mounts' stiffening."""
        g = stiffening_factor(np.ravel(freq_hz), self.stiffening, self.stiffness_hz)
        return np.asarray(g[:, None, None] * self.K[None], dtype=np.float64)

    @property
    def principal_moments(self) -> NDArray[np.float64]:
        """Eigenvalues of ``inertia_cog``, ascending, kg m^2."""
        return np.asarray(np.linalg.eigvalsh(self.inertia_cog), dtype=np.float64)

    def damping(self, frequency_hz: float) -> NDArray[np.float64]:
        """Viscous 6 x 6 damping equivalent at one frequency, ``C + K_loss / w`` (N s/m, ...)."""
        return self.C + self.K_loss / (2 * np.pi * frequency_hz)

    def rigid_modes(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Undamped rigid-body modes of ``M``, ``K``: frequencies (6,) Hz ascending and
        mass-normalised shapes (6, 6) as columns (DOFs at O)."""
        w2, shapes = scipy.linalg.eigh(self.K, self.M)
        return np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi), shapes

    def accelerance(self, freq: ArrayLike, resp_xyz: ArrayLike, resp_vectors: ArrayLike,
                    exc_xyz: ArrayLike, exc_vectors: ArrayLike) -> NDArray[np.complex128]:
        """Rigid-body accelerance (n_r, n_e, n_f), (m/s^2)/N, of this truth.

        ``H = -w^2 (s^T G(r)) (K + j K_loss + j w C - w^2 M)^-1 (G(p)^T e)`` for a response along
        ``s`` at ``r`` and a unit force along ``e`` at ``p``.
        """
        w = 2 * np.pi * np.asarray(freq, dtype=float).ravel()
        R = np.einsum("ni,nij->nj", np.asarray(resp_vectors, float).reshape(-1, 3),
                      rigid_map(np.asarray(resp_xyz, float).reshape(-1, 3)))
        T = np.einsum("nji,nj->in", rigid_map(np.asarray(exc_xyz, float).reshape(-1, 3)),
                      np.asarray(exc_vectors, float).reshape(-1, 3))
        g = stiffening_factor(w / (2 * np.pi), self.stiffening, self.stiffness_hz)
        Z = (g[:, None, None] * (self.K + 1j * self.K_loss)[None]
             + 1j * w[:, None, None] * self.C[None] - (w**2)[:, None, None] * self.M[None])
        Q = np.linalg.solve(Z, np.broadcast_to(T.astype(complex), (w.size, 6, T.shape[1])))
        return np.moveaxis(-(w**2)[:, None, None] * (R @ Q), 0, -1)


@dataclass(frozen=True)
class ReferenceSystem:
    """A lattice body on mounts (global frame, SI).

    Attributes
    ----------
    body : the lattice, node positions in the global frame
    mounts : its mounts (each attached to a body node)
    rigid : the body is infinitely stiff (FRFs from the 6-DOF truth)
    damping : "hysteretic" mounts (loss factors) or "viscous" ones (``eta k / w_ref``)
    reference_hz : ``f_ref`` of viscous mounts, Hz
    stiffening : the mounts' rise of stiffness per decade of frequency (0: constant rates)
    stiffness_hz : the frequency the mounts' rates hold at when they stiffen, Hz
    """

    body: LatticeBody
    mounts: tuple[Mount, ...]
    rigid: bool = False
    damping: Literal["hysteretic", "viscous"] = "hysteretic"
    reference_hz: float = 10.0
    stiffening: float = 0.0
    stiffness_hz: float = 10.0
    _cache: dict[str, object] = field(default_factory=dict, compare=False, repr=False)

    @cached_property
    def truth(self) -> Truth:
        """Mass properties from the node masses, K at O from the mounts' kinematics."""
        m, r = self.body.masses, self.body.xyz
        mass = float(m.sum())
        cog = (m @ r) / mass
        Kc = mounts_at_origin(self.mounts)
        viscous = self.damping == "viscous"
        return Truth(mass=mass, cog=cog, inertia_cog=inertia_tensor(m, r, cog),
                     inertia_origin=inertia_tensor(m, r), theta=theta_from_masses(m, r),
                     M=mass_matrix_6(m, r), K=Kc.real.copy(),
                     K_loss=np.zeros((6, 6)) if viscous else Kc.imag.copy(),
                     C=(damping_at_origin(self.mounts, self.reference_hz) if viscous
                        else np.zeros((6, 6))),
                     stiffening=self.stiffening, stiffness_hz=self.stiffness_hz)

    def dynamic_stiffness(self, factor: float = 1.0) -> NDArray[np.complex128]:
        """Complex stiffness of the assembled nodes (3n x 3n): body with loss + mounts
        (their real rates only when viscous), the mounts' times ``factor``."""
        K = self.body.stiffness() * (1 + 1j * self.body.eta)
        for mt in self.mounts:
            i = slice(3 * mt.node, 3 * mt.node + 3)
            k3 = mt.stiffness_3()
            K[i, i] += factor * (k3.real if self.damping == "viscous" else k3)
        return np.asarray(K, dtype=np.complex128)

    def _mount_block(self) -> tuple[NDArray[np.float64], NDArray[np.complex128]]:
        """U (3n, 3 n_mounts) selecting the mounts' node DOFs and their stiffness block
        (3 n_mounts square; real rates only when viscous)."""
        k = len(self.mounts)
        U = np.zeros((3 * self.body.n_nodes, 3 * k))
        Km = np.zeros((3 * k, 3 * k), dtype=complex)
        for j, mt in enumerate(self.mounts):
            U[3 * mt.node:3 * mt.node + 3, 3 * j:3 * j + 3] = np.eye(3)
            k3 = mt.stiffness_3()
            Km[3 * j:3 * j + 3, 3 * j:3 * j + 3] = k3.real if self.damping == "viscous" else k3
        return U, Km

    def viscous_damping(self) -> NDArray[np.float64]:
        """Viscous damping of the assembled nodes (3n x 3n), N s/m (zero if hysteretic)."""
        C = np.zeros((3 * self.body.n_nodes,) * 2)
        if self.damping == "viscous":
            for mt in self.mounts:
                i = slice(3 * mt.node, 3 * mt.node + 3)
                C[i, i] += mt.damping_3(self.reference_hz)
        return C

    @cached_property
    def _modal(self) -> tuple[NDArray[np.complex128], NDArray[np.complex128],
                              NDArray[np.complex128]]:
        """(lam, left, right) of the full eigen-decomposition (module notes): hysteretic,
        receptance ``left diag(1 / (lam - w^2)) right``; viscous, ``left diag(1 / (s - lam))
        right`` with ``s = j w``."""
        m3 = np.repeat(self.body.masses, 3)
        s = 1.0 / np.sqrt(m3)
        if self.damping == "viscous":
            n = m3.size
            A = np.zeros((2 * n, 2 * n), dtype=complex)
            A[:n, n:] = np.eye(n)
            A[n:, :n] = -self.dynamic_stiffness() / m3[:, None]
            A[n:, n:] = -self.viscous_damping() / m3[:, None]
            lam, V = scipy.linalg.eig(A)
            Vinv = np.linalg.inv(V)
            err = np.linalg.norm((V * lam) @ Vinv - A) / np.linalg.norm(A)
            if not err < 1e-9:
                raise ArithmeticError(f"state-space decomposition reproduces the system to "
                                      f"{err:.1e} only")
            order = np.argsort(np.abs(lam))
            left = np.asarray(V[:n][:, order], dtype=np.complex128)
            right = np.asarray(Vinv[order][:, n:] / m3[None, :], dtype=np.complex128)
            return lam[order], left, right
        A = s[:, None] * self.dynamic_stiffness() * s[None, :]
        lam, V = scipy.linalg.eig(A)
        Vinv = np.linalg.inv(V)
        err = np.linalg.norm((V * lam) @ Vinv - A) / np.linalg.norm(A)
        if not err < 1e-9:
            raise ArithmeticError(f"modal decomposition reproduces the system to {err:.1e} only")
        order = np.argsort(lam.real)
        left = np.asarray(s[:, None] * V[:, order], dtype=np.complex128)
        right = np.asarray(Vinv[order] * s[None, :], dtype=np.complex128)
        return lam[order], left, right

    def natural_frequencies_hz(self) -> NDArray[np.float64]:
        """Natural frequencies of the assembled system, ``sqrt(Re lam) / 2 pi``, ascending, Hz.

        For a rigid system, the six undamped rigid-body modes of the truth."""
        if self.rigid:
            return self.truth.rigid_modes()[0]
        lam = self._modal[0]
        if self.damping == "viscous":  # conjugate pairs: |lam| is the undamped frequency
            return np.sort(np.abs(lam[lam.imag > 0])) / (2 * np.pi)
        return np.sqrt(np.clip(lam.real, 0.0, None)) / (2 * np.pi)

    def slowest_decay_per_s(self) -> float:
        """Smallest modal decay rate ``alpha`` (free vibration ``~ exp(-alpha t)``), 1/s.

        Viscous modes: ``-Re s`` of the state-space poles; hysteretic ones (``lam = w^2 (1 +
        j eta)``): ``|Im sqrt(lam)|`` (about ``w eta / 2``). A rigid system uses its truth's
        6-DOF model (poles of ``[[0, I], [-M^-1 (K + j K_loss), -M^-1 C]]``). 0 when undamped.
        """
        if self.rigid:
            t = self.truth
            A = np.zeros((12, 12), dtype=complex)
            A[:6, 6:] = np.eye(6)
            A[6:, :6] = -np.linalg.solve(t.M, t.K + 1j * t.K_loss)
            A[6:, 6:] = -np.linalg.solve(t.M, t.C)
            return float(np.min(np.abs(np.linalg.eigvals(A).real)))
        lam = self._modal[0]
        if self.damping == "viscous":
            return float(np.min(np.abs(lam.real)))
        return float(np.min(np.abs(np.sqrt(lam.astype(complex)).imag)))

    def with_mount_damping(self, factor: float) -> ReferenceSystem:
        """The same body and mounts with every mount loss factor times ``factor`` (mass,
        centre of gravity, inertia and stiffness unchanged; the damping of the truth scales)."""
        mounts = tuple(Mount(m.node, m.position, m.axes, m.rates, m.loss_factors * factor)
                       for m in self.mounts)
        return ReferenceSystem(self.body, mounts, rigid=self.rigid, damping=self.damping,
                               reference_hz=self.reference_hz, stiffening=self.stiffening,
                               stiffness_hz=self.stiffness_hz)

    def first_elastic_hz(self) -> float:
        """The seventh natural frequency (the first above the six mount modes); inf if rigid."""
        return float("inf") if self.rigid else float(self.natural_frequencies_hz()[6])

    def _dof_vectors(self, nodes: ArrayLike, vectors: ArrayLike) -> NDArray[np.float64]:
        """(n, 3n) rows that read (or load) ``vectors`` at ``nodes``."""
        nodes = np.asarray(nodes, dtype=np.int64).ravel()
        v = np.asarray(vectors, dtype=float).reshape(-1, 3)
        out = np.zeros((nodes.size, 3 * self.body.n_nodes))
        cols = 3 * nodes[:, None] + np.arange(3)
        out[np.arange(nodes.size)[:, None], cols] = v
        return out

    def accelerance(self, freq: ArrayLike, resp_nodes: ArrayLike, resp_vectors: ArrayLike,
                    exc_nodes: ArrayLike, exc_vectors: ArrayLike) -> NDArray[np.complex128]:
        """Exact accelerance (n_r, n_e, n_f), (m/s^2)/N.

        Parameters
        ----------
        freq : (n_f,) Hz
        resp_nodes, resp_vectors : body node and sensing vector (3,) of each response; the
            response is ``vector . a`` (a non-unit vector models a gain error)
        exc_nodes, exc_vectors : body node and force vector (3,) per unit force input
        """
        w2 = (2 * np.pi * np.asarray(freq, dtype=float).ravel()) ** 2
        if self.rigid:
            b = self.body.xyz
            return self.truth.accelerance(np.sqrt(w2) / (2 * np.pi),
                                          b[np.asarray(resp_nodes, dtype=np.int64)], resp_vectors,
                                          b[np.asarray(exc_nodes, dtype=np.int64)], exc_vectors)
        lam, left, right = self._modal
        L = self._dof_vectors(resp_nodes, resp_vectors) @ left  # (n_r, N)
        R = right @ self._dof_vectors(exc_nodes, exc_vectors).T  # (N, n_e)
        if self.damping == "viscous":
            g = -w2[None, :] / (1j * np.sqrt(w2)[None, :] - lam[:, None])
        else:
            g = -w2[None, :] / (lam[:, None] - w2[None, :])  # (N, n_f)
        out = _through_modes(L, R, g)  # (n_r, n_e, n_f)
        if not self.stiffening:
            return out
        # mounts at g K_m: Woodbury on the receptance, R = R0 - R0 U D (I + U^T R0 U D)^-1 U^T R0
        U, Km = self._mount_block()
        # receptance factors, R0 = left diag(d) right (0 at 0 Hz, where the accelerance is)
        d = np.divide(g, -w2[None, :], out=np.zeros_like(g), where=w2[None, :] > 0)
        Lu, Ru = U.T @ left, right @ U  # (3k, N), (N, 3k)
        A_su, A_uu, A_uf = (_through_modes(a, b, d).transpose(2, 0, 1)
                            for a, b in ((L, Ru), (Lu, Ru), (Lu, R)))
        D = (stiffening_factor(np.sqrt(w2) / (2 * np.pi), self.stiffening, self.stiffness_hz)
             - 1.0)[:, None, None] * Km[None]
        eye = np.eye(Km.shape[0])[None]
        corr = A_su @ D @ np.linalg.solve(eye + A_uu @ D, A_uf)  # (n_f, n_r, n_e) receptance
        out = out + (w2[:, None, None] * corr).transpose(1, 2, 0)
        return out

    def accelerance_direct(self, freq: ArrayLike, resp_nodes: ArrayLike, resp_vectors: ArrayLike,
                           exc_nodes: ArrayLike, exc_vectors: ArrayLike,
                           ) -> NDArray[np.complex128]:
        """The same accelerance by one dense solve of the full system per line (slow; tests)."""
        Cd = self.viscous_damping()
        m3 = np.repeat(self.body.masses, 3)
        Sr = self._dof_vectors(resp_nodes, resp_vectors)
        Fe = self._dof_vectors(exc_nodes, exc_vectors).T
        body = self.dynamic_stiffness(0.0)  # the body alone; the mounts at each line's rate
        mounts = self.dynamic_stiffness(1.0) - body
        out = []
        for f in np.asarray(freq, dtype=float).ravel():
            w = 2 * np.pi * f
            g = float(stiffening_factor(f, self.stiffening, self.stiffness_hz))
            Z = body + g * mounts + 1j * w * Cd - w**2 * np.diag(m3)
            out.append(-(w**2) * (Sr @ np.linalg.solve(Z, Fe)))
        return np.moveaxis(np.array(out), 0, -1)
