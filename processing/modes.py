"""Mount-system analysis of the identified M, K, C (, D): the six rigid-body modes, their kinetic-
energy decoupling, the torque roll axis, the mounts' elastic axis and the isolation margin.

Modes
    ``K phi = w^2 M phi`` (:func:`scipy.linalg.eigh`), ascending; ``phi`` at O in the DOF
    order x, y, z, rx, ry, rz, mass-normalised (``phi^T M phi = 1``, so translations are in
    m and rotations in rad per unit modal coordinate of ``sqrt(kg) m``), with the sign that
    makes the entry of largest kinetic energy positive. Damping ratio: the proportional
    (modal) approximation ``zeta_r = phi_r^T C phi_r / (2 w_r) + phi_r^T D phi_r / (2 w_r^2)``
    (viscous C, structural D of ``K + j w C + j D``: the modal loss factor
    ``phi_r^T D phi_r / w_r^2`` is ``2 zeta`` at resonance), which ignores the off-diagonal
    terms of ``Phi^T C_r Phi`` (``C_r = C + D / w``, the viscous equivalent at the modes'
    frequencies); their largest relative size ``|c_rs| / sqrt(c_rr c_ss)``, with ``D`` taken
    at ``sqrt(w_r w_s)``, is reported as ``damping_coupling`` (small: the approximation
    holds).
Kinetic-energy decoupling
    At the centre of gravity ``G`` with global axis directions, where the mass matrix
    ``M_G = diag(m I, J_G)`` has no translation-rotation coupling: the shape there is
    ``psi = [u_O - [c]x theta; theta]`` and the fraction of mode ``r``'s kinetic energy in
    DOF ``k`` is ``E_kr = psi_k (M_G psi)_k / (psi^T M_G psi)`` (the usual energy
    distribution of mount-system design; columns sum to 1; with products of inertia a
    rotational entry can be slightly negative).
Torque roll axis (TRA)
    The axis about which the free body starts to rotate under a torque about the crankshaft
    axis ``t``: direction ``J_G^-1 t / |J_G^-1 t|`` through the centre of gravity.
Elastic axis
    The screw axis of the mounts' static deflection ``q = K^-1 [0; t]`` under the same
    torque: direction ``theta / |theta|``, the point of it nearest the CoG, and its pitch
    ``theta . u_G / |theta|^2`` (m/rad; 0 for a pure rotation). When the TRA and the
    elastic axis coincide, ``[0; t]`` is proportional to both ``M q`` and ``K q``, so the
    roll mode is a pure rotation about the TRA, decoupled from the other five. It does not
    exist when K is singular (some motion is not held by the mounts).
Isolation
    For an excitation frequency ``f_e`` each mode's frequency ratio ``r = f_e / f_r``;
    the mount system isolates above ``r = sqrt(2)``; ``margin = r / sqrt(2)`` (> 1:
    isolated) and the transmissibility ``sqrt((1 + (2 zeta r)^2) / ((1 - r^2)^2 +
    (2 zeta r)^2))`` at ``f_e``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from processing.geometry import skew

__all__ = [
    "DOF_NAMES",
    "ElasticAxis",
    "Isolation",
    "ModeSet",
    "TorqueRollAxis",
    "isolation",
    "rigid_body_modes",
    "torque_roll_axis",
]

DOF_NAMES = ("x", "y", "z", "rx", "ry", "rz")


def _mass_parts(M: NDArray[np.float64]) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """Mass (kg), CoG (m) and inertia about the CoG (kg m^2) from the 6x6 mass matrix at O."""
    m = float(np.trace(M[:3, :3]) / 3.0)
    if not m > 0:
        raise ValueError(f"the mass matrix has a non-positive mass {m:g} kg")
    S = 0.5 * (M[3:, :3] - M[:3, 3:]) / m  # M[3:, :3] = m [c]x
    c = np.array([S[2, 1], S[0, 2], S[1, 0]])
    JG = M[3:, 3:] - m * (c @ c * np.eye(3) - np.outer(c, c))
    return m, c, 0.5 * (JG + JG.T)


def _square(A: ArrayLike, what: str) -> NDArray[np.float64]:
    a = np.asarray(A, dtype=float)
    if a.shape != (6, 6) or not np.all(np.isfinite(a)):
        raise ValueError(f"{what} must be a finite 6x6 matrix, got shape {a.shape}")
    return 0.5 * (a + a.T)


@dataclass(frozen=True)
class ModeSet:
    """The six rigid-body modes of M, K (and C).

    Attributes
    ----------
    frequency_hz : (6,) undamped natural frequencies, ascending (0 for a negative
        eigenvalue, which ``warnings`` names)
    damping_ratio : (6,) modal damping ratios (0 without C and D)
    shapes : (6, 6) mass-normalised shapes at O as columns (DOF order x..rz)
    energy : (6, 6) kinetic-energy fractions at the CoG, DOF (rows) by mode (columns)
    damping_coupling : largest ``|c_rs| / sqrt(c_rr c_ss)`` of ``Phi^T C Phi`` (r != s), D
        taken as its viscous equivalent (module notes)
    warnings : one line per problem (indefinite K, ...)
    """

    frequency_hz: NDArray[np.float64]
    damping_ratio: NDArray[np.float64]
    shapes: NDArray[np.float64]
    energy: NDArray[np.float64]
    damping_coupling: float
    warnings: tuple[str, ...] = ()

    def dominant(self) -> list[str]:
        """Name of each mode's DOF of largest kinetic energy (``x`` ... ``rz``)."""
        return [DOF_NAMES[int(np.argmax(self.energy[:, r]))] for r in range(6)]

    def to_json(self, iso: Isolation | None = None) -> list[dict[str, Any]]:
        """The result JSON's ``modes``: one object per mode, ascending frequency."""
        out: list[dict[str, Any]] = []
        for r in range(6):
            d: dict[str, Any] = {
                "frequency_hz": float(self.frequency_hz[r]),
                "damping_ratio": float(self.damping_ratio[r]),
                "shape": self.shapes[:, r].tolist(),
                "energy": self.energy[:, r].tolist(),
                "dominant": self.dominant()[r],
            }
            if iso is not None:  # a 0 Hz mode has no finite ratio: null
                for key, v in (("frequency_ratio", iso.ratio[r]),
                               ("isolation_margin", iso.margin[r]),
                               ("transmissibility", iso.transmissibility[r])):
                    d[key] = float(v) if np.isfinite(v) else None
            out.append(d)
        return out


def rigid_body_modes(M: ArrayLike, K: ArrayLike, C: ArrayLike | None = None,
                     D: ArrayLike | None = None) -> ModeSet:
    """The six rigid-body modes of the body on its mounts.

    Parameters
    ----------
    M : (6, 6) mass matrix at O (kg, kg m, kg m^2)
    K : (6, 6) stiffness at O (N/m, N/rad, N m/m, N m/rad)
    C : (6, 6) viscous damping at O, optional
    D : (6, 6) structural (hysteretic) damping at O (``K* = K + j w C + j D``), optional

    Returns
    -------
    ModeSet

    Raises
    ------
    ValueError
        M or K not finite 6x6, or M not positive definite.

    Examples
    --------
    >>> M = np.diag([10.0, 10, 10, 1, 1, 1]); K = np.diag([1e4, 4e4, 9e4, 1e3, 2e3, 3e3])
    >>> np.round(rigid_body_modes(M, K).frequency_hz, 3)
    array([ 5.033,  5.033,  7.118,  8.717, 10.066, 15.099])
    """
    Mm, Km = _square(M, "M"), _square(K, "K")
    Cm = _square(C, "C") if C is not None else np.zeros((6, 6))
    Dm = _square(D, "D") if D is not None else np.zeros((6, 6))
    try:
        w2, V = scipy.linalg.eigh(Km, Mm)
    except np.linalg.LinAlgError as err:
        raise ValueError("the mass matrix is not positive definite: no modes") from err
    warnings = []
    if np.any(w2 < 0):
        warnings.append(f"K is not positive definite ({int(np.sum(w2 < 0))} negative "
                        "eigenvalue(s)): those modes are given 0 Hz")
    w = np.sqrt(np.clip(w2, 0.0, None))
    m, c, JG = _mass_parts(Mm)
    # shapes at the CoG (global axis directions) and the block-diagonal mass there
    T = np.eye(6)
    T[:3, 3:] = -skew(c)
    Psi = T @ V
    MG = np.zeros((6, 6))
    MG[:3, :3] = m * np.eye(3)
    MG[3:, 3:] = JG
    E = Psi * (MG @ Psi)
    E = E / np.sum(E, axis=0, keepdims=True)
    sign = np.sign(V[np.argmax(E, axis=0), np.arange(6)])
    V = V * np.where(sign == 0, 1.0, sign)
    w_safe = np.where(w > 0, w, np.inf)
    # viscous equivalent of D between modes r and s at sqrt(w_r w_s)
    Cr = V.T @ Cm @ V + (V.T @ Dm @ V) / np.sqrt(np.outer(w_safe, w_safe))
    diag = np.diag(Cr)
    zeta = diag / (2 * w_safe)
    dd = np.sqrt(np.abs(np.outer(diag, diag)))
    off = np.where(dd > 0, np.abs(Cr) / np.where(dd > 0, dd, 1.0), 0.0)
    np.fill_diagonal(off, 0.0)
    return ModeSet(w / (2 * np.pi), zeta, V, E, float(off.max()), tuple(warnings))


@dataclass(frozen=True)
class Isolation:
    """Each mode against one excitation frequency: ratio, margin ``r / sqrt(2)``,
    transmissibility (see the module's docstring)."""

    excitation_hz: float
    ratio: NDArray[np.float64]
    margin: NDArray[np.float64]
    transmissibility: NDArray[np.float64]

    @property
    def isolated(self) -> NDArray[np.bool_]:
        return np.asarray(self.margin > 1.0)


def isolation(modes: ModeSet, excitation_hz: float) -> Isolation:
    """Isolation of an excitation at ``excitation_hz`` (Hz, > 0) by each mode."""
    if not excitation_hz > 0:
        raise ValueError(f"the excitation frequency must be > 0 Hz, got {excitation_hz:g}")
    f = modes.frequency_hz
    r = excitation_hz / np.where(f > 0, f, np.nan)
    r = np.where(f > 0, r, np.inf)
    two_zr = 2 * modes.damping_ratio * np.where(np.isfinite(r), r, 0.0)
    with np.errstate(invalid="ignore"):
        tr = np.where(np.isfinite(r),
                      np.sqrt((1 + two_zr**2) / ((1 - r**2) ** 2 + two_zr**2)), 0.0)
    return Isolation(float(excitation_hz), r, r / np.sqrt(2.0), tr)


@dataclass(frozen=True)
class ElasticAxis:
    """Screw axis of the mounts' static deflection under a torque about the crank axis."""

    direction: NDArray[np.float64]
    point: NDArray[np.float64]
    pitch: float


@dataclass(frozen=True)
class TorqueRollAxis:
    """Torque roll axis, and where the mounts' elastic axis lies against it.

    Attributes
    ----------
    direction : unit vector, global frame (sign: positive component along ``crank_axis``)
    point : the centre of gravity, m
    crank_axis : the unit torque axis used
    angle_to_crank_deg : angle between the TRA and the crank axis, degrees
    elastic_axis : the mounts' elastic axis, or None when K is singular
    angle_deg : angle between the TRA and the elastic axis, degrees (nan without one)
    distance_m : distance from the CoG to the elastic axis, m (nan without one)
    note : why there is no elastic axis, or ""
    """

    direction: NDArray[np.float64]
    point: NDArray[np.float64]
    crank_axis: NDArray[np.float64]
    angle_to_crank_deg: float
    elastic_axis: ElasticAxis | None
    angle_deg: float
    distance_m: float
    note: str = ""

    def to_json(self) -> dict[str, Any]:
        """The result JSON's ``torque_roll_axis`` (``direction``, ``point``, more keys)."""
        ea = self.elastic_axis
        return {
            "direction": self.direction.tolist(),
            "point": self.point.tolist(),
            "crank_axis": self.crank_axis.tolist(),
            "angle_to_crank_deg": self.angle_to_crank_deg,
            "elastic_axis": None if ea is None else {
                "direction": ea.direction.tolist(), "point": ea.point.tolist(),
                "pitch_m_per_rad": ea.pitch},
            "angle_to_elastic_axis_deg": None if ea is None else self.angle_deg,
            "distance_to_elastic_axis_m": None if ea is None else self.distance_m,
            "note": self.note,
        }


def _angle(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Angle between two lines (0..90 degrees: directions are unsigned)."""
    cos = abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(min(1.0, cos))))


def torque_roll_axis(M: ArrayLike, K: ArrayLike | None, crank_axis: ArrayLike) -> TorqueRollAxis:
    """Torque roll axis of the body and the elastic axis of its mounts (module docstring).

    Parameters
    ----------
    M : (6, 6) mass matrix at O
    K : (6, 6) stiffness at O, or None (no elastic axis)
    crank_axis : (3,) direction of the crankshaft (any length > 0), global frame

    Examples
    --------
    >>> M = np.diag([100.0, 100, 100, 2, 3, 4])
    >>> torque_roll_axis(M, None, [1, 0, 0]).direction.tolist()
    [1.0, 0.0, 0.0]
    """
    Mm = _square(M, "M")
    t = np.asarray(crank_axis, dtype=float).reshape(-1)
    if t.shape != (3,) or not np.all(np.isfinite(t)) or np.linalg.norm(t) < 1e-12:
        raise ValueError("the crank axis must be a non-zero 3-vector")
    t = t / np.linalg.norm(t)
    _, c, JG = _mass_parts(Mm)
    if np.any(np.linalg.eigvalsh(JG) <= 0):
        raise ValueError("the inertia about the CoG is not positive definite: no torque roll "
                         "axis")
    d = np.linalg.solve(JG, t)
    d = d / np.linalg.norm(d)
    if d @ t < 0:
        d = -d
    tra_angle = _angle(d, t)
    if K is None:
        return TorqueRollAxis(d, c, t, tra_angle, None, float("nan"), float("nan"),
                              "no stiffness given")
    Km = _square(K, "K")
    sv = np.linalg.svd(Km, compute_uv=False)
    if sv[-1] <= 1e-12 * sv[0]:
        return TorqueRollAxis(d, c, t, tra_angle, None, float("nan"), float("nan"),
                              "K is singular: the mounts do not hold every motion, so a "
                              "torque has no static deflection and there is no elastic axis")
    q = np.linalg.solve(Km, np.concatenate([np.zeros(3), t]))
    u_O, th = q[:3], q[3:]
    u_G = u_O + np.cross(th, c)  # deflection at the CoG
    n2 = float(th @ th)
    e = th / np.sqrt(n2)
    if e @ t < 0:
        e = -e
    pitch = float(th @ u_G / n2)
    # the screw axis' point nearest the CoG: c + theta x u_G / |theta|^2
    p = c + np.cross(th, u_G) / n2
    dist = float(np.linalg.norm(np.cross(c - p, e)))
    return TorqueRollAxis(d, c, t, tra_angle, ElasticAxis(e, p, pitch), _angle(d, e), dist)
