"""Planning a test before the first hit: which sensors and excitation points to use, and how
well the identification will then know every number.

Given an approximate model of the unit under test (:class:`ApproximateModel`: mass, CoG,
inertia about the CoG, K and its damping at O, e.g. from mounts with rough rates), candidate
triaxial sensor positions and candidate excitation points with the directions the operator
can reach (:class:`Candidates`), and the test's conditions (:class:`TestConditions`: lines,
noise, averages, the stated location / angle / gain uncertainties), :func:`plan_test`
chooses ``n_sensors`` sensors and ``n_points`` excitations (each a point and one of its
allowed directions) and predicts the standard deviation of every identified number.

The search (:func:`fisher_blocks`, :func:`search`) maximises an optimal-design criterion on
the linearised information of the parameters (the ten inertia parameters, with K's 21 as an
option) carried by the FRFs ``H = E A T`` of the model, ``A(w) = (M - K*(w)/w^2)^-1``:

- each FRF value's sensitivity is ``dH/dtheta_i = -e^T A M_i A t`` (``dH/dK_ij =
  e^T A S_ij A t / w^2``), on up to :data:`CRITERION_LINES` lines of the mass line (and of the
  stiffness band with K);
- each value's variance is the noise of an H1 estimate, ``noise^2 (rms^2 + |H|^2) / n``
  (response noise relative to the record's RMS, force noise), plus the stated test errors
  (gain, the sensor's and the point's location, the sensor's angle) to first order, counted
  once for the whole band (they are the same on every line, so more lines do not average
  them out);
- the information of a sensor and an excitation is the sum over its three channels and the
  lines: adding or exchanging a candidate adds or removes one precomputed block, so greedy
  additions then exchange passes cost a few batched determinants or inverses per step;
- ``D``: maximise ``log det F``, ``A``: minimise ``trace F^-1`` (parameters scaled to m,
  m L, m L^2 and sqrt(K_ii K_jj)); layouts whose E or T are rank-deficient are never taken.

The predicted standard deviations of the chosen layout then come from the identification
itself (:func:`predict`): the model's FRFs (:func:`processing.synthesis.synthesise`, the
forward model the fit assumes) with H1 noise at the stated level and averages, identified by
:func:`processing.identify.fit` with the stated test uncertainties, whose uncertainty
(the fit's covariance and the Monte Carlo of location, angle and gain) is the prediction.
With an expected first elastic mode the FRFs also hold generic elastic modes
(:class:`GenericElastic`: a free beam's first bending and torsion shapes on the model's
box), whose bias on the mass line a real test has however many hits it averages.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.data import FRFSet, Geometry, InputError
from processing.geometry import (
    GeometryReport,
    characteristic_length,
    check_geometry,
    excitation_matrix,
    response_matrix,
    skew,
)
from processing.identify import IdentifyOptions, fit
from processing.inertia import MASS_BASIS, theta_from_body
from processing.measurement import Measurement
from processing.montecarlo import StatedUncertainty
from processing.synthesis import synthesise

__all__ = [
    "CRITERION_LINES",
    "ApproximateModel",
    "Candidates",
    "Criterion",
    "Information",
    "Layout",
    "PlanningError",
    "Prediction",
    "TestConditions",
    "TestDesign",
    "box_inertia",
    "criterion_value",
    "fisher_blocks",
    "layout_value",
    "linearised_std",
    "mount_stiffness",
    "plan_test",
    "predict",
    "search",
    "test_error_cov",
]

Criterion = Literal["D", "A"]

#: lines of each band the search's information is summed over (spread over the band)
CRITERION_LINES = 48
#: a layout whose scaled E or T has a singular value under this fraction of its largest
#: is rank-deficient
RANK_TOL = 1e-6
#: the least relative noise of an FRF value the search assumes (the fit's weights have a floor of
#: 0.1 % of the FRFs' RMS, processing.problem.COHERENCE_NOISE_FLOOR)
NOISE_FLOOR = 1e-3
#: cond(T) (rotations scaled by the candidates' size) a chosen layout stays under: the fit
#: drops the lines of a T over 20 (processing.geometry.DEFAULT_MAX_COND_T, rotations scaled by
#: the layout's own size), with a margin for the difference of scale
MAX_COND_T = 12.0


class PlanningError(InputError):
    """The planning problem cannot be solved as given; one line naming what to change."""


# --- the approximate model -------------------------------------------------------------------


def box_inertia(mass: float, size: ArrayLike) -> NDArray[np.float64]:
    """Inertia tensor (3, 3), kg m^2, about the centre of a uniform box of ``size`` (a, b, c)
    m along x, y, z: ``m / 12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2)``.

    Examples
    --------
    >>> box_inertia(12.0, [1.0, 1.0, 1.0])[0, 0]
    np.float64(2.0)
    """
    a, b, c = np.asarray(size, dtype=float)
    return mass / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def mount_stiffness(position: ArrayLike, axes: ArrayLike, rates: ArrayLike,
                    loss_factors: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """K and the structural damping D (6, 6) at O of one mount: ``G^T A^T diag(k) A G`` with
    ``G = [I, -[p]x]`` (the mount's displacement from the DOFs at O), ``A`` the rows of its
    axes, ``k`` its rates (N/m) and ``D`` the same with ``eta k``."""
    p = np.asarray(position, dtype=float)
    A = np.asarray(axes, dtype=float)
    G = np.concatenate([np.eye(3), -skew(p)], axis=1)
    AG = A @ G
    k = np.asarray(rates, dtype=float)
    eta = np.asarray(loss_factors, dtype=float)
    return AG.T @ (k[:, None] * AG), AG.T @ ((eta * k)[:, None] * AG)


@dataclass(frozen=True)
class ApproximateModel:
    """What is roughly known of the unit before the test (SI, global frame).

    Attributes
    ----------
    mass : kg
    cog : (3,) m
    inertia_cog : (3, 3) kg m^2 about the CoG (minus products off the diagonal)
    K : (6, 6) N/m... stiffness at O
    D : (6, 6) structural damping at O (``K* = K + j D``), or zeros
    C : (6, 6) viscous damping at O (``K* = K + j w C``), or zeros
    first_elastic_hz : the expected first elastic mode of the unit, Hz, or None (stiff)
    """

    mass: float
    cog: NDArray[np.float64]
    inertia_cog: NDArray[np.float64]
    K: NDArray[np.float64]
    D: NDArray[np.float64] = field(default_factory=lambda: np.zeros((6, 6)))
    C: NDArray[np.float64] = field(default_factory=lambda: np.zeros((6, 6)))
    first_elastic_hz: float | None = None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise PlanningError(f"model mass must be > 0 kg, got {self.mass!r}")
        for name, shape in (("cog", (3,)), ("inertia_cog", (3, 3)), ("K", (6, 6)),
                            ("D", (6, 6)), ("C", (6, 6))):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != shape or not np.all(np.isfinite(v)):
                raise PlanningError(f"model {name} must be finite of shape {shape}, got "
                                    f"shape {v.shape}")
            object.__setattr__(self, name, v)
        J = 0.5 * (self.inertia_cog + self.inertia_cog.T)
        if np.linalg.eigvalsh(J)[0] <= 0:
            raise PlanningError("model inertia_cog must be positive definite")
        if np.linalg.eigvalsh(0.5 * (self.K + self.K.T))[0] <= 0:
            raise PlanningError("the model's stiffness at O is singular: give at least three "
                                "mounts (or rates) that hold the six rigid-body motions")
        f = self.first_elastic_hz
        if f is not None and not (np.isfinite(f) and f > 0):
            raise PlanningError(f"model first_elastic_hz must be > 0 Hz, got {f!r}")

    @property
    def theta(self) -> NDArray[np.float64]:
        """The ten inertia parameters about O."""
        return theta_from_body(self.mass, self.cog, self.inertia_cog)

    @property
    def M(self) -> NDArray[np.float64]:
        return np.tensordot(self.theta, MASS_BASIS, axes=1)

    def rigid_modes_hz(self) -> NDArray[np.float64]:
        """Undamped rigid-body modes of M and K, Hz (ascending)."""
        lam = np.linalg.eigvals(np.linalg.solve(self.M, self.K)).real
        return np.sqrt(np.clip(np.sort(lam), 0, None)) / (2 * np.pi)

    def accelerance_at_origin(self, freq: ArrayLike) -> NDArray[np.complex128]:
        """``A(w) = -w^2 (K + j D + j w C - w^2 M)^-1`` (n_f, 6, 6)."""
        w = 2 * np.pi * np.asarray(freq, dtype=float)
        Z = (self.K + 1j * self.D)[None] + 1j * w[:, None, None] * self.C[None] \
            - (w**2)[:, None, None] * self.M[None]
        Zi: NDArray[np.complex128] = np.linalg.inv(Z.astype(np.complex128))
        return Zi * -(w**2)[:, None, None]


# --- candidates and conditions ---------------------------------------------------------------


@dataclass(frozen=True)
class Candidates:
    """Candidate triaxial sensor positions and excitation DOFs (a point and one of the
    directions the operator can reach there).

    Attributes
    ----------
    sensor_nodes : (n_s,) node ids; sensor_xyz : (n_s, 3) m
    point_nodes : (n_p,) node ids; point_xyz : (n_p, 3) m
    exc_point : (n_e,) index of each excitation DOF's point; exc_dirs : (n_e, 3) unit vectors
    """

    sensor_nodes: NDArray[np.int64]
    sensor_xyz: NDArray[np.float64]
    point_nodes: NDArray[np.int64]
    point_xyz: NDArray[np.float64]
    exc_point: NDArray[np.int64]
    exc_dirs: NDArray[np.float64]

    def __post_init__(self) -> None:
        sn = np.asarray(self.sensor_nodes, dtype=np.int64).ravel()
        sx = np.asarray(self.sensor_xyz, dtype=float).reshape(-1, 3)
        pn = np.asarray(self.point_nodes, dtype=np.int64).ravel()
        px = np.asarray(self.point_xyz, dtype=float).reshape(-1, 3)
        ep = np.asarray(self.exc_point, dtype=np.int64).ravel()
        ed = np.asarray(self.exc_dirs, dtype=float).reshape(-1, 3)
        if sn.size != sx.shape[0] or pn.size != px.shape[0] or ep.size != ed.shape[0]:
            raise PlanningError("candidate node ids, coordinates and directions differ in count")
        if not (np.all(np.isfinite(sx)) and np.all(np.isfinite(px)) and np.all(np.isfinite(ed))):
            raise PlanningError("candidate coordinates or directions are not finite")
        if ep.size and (ep.min() < 0 or ep.max() >= pn.size):
            raise PlanningError("an excitation direction refers to no candidate point")
        n = np.linalg.norm(ed, axis=1)
        if np.any(n < 1e-12):
            raise PlanningError("a candidate excitation direction is zero")
        object.__setattr__(self, "sensor_nodes", sn)
        object.__setattr__(self, "sensor_xyz", sx)
        object.__setattr__(self, "point_nodes", pn)
        object.__setattr__(self, "point_xyz", px)
        object.__setattr__(self, "exc_point", ep)
        object.__setattr__(self, "exc_dirs", ed / n[:, None])

    @property
    def exc_xyz(self) -> NDArray[np.float64]:
        return self.point_xyz[self.exc_point]

    @property
    def exc_nodes(self) -> NDArray[np.int64]:
        return self.point_nodes[self.exc_point]


@dataclass(frozen=True)
class TestConditions:
    """How the test will measure.

    Attributes
    ----------
    freq : (n_f,) Hz, the analyser's lines
    noise : noise on force and every response, relative to each record's RMS
    averages : hits or blocks averaged per point
    stated : the test's location, angle and gain uncertainties (standard deviations)
    seed : of the simulated noise
    realisations : noise realisations; the prediction is their median variance
    """

    freq: NDArray[np.float64]
    noise: float = 0.01
    averages: int = 5
    stated: StatedUncertainty = field(default_factory=StatedUncertainty)
    seed: int = 0
    realisations: int = 3

    __test__ = False  # not a pytest test class

    def __post_init__(self) -> None:
        f = np.asarray(self.freq, dtype=float).ravel()
        if f.size < 16 or not np.all(np.isfinite(f)) or f[0] <= 0 or np.any(np.diff(f) <= 0):
            raise PlanningError("the test's lines must be at least 16 increasing frequencies "
                                "above 0 Hz")
        object.__setattr__(self, "freq", f)
        if not (np.isfinite(self.noise) and 0 <= self.noise < 1):
            raise PlanningError(f"noise must be from 0 to 1 (relative), got {self.noise!r}")
        if self.averages < 1 or self.realisations < 1:
            raise PlanningError("averages and realisations must be at least 1")

    def lines(self, model: ApproximateModel) -> NDArray[np.float64]:
        """The lines an identification will use: up to half the expected first elastic
        mode (0.7 when the noise lets the fit model elastic leakage, under 0.2 %), as the
        automatic mass line ends (docs/identification.md)."""
        f = self.freq
        if model.first_elastic_hz is not None:
            top = (0.7 if self.noise < 0.002 else 0.5) * model.first_elastic_hz
            f = f[f <= top]
        if f.size < 16:
            raise PlanningError(f"only {f.size} lines under the expected first elastic mode's "
                                "usable fraction: use a finer line spacing")
        return f


# --- the information of each sensor and excitation -------------------------------------------


def _bands(model: ApproximateModel, lines: NDArray[np.float64], with_stiffness: bool,
           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lines (sub-sampled) and their weights (lines each stands for) of the mass line, and
    of the stiffness band when asked."""
    f_r = float(model.rigid_modes_hz()[-1])
    out_f, out_w = [], []
    lo = 2 * f_r if np.count_nonzero(lines >= 2 * f_r) >= 8 else 1.3 * f_r
    bands = [(lo, np.inf)]
    if with_stiffness:
        bands.append((0.0, 1.5 * f_r))
    for a, b in bands:
        sel = lines[(lines >= a) & (lines <= b)]
        if sel.size == 0:
            sel = lines[-max(8, lines.size // 3):] if a > 0 else lines[:max(8, lines.size // 3)]
        take = np.unique(np.linspace(0, sel.size - 1, min(CRITERION_LINES, sel.size)).round()
                         .astype(int))
        out_f.append(sel[take])
        out_w.append(np.full(take.size, sel.size / take.size))
    return np.concatenate(out_f), np.concatenate(out_w)


def _param_basis(model: ApproximateModel, with_stiffness: bool
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The derivative of ``A^-1 = M - K/w^2`` along each (scaled) parameter: (n_par, 6, 6)
    matrices, the parameters' scales, and which are stiffness entries (divided by w^2)."""
    L = _length(model)
    m = model.mass
    scales = [m, m * L, m * L, m * L, *([m * L * L] * 6)]
    mats = list(MASS_BASIS)
    is_k = [False] * 10
    if with_stiffness:
        d = np.sqrt(np.abs(np.diag(model.K)))
        for i, j in zip(*np.triu_indices(6), strict=True):
            S = np.zeros((6, 6))
            S[i, j] = S[j, i] = -1.0  # d(A^-1)/dK_ij = -S / w^2
            mats.append(S)
            scales.append(float(d[i] * d[j]))
            is_k.append(True)
    return np.array(mats), np.array(scales), np.array(is_k)


def _length(model: ApproximateModel) -> float:
    return float(max(np.sqrt(np.trace(model.inertia_cog) / (2 * model.mass)), 1e-3))


@dataclass(frozen=True)
class Information:
    """What the search sums and projects (scaled parameters, p of them):

    - ``F`` (n_s, n_e, p, p): the information of each candidate sensor's FRFs with each
      candidate excitation about the parameters (noise only); a layout's is the sum;
    - ``E`` (n_s, 3, 6), ``T`` (n_e, 6): each candidate's rows of E and column of T;
      ``sensor_xyz`` (n_s, 3), ``exc_dirs`` (n_e, 3);
    - ``M`` (6, 6): the model's mass matrix at O; ``proj`` (p, 36): the least-squares
      projection of a symmetric change of M onto the scaled parameters;
    - ``stated``: the test's location, angle and gain standard deviations.

    A layout's covariance is ``F^-1 + C_test`` (:func:`test_error_cov`: every test error a
    random effect through the fit's own projections ``E^+`` and ``T^+``).
    """

    F: NDArray[np.float64]
    E: NDArray[np.float64]
    T: NDArray[np.float64]
    sensor_xyz: NDArray[np.float64]
    exc_dirs: NDArray[np.float64]
    M: NDArray[np.float64]
    proj: NDArray[np.float64]
    stated: StatedUncertainty
    scales: NDArray[np.float64]


def test_error_cov(info: Information, S: NDArray[np.int64], P: NDArray[np.int64]
                   ) -> NDArray[np.float64]:
    """Covariance (b, p, p) of the scaled parameters from the stated test errors for
    ``b`` layouts: sensors ``S`` (b, n) and excitations ``P`` (b, k), index arrays.

    The fit projects the responses on the rigid-body motions, ``X = E^+ H``, and the forces
    on them, ``A^-1 = T X^+`` (``X^+ = T^+ A^-1``), so on the mass line a change ``dE`` of
    the response rows and ``dT`` of the excitation columns moves the identified mass matrix
    by ``dM = -M E^+ dE + dT T^+ M``. Every error is an independent random effect of its
    standard deviation: each channel's gain (``dE_r = g E_r``) and tilt about its two
    perpendicular axes (``dE_r = a E_r'``, the rows of the sensor's other channels), each
    sensor's location (``dE_r = [0, delta x d_r]`` on its three channels), each
    excitation's location (``dT_c = [0, delta x e_c]``) and force gain (``dT_c = g T_c``).
    Each ``dM`` (symmetrised) is projected on the parameters; the covariance is the sum of
    the outer products. It grows with cond(E) and cond(T): clustered sensors or points
    make ``E^+`` or ``T^+`` large."""
    st = info.stated
    S = np.asarray(S, dtype=np.int64)
    P = np.asarray(P, dtype=np.int64)
    b, n = S.shape
    E = info.E[S].reshape(b, 3 * n, 6)
    T = np.swapaxes(info.T[P], 1, 2)  # (b, 6, k)
    Ep = np.linalg.pinv(E)  # (b, 6, 3n)
    Tp = np.linalg.pinv(T)  # (b, k, 6)
    M = info.M
    MEp = np.einsum("ij,bjr->bir", M, Ep)  # (b, 6, 3n)
    dirs = np.eye(3)
    errs = []  # each (b, m, 6, 6): dM per unit error times its std
    if st.gain > 0:
        errs.append(-st.gain * np.einsum("bir,brj->brij", MEp, E))
    if st.angle > 0:
        other = np.array([[1, 2], [0, 2], [0, 1]])
        rows = (3 * np.arange(n)[:, None, None] + other[None]).reshape(3 * n, 2)
        Eo = E[:, rows]  # (b, 3n, 2, 6): the other two channels' rows of each sensor
        errs.append(-st.angle * np.einsum("bir,brkj->brkij", MEp, Eo).reshape(b, -1, 6, 6))
    if st.location > 0:
        # row r's rotation part moves by delta x d_r for delta along each axis j
        dr = np.zeros((3, 3, 6))  # (j, channel axis, 6)
        dr[:, :, 3:] = np.cross(dirs[:, None, :], dirs[None, :, :])
        MEs = MEp.reshape(b, 6, n, 3)
        errs.append(-st.location * np.einsum("bisc,jck->bsjik", MEs, dr).reshape(b, -1, 6, 6))
        ec = info.exc_dirs[P]  # (b, k, 3)
        dT = np.zeros((b, P.shape[1], 3, 6))
        dT[..., 3:] = np.cross(dirs[None, None], ec[:, :, None, :])
        TpM = np.einsum("bkj,jl->bkl", Tp, M)
        errs.append(st.location * np.einsum("bkji,bkl->bkjil", dT, TpM).reshape(b, -1, 6, 6))
    if st.gain > 0:
        TpM = np.einsum("bkj,jl->bkl", Tp, M)
        errs.append(st.gain * np.einsum("bik,bkl->bkil", T, TpM))
    p = info.proj.shape[0]
    if not errs:
        return np.zeros((b, p, p))
    dM = np.concatenate(errs, axis=1)
    dM = 0.5 * (dM + np.swapaxes(dM, -1, -2))
    shift = np.einsum("pk,bmk->bmp", info.proj, dM.reshape(b, dM.shape[1], 36))
    return np.einsum("bmp,bmq->bpq", shift, shift)


def fisher_blocks(model: ApproximateModel, candidates: Candidates, conditions: TestConditions,
                  *, with_stiffness: bool = False) -> Information:
    """:class:`Information` of every candidate sensor (its three channels) with every
    candidate excitation DOF (see the module's notes).

    Sums over the sub-sampled lines of the mass line (and the stiffness band with K) with
    their weights; the noise variance of an FRF value is ``noise^2 (rms^2 + |H|^2) / n`` with
    ``rms`` the FRF's RMS over all lines (the noise at least :data:`NOISE_FLOOR`, the floor
    the fit's weights have); the stated test errors enter to first order, the same on
    every line.
    """
    lines = conditions.lines(model)
    f, wt = _bands(model, lines, with_stiffness)
    mats, scales, is_k = _param_basis(model, with_stiffness)
    w = 2 * np.pi * f
    A = model.accelerance_at_origin(f)  # (L, 6, 6)
    eye = np.eye(3)
    n_s = candidates.sensor_xyz.shape[0]
    r_xyz = np.repeat(candidates.sensor_xyz, 3, axis=0)
    r_dir = np.tile(eye, (n_s, 1))
    Ec = response_matrix(r_xyz, r_dir)  # (n_r, 6)
    Tc = excitation_matrix(candidates.exc_xyz, candidates.exc_dirs)  # (6, n_e)
    u = np.einsum("ra,lab->lrb", Ec, A)  # (L, n_r, 6): e^T A
    v = np.einsum("lab,be->leb", A, Tc)  # (L, n_e, 6): A t
    H = np.einsum("lrb,leb->lre", u, v)  # (L, n_r, n_e)
    fs = lines[np.unique(np.linspace(0, lines.size - 1, min(256, lines.size)).round()
                         .astype(int))]
    Hs = np.einsum("ra,lab,be->rel", Ec, model.accelerance_at_origin(fs), Tc)
    rms2 = np.mean(np.abs(Hs) ** 2, axis=2)  # (n_r, n_e)
    noise = max(conditions.noise, NOISE_FLOOR)
    var = noise**2 * (rms2[None] + np.abs(H) ** 2) / conditions.averages
    iv = wt[:, None, None] / np.maximum(var, 1e-300)  # (L, n_r, n_e)
    Bv = np.einsum("pab,leb->lepa", mats, v)  # (L, n_e, p, 6)
    div = np.where(is_k[None, :], 1.0 / (w**2)[:, None], 1.0) * scales  # (L, p)
    n_e, n_par = Tc.shape[1], mats.shape[0]
    F = np.zeros((n_s, n_e, n_par, n_par))
    chunk = max(1, 1_500_000 // (n_e * f.size * n_par * 3))
    for s0 in range(0, n_s, chunk):  # chunks of sensors bound the memory
        s1 = min(n_s, s0 + chunk)
        rows = slice(3 * s0, 3 * s1)
        g = -np.einsum("lra,lepa->lrep", u[:, rows], Bv) * div[:, None, None, :]
        giv = np.conj(g) * iv[:, rows, :, None]  # (L, r, e, p)
        F[s0:s1] = np.einsum("lrep,lreq->reqp", giv, g).real.reshape(
            s1 - s0, 3, n_e, n_par, n_par).sum(axis=1)
    basis = (mats[:10] * scales[:10, None, None]).reshape(10, 36).T  # (36, 10)
    proj = np.zeros((n_par, 36))
    proj[:10] = np.linalg.pinv(basis)
    return Information(F, Ec.reshape(n_s, 3, 6), Tc.T.copy(), candidates.sensor_xyz,
                       candidates.exc_dirs, model.M, proj, conditions.stated, scales)


# --- the search ------------------------------------------------------------------------------


def criterion_value(F: NDArray[np.float64], C: NDArray[np.float64] | float,
                    criterion: Criterion) -> NDArray[np.float64]:
    """The criterion (to be *minimised*) of the covariance ``F^-1 + C`` of the scaled
    parameters (noise, and the test errors' ``C`` of :func:`test_error_cov`), for stacks
    ``F``, ``C`` (..., p, p): its log-determinant (D) or trace (A); +inf where F is
    singular."""
    F = 0.5 * (F + np.swapaxes(F, -1, -2))
    ev, V = np.linalg.eigh(F)
    ok = ev[..., 0] > ev[..., -1] * 1e-13
    inv = np.einsum("...ik,...k,...jk->...ij", V, 1.0 / np.where(ok[..., None], ev, 1.0), V)
    cov = inv + C
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    if criterion == "D":
        sign, logdet = np.linalg.slogdet(cov)
        return np.where(ok & (sign > 0), logdet, np.inf)
    return np.where(ok, np.trace(cov, axis1=-2, axis2=-1), np.inf)


def _rank(sets: NDArray[np.float64]) -> NDArray[np.int64]:
    """Rank of each (..., n, 6) matrix (relative tolerance :data:`RANK_TOL`)."""
    s = np.linalg.svd(sets, compute_uv=False)
    return np.sum(s > RANK_TOL * s[..., :1], axis=-1)


def _rank_ok(sets: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether each (..., n, 6) matrix has rank 6."""
    return _rank(sets) >= 6


def _ix(rows: ArrayLike, cols: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``np.ix_`` of two index lists."""
    r, c = np.ix_(np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64))
    return r, c


@dataclass(frozen=True)
class Layout:
    """Chosen candidate indices: ``sensors`` into the candidate sensors, ``excitations`` into
    the candidate excitation DOFs; the criterion's value (minimised) and the steps taken."""

    sensors: tuple[int, ...]
    excitations: tuple[int, ...]
    value: float
    steps: int


def layout_value(info: Information, sensors: list[int] | tuple[int, ...],
                 excitations: list[int] | tuple[int, ...], criterion: Criterion) -> float:
    """The criterion of one layout."""
    S, P = list(sensors), list(excitations)
    F = info.F[_ix(S, P)].sum(axis=(0, 1))
    C = test_error_cov(info, np.array([S]), np.array([P]))[0]
    return float(criterion_value(F, C, criterion))


def search(info: Information, candidates: Candidates, n_sensors: int, n_points: int,
           criterion: Criterion = "D", *, max_passes: int = 20) -> Layout:
    """Greedy additions, then exchange passes, on the :class:`Information` of
    :func:`fisher_blocks`: sensors first (with every excitation candidate), then the
    excitations (with those sensors), then one sensor or one excitation exchanged at a time
    for the best candidate until no exchange lowers the criterion. Only layouts whose E and
    T have rank 6 (rotations scaled by the points' size) are taken.

    Raises
    ------
    PlanningError
        Too few candidates, or no rank-6 layout of that size among them.
    """
    n_s, n_e = info.F.shape[:2]
    if n_sensors < 3:
        raise PlanningError(f"ask for at least 3 sensors (triaxial, not on one line: two "
                            f"leave the rotation about their line unseen), got {n_sensors}")
    if n_points < 6:
        raise PlanningError(f"ask for at least 6 excitation points (rank 6), got {n_points}")
    if n_sensors > n_s:
        raise PlanningError(f"{n_sensors} sensors asked for but only {n_s} candidate sensor "
                            "positions given")
    if n_points > n_e:
        raise PlanningError(f"{n_points} excitation points asked for but only {n_e} candidate "
                            "excitation directions given")
    return _Search(info, candidates, n_sensors, n_points, criterion).run(max_passes)


class _Search:
    """The state of :func:`search`: the candidates' E rows and T columns (rotations scaled),
    and the criterion of a layout grown or changed by one candidate, for every candidate."""

    def __init__(self, info: Information, candidates: Candidates, n_sensors: int,
                 n_points: int, criterion: Criterion) -> None:
        self.info, self.criterion = info, criterion
        self.n_sensors, self.n_points = n_sensors, n_points
        self.n_s, self.n_e = info.F.shape[:2]
        L = characteristic_length(candidates.sensor_xyz, candidates.point_xyz)
        scale = np.array([1.0, 1.0, 1.0, L, L, L])
        eye = np.eye(3)
        self.Es = np.stack([response_matrix(np.repeat(p[None], 3, 0), eye) for p in
                            candidates.sensor_xyz]) / scale  # (n_s, 3, 6)
        self.Te = (excitation_matrix(candidates.exc_xyz, candidates.exc_dirs)
                   / scale[:, None]).T
        if not _rank_ok(self.Es.reshape(1, -1, 6))[0]:
            raise PlanningError("the candidate sensor positions cannot span the six "
                                "rigid-body motions (rank < 6: are they on one line?): add "
                                "positions off it")
        if not _rank_ok(self.Te[None])[0]:
            raise PlanningError("the candidate excitations cannot span the six rigid-body "
                                "motions (rank < 6): add points or allowed directions")
        n_par = info.F.shape[-1]
        self.ridge = 1e-9 * max(float(np.trace(info.F.sum(axis=(0, 1)))) / n_par,
                                1e-300) * np.eye(n_par)
        self.steps = 0

    def e_ok(self, rest: list[int], free: NDArray[np.int64], need: int = 6
             ) -> NDArray[np.bool_]:
        """E of ``rest`` + each free sensor has rank ``need`` at least."""
        return _rank(np.concatenate([np.broadcast_to(self.Es[rest].reshape(-1, 6),
                                                     (free.size, 3 * len(rest), 6)),
                                     self.Es[free]], axis=1)) >= need

    def t_ok(self, rest: list[int], free: NDArray[np.int64], need: int = 6,
             cond: bool = True) -> NDArray[np.bool_]:
        """Rank ``need`` at least; with ``cond``, cond(T) under the fit's limit too (the fit
        drops every line of a worse T)."""
        sets = np.concatenate([np.broadcast_to(self.Te[rest], (free.size, len(rest), 6)),
                               self.Te[free][:, None]], axis=1)
        sv = np.linalg.svd(sets, compute_uv=False)
        rank = np.sum(sv > RANK_TOL * sv[..., :1], axis=-1)
        if need < 6 or not cond:
            return rank >= need
        return (rank >= 6) & (sv[..., 0] < MAX_COND_T * sv[..., -1])

    @staticmethod
    def _grown(rest: list[int], free: NDArray[np.int64]) -> NDArray[np.int64]:
        """(n_free, len(rest) + 1): ``rest`` with each free candidate."""
        return np.concatenate([np.broadcast_to(np.array(rest, dtype=np.int64),
                                               (free.size, len(rest))), free[:, None]], axis=1)

    def sensor_values(self, rest: list[int], P: list[int], free: NDArray[np.int64]
                      ) -> NDArray[np.float64]:
        """Criterion of ``rest`` + each free sensor, with excitations ``P``."""
        info = self.info
        F = self.ridge + info.F[_ix(rest, P)].sum(axis=(0, 1)) + info.F[_ix(free, P)].sum(1)
        C = test_error_cov(info, self._grown(rest, free),
                           np.broadcast_to(np.array(P), (free.size, len(P))))
        return criterion_value(F, C, self.criterion)

    def point_values(self, S: list[int], rest: list[int], free: NDArray[np.int64]
                     ) -> NDArray[np.float64]:
        """Criterion of excitations ``rest`` + each free one, with sensors ``S``."""
        info = self.info
        F = self.ridge + info.F[_ix(S, rest)].sum(axis=(0, 1)) + info.F[_ix(S, free)].sum(0)
        C = test_error_cov(info, np.broadcast_to(np.array(S), (free.size, len(S))),
                           self._grown(rest, free))
        return criterion_value(F, C, self.criterion)

    def best_of(self, vals: NDArray[np.float64], feas: NDArray[np.bool_], what: str) -> int:
        if not np.any(feas):
            raise PlanningError(f"no layout of {self.n_sensors} sensors and {self.n_points} "
                                f"excitations among the candidates has a rank-6 {what} "
                                "matrix: add candidates or ask for more")
        vals = np.where(feas, vals, np.inf)
        return int(np.argmin(vals)) if np.any(np.isfinite(vals)) else int(np.argmax(feas))

    def greedy(self) -> tuple[list[int], list[int], bool]:
        """Sensors, then excitations, added one at a time keeping the rank growing to 6
        (3, 5, 6 for triaxial sensors: two points leave the rotation about the line through
        them unseen); and whether cond(T) could be kept under the limit."""
        S: list[int] = []
        every = list(range(self.n_e))
        for k in range(self.n_sensors):  # 1. sensors, against every excitation candidate
            free = np.setdiff1d(np.arange(self.n_s), S)
            feas = self.e_ok(S, free, (3, 5, 6)[min(k, 2)])
            S.append(int(free[self.best_of(self.sensor_values(S, every, free), feas,
                                           "response")]))
            self.steps += 1
        P: list[int] = []
        well = True
        for k in range(self.n_points):  # 2. excitations, with those sensors
            free = np.setdiff1d(np.arange(self.n_e), P)
            last = k == self.n_points - 1
            feas = self.t_ok(P, free, min(k + 1, 6), cond=last)
            if last:
                well = bool(np.any(feas))
                if not well:  # none under the limit: rank 6 at least
                    feas = self.t_ok(P, free, cond=False)
            P.append(int(free[self.best_of(self.point_values(S, P, free), feas,
                                           "excitation")]))
            self.steps += 1
        return S, P, well

    def run(self, max_passes: int) -> Layout:
        """The greedy layout, then exchanges of one sensor or one excitation at a time."""
        S, P, well = self.greedy()
        best = layout_value(self.info, S, P, self.criterion)
        for _ in range(max_passes):  # 3. exchanges
            improved = False
            for slot in range(self.n_sensors):
                rest = S[:slot] + S[slot + 1:]
                free = np.setdiff1d(np.arange(self.n_s), S)
                if free.size == 0:
                    break
                vals = np.where(self.e_ok(rest, free), self.sensor_values(rest, P, free),
                                np.inf)
                k = int(np.argmin(vals))
                if vals[k] < best - 1e-9 * max(1.0, abs(best)):
                    S[slot], best, improved = int(free[k]), float(vals[k]), True
                    self.steps += 1
            for slot in range(self.n_points):
                rest = P[:slot] + P[slot + 1:]
                free = np.setdiff1d(np.arange(self.n_e), P)
                if free.size == 0:
                    break
                vals = np.where(self.t_ok(rest, free, cond=well),
                                self.point_values(S, rest, free), np.inf)
                k = int(np.argmin(vals))
                if vals[k] < best - 1e-9 * max(1.0, abs(best)):
                    P[slot], best, improved = int(free[k]), float(vals[k]), True
                    self.steps += 1
            if not improved:
                break
        return Layout(tuple(S), tuple(P), best, self.steps)


# --- the prediction --------------------------------------------------------------------------


@dataclass(frozen=True)
class Prediction:
    """Predicted standard deviations (SI) of the identified numbers for one layout.

    ``std`` holds ``mass``, ``cog`` (3,), ``inertia_cog`` and ``inertia_origin`` (3, 3),
    ``principal_moments`` (3,), ``stiffness`` and ``damping`` (6, 6): the root median of the
    identification's variances over the noise realisations. ``linearised`` holds the search's
    own first-order std of the ten parameters about O (``theta``, (10,)). ``sources`` says
    what the identification propagated; ``mass_band`` the mass line it chose (Hz).
    """

    std: dict[str, NDArray[np.float64]]
    linearised: NDArray[np.float64]
    sources: tuple[str, ...]
    mass_band: tuple[float, float]
    geometry: GeometryReport


def _h1(H: NDArray[np.complex128], noise: float, averages: int, rng: np.random.Generator,
        ) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """H1 and coherence (n_r, n_e, n_f) of ``averages`` unit random force spectra per
    excitation with complex Gaussian noise of ``noise`` times each channel's RMS (the force's
    and every response's over the run) on force and responses."""
    n_r, n_e, n_f = H.shape
    if noise <= 0:
        return H.copy(), np.ones(H.shape)

    def cn(*size: int) -> NDArray[np.complex128]:
        return (rng.normal(size=size) + 1j * rng.normal(size=size)) / np.sqrt(2)

    F = cn(n_e, averages, n_f)
    X = H[:, :, None, :] * F[None]  # (n_r, n_e, n_avg, n_f)
    rms_f = np.sqrt(np.mean(np.abs(F) ** 2, axis=(1, 2)))  # (n_e,)
    rms_x = np.sqrt(np.mean(np.abs(X) ** 2, axis=(2, 3)))  # (n_r, n_e)
    Fm = F + noise * rms_f[:, None, None] * cn(n_e, averages, n_f)
    Xm = X + noise * rms_x[..., None, None] * cn(n_r, n_e, averages, n_f)
    Sff = np.sum(np.abs(Fm) ** 2, axis=1)  # (n_e, n_f)
    Sfx = np.sum(np.conj(Fm)[None] * Xm, axis=2)  # (n_r, n_e, n_f)
    Sxx = np.sum(np.abs(Xm) ** 2, axis=2)
    return Sfx / Sff[None], np.abs(Sfx) ** 2 / (Sff[None] * Sxx)


#: the generic elastic modes of the prediction: their frequencies over the expected first
#: elastic mode (which shape takes which is drawn per noise realisation), their loss
#: factor, and the top of the lines the prediction synthesises over the first elastic mode
ELASTIC_RATIOS = (1.0, 1.5, 2.0)
ELASTIC_LOSS = 0.01
ELASTIC_TOP = 3.0
#: the generic box's shortest half size, over its longest (a model whose moments no box has)
MIN_HALF = 0.3


class GenericElastic:
    """Deformation fields standing for the unit's unknown first elastic modes: bending in
    the two planes through the longest principal axis (``u = q_1^2`` across it, with the
    beam's ``-2 q_1 q_k`` along it) and torsion about that axis (``u = q_1 (e_1 x q)``), on
    the uniform box with the model's mass and principal moments (each half size at least
    :data:`MIN_HALF` of the longest), made orthogonal to the six rigid-body motions and to
    each other and mass-normalised over the box, as elastic modes are. A free beam's first
    bending mode reads ``phi^2 m = 4`` at its ends; these read 5."""

    def __init__(self, model: ApproximateModel) -> None:
        ev, V = np.linalg.eigh(0.5 * (model.inertia_cog + model.inertia_cog.T))
        # a uniform box: I_1 = m (b^2 + c^2) / 12 ...; its half sizes, longest first
        sq = 6.0 * (ev.sum() - 2 * ev) / model.mass
        half = 0.5 * np.sqrt(np.clip(sq, 0.0, None))
        order = np.argsort(half)[::-1]
        self.half = np.maximum(half[order], MIN_HALF * half.max())
        self.V, self.cog, self.mass = V[:, order], model.cog, model.mass
        axes = [h * (np.arange(8) * 2 - 7) / 8 for h in self.half]  # cell centres
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) @ self.V.T
        grid += self.cog
        # each grid point read along the three axes, by the fields and the rigid motions
        Ug = self._fields(grid).reshape(-1, 3)
        Rg = response_matrix(np.repeat(grid - self.cog, 3, axis=0),
                             np.tile(np.eye(3), (grid.shape[0], 1)))
        self.coef = np.linalg.lstsq(Rg, Ug, rcond=None)[0]
        A = Ug - Rg @ self.coef
        # mass-normalised (the mean of |u|^2 over the box 1 / m) and orthogonal, each field
        # kept as close to its own shape as can be (G^-1/2, G the fields' Gram matrix)
        ev_g, Vg = np.linalg.eigh(A.T @ A * (self.mass / grid.shape[0]))
        self.W = (Vg / np.sqrt(ev_g)) @ Vg.T

    def _fields(self, xyz: NDArray[np.float64]) -> NDArray[np.float64]:
        """The three fields (n, 3, 3): global components, field."""
        q = ((xyz - self.cog) @ self.V) / self.half[0]
        local = np.zeros((xyz.shape[0], 3, 3))
        local[:, 1, 0], local[:, 0, 0] = q[:, 0] ** 2, -2 * q[:, 0] * q[:, 1]  # bending 1-2
        local[:, 2, 1], local[:, 0, 1] = q[:, 0] ** 2, -2 * q[:, 0] * q[:, 2]  # bending 1-3
        local[:, 1, 2], local[:, 2, 2] = -q[:, 0] * q[:, 2], q[:, 0] * q[:, 1]  # torsion
        return np.asarray(np.einsum("ck,nkj->ncj", self.V, local))

    def at(self, xyz: NDArray[np.float64], dirs: NDArray[np.float64]) -> NDArray[np.float64]:
        """The mass-normalised shapes read along ``dirs`` at ``xyz``: (n, 3)."""
        u = (np.einsum("ncj,nc->nj", self._fields(xyz), dirs)
             - response_matrix(xyz - self.cog, dirs) @ self.coef)  # less its rigid part
        return np.asarray(u @ self.W)

    def accelerance(self, freq: NDArray[np.float64], first_hz: float,
                    resp: NDArray[np.float64], exc: NDArray[np.float64],
                    rng: np.random.Generator) -> NDArray[np.complex128]:
        """Accelerance (n_r, n_e, n_f) of the three shapes at :data:`ELASTIC_RATIOS` times
        ``first_hz`` in a random order; ``resp``, ``exc``: :meth:`at` of the channels and
        of the forces."""
        w = 2 * np.pi * freq
        wr = 2 * np.pi * first_hz * np.asarray(ELASTIC_RATIOS)[rng.permutation(3)]
        g = -(w**2) / (wr[:, None] ** 2 - w**2 + 1j * ELASTIC_LOSS * wr[:, None] ** 2)
        return np.asarray(np.einsum("rk,ek,kf->ref", resp, exc, g))


def _elastic_part(model: ApproximateModel, first_hz: float, lines: NDArray[np.float64],
                  r_xyz: NDArray[np.float64], r_dir: NDArray[np.float64],
                  ex: NDArray[np.float64], ed: NDArray[np.float64],
                  ) -> Callable[[np.random.Generator], NDArray[np.complex128]]:
    """Draws of the generic elastic modes' accelerance between the layout's channels and
    forces on ``lines`` (:class:`GenericElastic`)."""
    gen = GenericElastic(model)
    resp, exc = gen.at(r_xyz, r_dir), gen.at(ex, ed)
    return lambda rng: gen.accelerance(lines, first_hz, resp, exc, rng)


def predict(model: ApproximateModel, resp_xyz: ArrayLike, exc_xyz: ArrayLike,
            exc_dirs: ArrayLike, conditions: TestConditions, *,
            resp_nodes: ArrayLike | None = None, exc_nodes: ArrayLike | None = None,
            linearised: NDArray[np.float64] | None = None) -> Prediction:
    """Predicted standard deviations of a layout: triaxial sensors at ``resp_xyz`` (n_s, 3)
    along the global axes, forces at ``exc_xyz`` along ``exc_dirs``, by the identification
    itself (see the module's notes): the model's FRFs with H1 noise, fitted by
    :func:`processing.identify.fit` with the stated test uncertainties, per noise
    realisation; the variances are averaged."""
    rx = np.asarray(resp_xyz, dtype=float).reshape(-1, 3)
    ex = np.asarray(exc_xyz, dtype=float).reshape(-1, 3)
    ed = np.asarray(exc_dirs, dtype=float).reshape(-1, 3)
    n_s, n_e = rx.shape[0], ex.shape[0]
    r_xyz, r_dir = np.repeat(rx, 3, axis=0), np.tile(np.eye(3), (n_s, 1))
    rn = (np.arange(1, n_s + 1) if resp_nodes is None else np.asarray(resp_nodes)).astype(
        np.int64)
    en = (np.arange(1, n_e + 1) + 1000 if exc_nodes is None else np.asarray(exc_nodes)
          ).astype(np.int64)
    geo = check_geometry(r_xyz, r_dir, ex, ed)
    if not geo.ok:
        raise PlanningError("; ".join(geo.messages))
    elastic = model.first_elastic_hz
    lines = conditions.lines(model)
    if elastic is not None:  # with the elastic modes: the test's lines up to ELASTIC_TOP x
        lines = conditions.freq[conditions.freq <= ELASTIC_TOP * elastic]
    H0 = synthesise(lines, response_matrix(r_xyz, r_dir), excitation_matrix(ex, ed), model.M,
                    model.K, model.C, model.D)
    flex = None if elastic is None else _elastic_part(model, elastic, lines, r_xyz, r_dir, ex, ed)
    nodes: dict[int, NDArray[np.float64]] = {}
    for n, p in zip([*rn, *en], [*rx, *ex], strict=True):
        nodes.setdefault(int(n), p)
    ids = np.array(sorted(nodes), dtype=np.int64)
    geometry = Geometry(ids, np.array([nodes[i] for i in ids]))
    rng = np.random.default_rng([conditions.seed, 31])
    var: dict[str, list[NDArray[np.float64]]] = {}
    sources: tuple[str, ...] = ()
    band = (0.0, 0.0)
    # the model's FRFs have no channel delay to read: the search for them (a few fits more,
    # processing.identify) would only cost time (3-4x on flexible units, the same std)
    options = IdentifyOptions(stated=conditions.stated if conditions.stated.stated else None,
                              channel_delays="off")
    for _ in range(conditions.realisations):
        H, coh = _h1(H0 if flex is None else H0 + flex(rng), conditions.noise,
                     conditions.averages, rng)
        frf = FRFSet(lines, H, np.repeat(rn, 3), r_dir, en, ed, geometry, coherence=coh)
        try:
            result = fit(Measurement(frf, source="plan"), options)
        except InputError as err:
            raise PlanningError(f"the identification of the chosen layout's predicted FRFs "
                                f"fails: {err}") from err
        unc = result.uncertainty
        if unc is None:
            raise PlanningError("the identification of the model's FRFs gave no uncertainty")
        for k, v in unc.std.items():
            var.setdefault(k, []).append(np.asarray(v) ** 2)
        sources, band = unc.sources, result.mass_band
    lin = np.full(10, np.nan) if linearised is None else linearised
    # the median variance over the realisations: one realisation whose band lands on an
    # elastic mode's flank does not decide the prediction
    return Prediction({k: np.sqrt(np.median(v, axis=0)) for k, v in var.items()}, lin,
                      sources, band, geo)


# --- the whole planning ----------------------------------------------------------------------


@dataclass(frozen=True)
class TestDesign:
    """A planned test: the chosen candidate indices, the criterion, the prediction."""

    layout: Layout
    criterion: Criterion
    with_stiffness: bool
    candidates: Candidates
    prediction: Prediction | None

    __test__ = False

    @property
    def sensor_xyz(self) -> NDArray[np.float64]:
        return self.candidates.sensor_xyz[list(self.layout.sensors)]

    @property
    def exc_xyz(self) -> NDArray[np.float64]:
        return self.candidates.exc_xyz[list(self.layout.excitations)]

    @property
    def exc_dirs(self) -> NDArray[np.float64]:
        return self.candidates.exc_dirs[list(self.layout.excitations)]


def linearised_std(info: Information, layout: Layout) -> NDArray[np.float64]:
    """The search's first-order std of the ten parameters about O for ``layout`` (SI):
    the diagonal of ``F^-1 + C_test`` (see :class:`Information`)."""
    S, P = list(layout.sensors), list(layout.excitations)
    F = info.F[_ix(S, P)].sum(axis=(0, 1))
    C = test_error_cov(info, np.array([S]), np.array([P]))[0]
    try:
        Fi = np.linalg.inv(0.5 * (F + F.T))
    except np.linalg.LinAlgError:
        return np.full(10, np.inf)
    cov = Fi + C
    return np.sqrt(np.clip(np.diag(cov)[:10], 0, None)) * info.scales[:10]


def plan_test(model: ApproximateModel, candidates: Candidates, n_sensors: int, n_points: int,
              conditions: TestConditions, *, criterion: Criterion = "D",
              with_stiffness: bool = False, predicted: bool = True) -> TestDesign:
    """Choose ``n_sensors`` triaxial sensors and ``n_points`` excitations among the
    candidates (:func:`search` on :func:`fisher_blocks`) and predict the identification's
    standard deviations for them (:func:`predict`; ``predicted=False`` skips it).

    Raises
    ------
    PlanningError
        With one line naming what to change.
    """
    if criterion not in ("D", "A"):
        raise PlanningError(f"criterion must be 'D' or 'A', got {criterion!r}")
    info = fisher_blocks(model, candidates, conditions, with_stiffness=with_stiffness)
    layout = search(info, candidates, n_sensors, n_points, criterion)
    pred = None
    if predicted:
        S, P = list(layout.sensors), list(layout.excitations)
        pred = predict(model, candidates.sensor_xyz[S], candidates.exc_xyz[P],
                       candidates.exc_dirs[P], conditions,
                       resp_nodes=candidates.sensor_nodes[S], exc_nodes=candidates.exc_nodes[P],
                       linearised=linearised_std(info, layout))
    return TestDesign(layout, criterion, with_stiffness, candidates, pred)
