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
"""

from __future__ import annotations

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
    "Layout",
    "PlanningError",
    "Prediction",
    "TestConditions",
    "TestDesign",
    "box_inertia",
    "criterion_value",
    "fisher_blocks",
    "mount_stiffness",
    "plan_test",
    "predict",
    "search",
]

Criterion = Literal["D", "A"]

#: lines of each band the search's information is summed over (spread over the band)
CRITERION_LINES = 48
#: a layout whose scaled E or T has a singular value under this fraction of its largest
#: is rank-deficient
RANK_TOL = 1e-6


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
        return -(w**2)[:, None, None] * np.linalg.inv(Z)


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
    realisations : noise realisations whose predicted variances are averaged
    """

    freq: NDArray[np.float64]
    noise: float = 0.01
    averages: int = 5
    stated: StatedUncertainty = field(default_factory=StatedUncertainty)
    seed: int = 0
    realisations: int = 2

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
    mats = [b for b in MASS_BASIS]
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


def fisher_blocks(model: ApproximateModel, candidates: Candidates, conditions: TestConditions,
                  *, with_stiffness: bool = False) -> NDArray[np.float64]:
    """Information (n_s, n_e, n_par, n_par) of every candidate sensor (its three channels)
    with every candidate excitation DOF, in scaled parameters (see the module's notes).

    Sums over the sub-sampled lines of the mass line (and the stiffness band with K) with
    their weights; the noise variance of an FRF value is ``noise^2 (rms^2 + |H|^2) / n`` with
    ``rms`` the FRF's RMS over all lines, and the stated test errors add their first-order
    variance times the band's line count (the same on every line, they do not average out).
    """
    lines = conditions.lines(model)
    f, wt = _bands(model, lines, with_stiffness)
    mats, scales, is_k = _param_basis(model, with_stiffness)
    w = 2 * np.pi * f
    A = model.accelerance_at_origin(f)  # (L, 6, 6)
    eye = np.eye(3)
    # channels: 3 per sensor, global axes
    r_xyz = np.repeat(candidates.sensor_xyz, 3, axis=0)
    r_dir = np.tile(eye, (candidates.sensor_xyz.shape[0], 1))
    Ec = response_matrix(r_xyz, r_dir)  # (n_r, 6)
    Tc = excitation_matrix(candidates.exc_xyz, candidates.exc_dirs)  # (6, n_e)
    u = np.einsum("ra,lab->lrb", Ec, A)  # (L, n_r, 6): e^T A
    v = np.einsum("lab,be->lea", A, Tc)  # (L, n_e, 6): A t
    H = np.einsum("lrb,leb->rel", u, v)  # (n_r, n_e, L)
    # noise: relative to the record's RMS over all the test's lines (accelerance of the
    # model on the full span, approximated on a sub-sample)
    fs = lines[np.unique(np.linspace(0, lines.size - 1, min(256, lines.size)).round()
                         .astype(int))]
    As = model.accelerance_at_origin(fs)
    Hs = np.einsum("ra,lab,be->rel", Ec, As, Tc)
    rms2 = np.mean(np.abs(Hs) ** 2, axis=2)  # (n_r, n_e)
    noise2 = conditions.noise**2 * (rms2[..., None] + np.abs(H) ** 2) / conditions.averages
    st = conditions.stated
    n_band = float(np.sum(wt))
    sys2 = np.zeros(H.shape)
    if st.gain > 0:
        sys2 += st.gain**2 * np.abs(H) ** 2
    if st.location > 0:  # sensor offset: (delta x d) . alpha ; point offset: (delta x e) . u_rot
        s_loc = np.cross(r_dir[None, :, None, :], v[:, None, :, 3:])  # (L, n_r, n_e, 3)
        p_loc = np.cross(candidates.exc_dirs[None, None, :, :], u[:, :, None, 3:])
        sys2 += st.location**2 * np.transpose(
            np.sum(np.abs(s_loc) ** 2, axis=-1) + np.sum(np.abs(p_loc) ** 2, axis=-1),
            (1, 2, 0))
    if st.angle > 0:  # the channel's direction tilted: the point's acceleration across it
        acc = v[:, None, :, :3] + np.cross(v[:, None, :, 3:], r_xyz[None, :, None, :])
        across = acc - np.einsum("lrek,rk->lre", acc, r_dir)[..., None] * r_dir[None, :, None]
        sys2 += st.angle**2 * np.transpose(np.sum(np.abs(across) ** 2, axis=-1), (1, 2, 0))
    var = noise2 + n_band * sys2
    var = np.maximum(var, 1e-12 * np.max(var) if np.max(var) > 0 else 1e-300)
    # sensitivities g = -u^T dA^-1... : dH/dp = -u^T B_p v (mass) and the same / w^2 (K)
    Bv = np.einsum("pab,leb->lepa", mats, v)  # (L, n_e, n_par, 6)
    div = np.where(is_k[None, :], 1.0 / (w**2)[:, None], 1.0)  # (L, n_par)
    n_s, n_e, n_par = candidates.sensor_xyz.shape[0], Tc.shape[1], mats.shape[0]
    out = np.zeros((n_s, n_e, n_par, n_par))
    wl = wt[:, None, None]
    chunk = max(1, 2_000_000 // (n_e * f.size * n_par * 3))
    for s0 in range(0, n_s, chunk):  # chunks of sensors bound the memory
        rows = slice(3 * s0, 3 * min(n_s, s0 + chunk))
        g = -np.einsum("lra,lepa->lrep", u[:, rows], Bv) * (div * scales)[:, None, None, :]
        iv = (wl / np.transpose(var[rows], (2, 0, 1)))[..., None]  # (L, n_r, n_e, 1)
        G = np.einsum("lrep,lreq->reqp", np.conj(g), g * iv).real  # (n_r, n_e, p, p)
        out[s0:s0 + (rows.stop - rows.start) // 3] = G.reshape(-1, 3, n_e, n_par, n_par
                                                               ).sum(axis=1)
    return out


# --- the search ------------------------------------------------------------------------------


def criterion_value(F: NDArray[np.float64], criterion: Criterion) -> NDArray[np.float64]:
    """The criterion of information matrices ``F`` (..., p, p) to be *minimised*:
    ``-log det F`` (D) or ``trace F^-1`` (A); +inf where F is singular."""
    F = 0.5 * (F + np.swapaxes(F, -1, -2))
    if criterion == "D":
        sign, logdet = np.linalg.slogdet(F)
        return np.where(sign > 0, -logdet, np.inf)
    ev = np.linalg.eigvalsh(F)
    ok = ev[..., 0] > ev[..., -1] * 1e-13
    return np.where(ok, np.sum(1.0 / np.where(ok[..., None], ev, 1.0), axis=-1), np.inf)


def _rank_ok(sets: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether each (..., 6, n) or (..., n, 6) matrix has rank 6 (relative tolerance)."""
    s = np.linalg.svd(sets, compute_uv=False)
    return (s[..., 5] > RANK_TOL * s[..., 0]) if s.shape[-1] >= 6 else np.zeros(s.shape[:-1],
                                                                                 bool)


@dataclass(frozen=True)
class Layout:
    """Chosen candidate indices: ``sensors`` into the candidate sensors, ``excitations`` into
    the candidate excitation DOFs; the criterion's value (minimised) and its path."""

    sensors: tuple[int, ...]
    excitations: tuple[int, ...]
    value: float
    steps: int


def search(blocks: NDArray[np.float64], candidates: Candidates, n_sensors: int, n_points: int,
           criterion: Criterion = "D", *, max_passes: int = 20) -> Layout:
    """Greedy additions, then exchange passes, on the information ``blocks`` of
    :func:`fisher_blocks`: sensors first (with every excitation candidate), then the
    excitations (with those sensors), then one sensor or one excitation exchanged at a time
    for the best candidate until no exchange lowers the criterion. Only layouts whose E and
    T have rank 6 (rotations scaled by the points' size) are taken.

    Raises
    ------
    PlanningError
        Too few candidates, or no rank-6 layout of that size among them.
    """
    n_s, n_e = blocks.shape[:2]
    if n_sensors < 2:
        raise PlanningError(f"ask for at least 2 sensors (triaxial, not on one line), got "
                            f"{n_sensors}")
    if n_points < 6:
        raise PlanningError(f"ask for at least 6 excitation points (rank 6), got {n_points}")
    if n_sensors > n_s:
        raise PlanningError(f"{n_sensors} sensors asked for but only {n_s} candidate sensor "
                            "positions given")
    if n_points > n_e:
        raise PlanningError(f"{n_points} excitation points asked for but only {n_e} candidate "
                            "excitation directions given")
    L = characteristic_length(candidates.sensor_xyz, candidates.point_xyz)
    scale = np.array([1.0, 1.0, 1.0, L, L, L])
    eye = np.eye(3)
    Es = np.stack([response_matrix(np.repeat(p[None], 3, 0), eye) for p in
                   candidates.sensor_xyz]) / scale  # (n_s, 3, 6)
    Te = (excitation_matrix(candidates.exc_xyz, candidates.exc_dirs) / scale[:, None]).T
    if not _rank_ok(Es.reshape(1, -1, 6))[0]:
        raise PlanningError("the candidate sensor positions cannot span the six rigid-body "
                            "motions (rank < 6: are they on one line?): add positions off it")
    if not _rank_ok(Te[None])[0]:
        raise PlanningError("the candidate excitations cannot span the six rigid-body motions "
                            "(rank < 6): add points or allowed directions")
    n_par = blocks.shape[-1]
    ridge = 1e-12 * max(float(np.trace(blocks.sum(axis=(0, 1)))) / n_par, 1e-300) * np.eye(n_par)
    steps = 0

    def pick(values: NDArray[np.float64], feasible: NDArray[np.bool_], what: str) -> int:
        vals = np.where(feasible, values, np.inf)
        if not np.any(np.isfinite(vals)) and not np.any(feasible):
            raise PlanningError(f"no layout of {n_sensors} sensors and {n_points} excitations "
                                f"among the candidates has a rank-6 {what} matrix: add "
                                "candidates or ask for more")
        if not np.any(np.isfinite(vals)):
            return int(np.flatnonzero(feasible)[0])
        return int(np.nanargmin(vals))

    # 1. sensors, against every excitation candidate
    per_sensor = blocks.sum(axis=1)  # (n_s, p, p)
    S: list[int] = []
    F = ridge.copy()
    for k in range(n_sensors):
        free = np.setdiff1d(np.arange(n_s), S)
        vals = criterion_value(F + per_sensor[free], criterion)
        feas = np.ones(free.size, bool)
        if k == n_sensors - 1:  # the last one must make E rank 6
            feas = _rank_ok(np.concatenate([np.broadcast_to(Es[S].reshape(-1, 6),
                                                            (free.size, 3 * len(S), 6)),
                                            Es[free]], axis=1))
        j = int(free[pick(vals, feas, "response")])
        S.append(j)
        F = F + per_sensor[j]
        steps += 1
    # 2. excitations, with those sensors
    per_exc = blocks[S].sum(axis=0)  # (n_e, p, p)
    P: list[int] = []
    F = ridge.copy()
    for k in range(n_points):
        free = np.setdiff1d(np.arange(n_e), P)
        vals = criterion_value(F + per_exc[free], criterion)
        feas = np.ones(free.size, bool)
        if k == n_points - 1:
            feas = _rank_ok(np.concatenate([np.broadcast_to(Te[P], (free.size, len(P), 6)),
                                            Te[free][:, None]], axis=1))
        j = int(free[pick(vals, feas, "excitation")])
        P.append(j)
        F = F + per_exc[j]
        steps += 1
    if not (_rank_ok(Es[S].reshape(1, -1, 6))[0] and _rank_ok(Te[P][None])[0]):
        raise PlanningError(f"no rank-6 layout of {n_sensors} sensors and {n_points} "
                            "excitations found among the candidates: add candidates")
    # 3. exchanges
    best = float(criterion_value(ridge + blocks[np.ix_(S, P)].sum(axis=(0, 1)), criterion))
    for _ in range(max_passes):
        improved = False
        for slot in range(n_sensors):
            rest = S[:slot] + S[slot + 1:]
            base = ridge + blocks[np.ix_(rest, P)].sum(axis=(0, 1))
            free = np.setdiff1d(np.arange(n_s), S)
            if free.size == 0:
                break
            vals = criterion_value(base + blocks[np.ix_(free, P)].sum(axis=1), criterion)
            feas = _rank_ok(np.concatenate([np.broadcast_to(Es[rest].reshape(-1, 6),
                                                            (free.size, 3 * len(rest), 6)),
                                            Es[free]], axis=1))
            vals = np.where(feas, vals, np.inf)
            k = int(np.argmin(vals))
            if vals[k] < best - 1e-9 * max(1.0, abs(best)):
                S[slot], best, improved = int(free[k]), float(vals[k]), True
                steps += 1
        for slot in range(n_points):
            rest = P[:slot] + P[slot + 1:]
            base = ridge + blocks[np.ix_(S, rest)].sum(axis=(0, 1))
            free = np.setdiff1d(np.arange(n_e), P)
            if free.size == 0:
                break
            vals = criterion_value(base + blocks[np.ix_(S, free)].sum(axis=0), criterion)
            feas = _rank_ok(np.concatenate([np.broadcast_to(Te[rest], (free.size, len(rest), 6)),
                                            Te[free][:, None]], axis=1))
            vals = np.where(feas, vals, np.inf)
            k = int(np.argmin(vals))
            if vals[k] < best - 1e-9 * max(1.0, abs(best)):
                P[slot], best, improved = int(free[k]), float(vals[k]), True
                steps += 1
        if not improved:
            break
    return Layout(tuple(S), tuple(P), best, steps)


# --- the prediction --------------------------------------------------------------------------


@dataclass(frozen=True)
class Prediction:
    """Predicted standard deviations (SI) of the identified numbers for one layout.

    ``std`` holds ``mass``, ``cog`` (3,), ``inertia_cog`` and ``inertia_origin`` (3, 3),
    ``principal_moments`` (3,), ``stiffness`` and ``damping`` (6, 6): the root mean of the
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
    lines = conditions.lines(model)
    H0 = synthesise(lines, response_matrix(r_xyz, r_dir), excitation_matrix(ex, ed), model.M,
                    model.K, model.C, model.D)
    nodes: dict[int, NDArray[np.float64]] = {}
    for n, p in zip([*rn, *en], [*rx, *ex], strict=True):
        nodes.setdefault(int(n), p)
    ids = np.array(sorted(nodes), dtype=np.int64)
    geometry = Geometry(ids, np.array([nodes[i] for i in ids]))
    rng = np.random.default_rng([conditions.seed, 31])
    var: dict[str, NDArray[np.float64]] = {}
    sources: tuple[str, ...] = ()
    band = (0.0, 0.0)
    options = IdentifyOptions(stated=conditions.stated if conditions.stated.stated else None)
    for _ in range(conditions.realisations):
        H, coh = _h1(H0, conditions.noise, conditions.averages, rng)
        frf = FRFSet(lines, H, np.repeat(rn, 3), r_dir, en, ed, geometry, coherence=coh)
        result = fit(Measurement(frf, source="plan"), options)
        unc = result.uncertainty
        if unc is None:
            raise PlanningError("the identification of the model's FRFs gave no uncertainty")
        for k, v in unc.std.items():
            var[k] = var.get(k, 0.0) + np.asarray(v) ** 2 / conditions.realisations
        sources, band = unc.sources, result.mass_band
    lin = np.full(10, np.nan) if linearised is None else linearised
    return Prediction({k: np.sqrt(v) for k, v in var.items()}, lin, sources, band, geo)


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


def linearised_std(blocks: NDArray[np.float64], layout: Layout, model: ApproximateModel,
                   with_stiffness: bool = False) -> NDArray[np.float64]:
    """The search's first-order std of the ten parameters about O for ``layout`` (SI)."""
    F = blocks[np.ix_(list(layout.sensors), list(layout.excitations))].sum(axis=(0, 1))
    _, scales, _ = _param_basis(model, with_stiffness)
    try:
        cov = np.linalg.inv(0.5 * (F + F.T))
    except np.linalg.LinAlgError:
        return np.full(10, np.inf)
    return np.sqrt(np.clip(np.diag(cov)[:10], 0, None)) * scales[:10]


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
    blocks = fisher_blocks(model, candidates, conditions, with_stiffness=with_stiffness)
    layout = search(blocks, candidates, n_sensors, n_points, criterion)
    pred = None
    if predicted:
        S, P = list(layout.sensors), list(layout.excitations)
        pred = predict(model, candidates.sensor_xyz[S], candidates.exc_xyz[P],
                       candidates.exc_dirs[P], conditions,
                       resp_nodes=candidates.sensor_nodes[S], exc_nodes=candidates.exc_nodes[P],
                       linearised=linearised_std(blocks, layout, model, with_stiffness))
    return TestDesign(layout, criterion, with_stiffness, candidates, pred)
