"""Individual mount rates and loss factors from the identified 6x6 stiffness and damping at O.

A mount at ``p`` whose local axes are the unit vectors ``a_1, a_2, a_3`` (u, v, w, global
frame) with rates ``k_1, k_2, k_3`` adds to the stiffness at O

    K_m = G^T R diag(k) R^T G = sum_a k_a g_a g_a^T,   G = [I, -[p]x],   g_a = [a; p x a]

(``R`` has the axes as columns; ``g_a`` are the Plücker coordinates of the line of action of
spring ``a``). K is therefore linear in the ``3 n`` rates: ``vech(K) = D k`` with the 21
independent entries of the symmetric K as rows and one column ``vech(g_a g_a^T)`` per rate.
The rates are the non-negative least-squares solution (:func:`scipy.optimize.nnls`) of the
weighted problem; the same design gives the viscous rates ``c`` from C (N s/m along each
axis) and the structural rates ``d`` from the structural damping D of
``K* = K + j w C + j D`` (N/m: a rubber mount's ``eta k``). The loss factor is
``eta = (d + 2 pi f c) / k``: ``d / k`` directly when the damping is structural (the same at
every frequency), and at a stated frequency ``f`` for the viscous part (the hysteretic loss
factor that dissipates, at ``f``, what the viscous rate ``c`` does).

Weighting
    Without standard deviations of K the residual ``K - D k`` is expressed at the centroid
    ``P`` of the mounts with its rotational rows and columns divided by the rms distance
    ``L`` of the mounts from ``P`` (so every entry is in N/m and the weights do not depend
    on where O is), then measured in the Frobenius norm (off-diagonal entries count twice).
    With a 6x6 standard deviation of K (``K_std``) every entry is weighted by ``1 / std``.

Identifiability
    A rate is determined by K iff its unit vector lies in the row space of the weighted
    design (21 x 3n, columns normalised): its component in the numerical null space is
    below ``1e-6``. More than 7 mounts (3n > 21) always leave some undetermined; so do
    springs whose ``g g^T`` are linearly dependent, e.g. the axial rates of mounts on one
    line (their lines of action coincide) or the three rates of mounts sharing all axes and
    the rank being short otherwise. Each null-space direction is named by the rates it
    combines.

Uncertainty
    Residual-based covariance of the linear least-squares fit,
    ``cov = s^2 (D_w^T D_w)^+`` with ``s^2 = |r_w|^2 / (21 - rank)`` (or ``s = 1`` when
    ``K_std`` weights are given), restricted to the identifiable rates; undetermined rates
    get no standard deviation (``nan``). With the identification's covariance of K
    (``K_cov``), its first-order image ``P cov(vec K) P^T`` through the unconstrained fit is
    added: the residual sees only the part of K's error outside the design's span.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.geometry import skew

__all__ = [
    "MountFit",
    "MountGeometry",
    "MountGeometryError",
    "MountRates",
    "check_mounts",
    "fit_mount_rates",
    "identify_mount_rates",
    "mount_design",
    "mount_stiffness",
    "vech",
]

#: relative singular-value tolerance of the rank of the normalised design
RANK_TOL = 1e-8
#: largest null-space component of a rate's unit vector for it to count as determined
IDENTIFIABLE_TOL = 1e-6

_IU = np.triu_indices(6)
_OFF = np.where(_IU[0] == _IU[1], 1.0, np.sqrt(2.0))


class MountGeometryError(ValueError):
    """The mount geometry cannot give any rate, or the mount description is invalid."""


@dataclass(frozen=True)
class MountGeometry:
    """Where a mount is and how it is turned.

    Attributes
    ----------
    name : label
    position : (3,) elastic centre of the mount, m, global frame
    axes : (3, 3) rows are the mount's local u, v, w unit axes in the global frame
    """

    name: str
    position: NDArray[np.float64]
    axes: NDArray[np.float64]

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=float).reshape(-1)
        A = np.asarray(self.axes, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise MountGeometryError(f"mount {self.name!r}: position must be 3 finite numbers")
        if A.shape != (3, 3) or not np.all(np.isfinite(A)):
            raise MountGeometryError(f"mount {self.name!r}: axes must be 3 rows of 3 numbers")
        if not np.allclose(A @ A.T, np.eye(3), atol=1e-6):
            raise MountGeometryError(
                f"mount {self.name!r}: axes must be orthonormal unit rows (u, v, w)")
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "axes", A)


def vech(S: ArrayLike) -> NDArray[np.float64]:
    """The 21 upper-triangle entries (row by row) of symmetric 6x6 matrices (..., 6, 6)."""
    a = np.asarray(S, dtype=float)
    return a[..., _IU[0], _IU[1]]


def _lines(mounts: Sequence[MountGeometry]) -> NDArray[np.float64]:
    """Plücker vectors g = [a; p x a] of every spring, (3 n, 6), mount by mount, u v w."""
    A = np.stack([m.axes for m in mounts])  # (n, 3, 3) rows = axes
    P = np.stack([m.position for m in mounts])  # (n, 3)
    moment = np.cross(P[:, None, :], A)  # (n, 3, 3)
    return np.concatenate([A, moment], axis=2).reshape(-1, 6)


def mount_design(mounts: Sequence[MountGeometry]) -> NDArray[np.float64]:
    """The springs' unit stiffness matrices at O, ``g g^T``, shape (3 n, 6, 6).

    ``K = einsum("j,jkl->kl", rates, mount_design(mounts))`` with ``rates`` mount by
    mount in u, v, w order.
    """
    g = _lines(mounts)
    return np.einsum("jk,jl->jkl", g, g)


def mount_stiffness(mounts: Sequence[MountGeometry], rates: ArrayLike) -> NDArray[np.float64]:
    """6x6 stiffness (or damping) at O of mounts with rates (n, 3) along their u, v, w axes."""
    r = np.asarray(rates, dtype=float).reshape(-1)
    return np.asarray(np.einsum("j,jkl->kl", r, mount_design(mounts)))


def _centroid_scaling(mounts: Sequence[MountGeometry]) -> NDArray[np.float64]:
    """The 6x6 map W with ``W^T S W`` = S at the mounts' centroid, rotations scaled by L."""
    P = np.stack([m.position for m in mounts])
    c = P.mean(axis=0)
    L = float(np.sqrt(np.mean(np.sum((P - c) ** 2, axis=1))))
    if L < 1e-9:
        L = 1.0
    # q_O = Gi q_c with Gi = [[I, [c]x], [0, I]]; S_c = Gi^T S_O Gi; then scale rotations by 1/L
    Gi = np.eye(6)
    Gi[:3, 3:] = skew(c)
    return np.asarray(Gi @ np.diag([1.0, 1.0, 1.0, 1 / L, 1 / L, 1 / L]))


@dataclass(frozen=True)
class MountFit:
    """Rates of each mount along its u, v, w axes and how well the test determines them.

    Attributes
    ----------
    names : mount names, in order
    rates : (n, 3) non-negative rates (N/m for K, N s/m for C)
    std : (n, 3) standard deviations (nan where not determined or no residual dof)
    identifiable : (n, 3) whether K (or C) determines the rate
    rank : rank of the weighted 21 x 3n design
    cond : its condition number (columns normalised; inf when rank < 3n)
    null_space : (3n, 3n - rank) orthonormal basis of the rate combinations K cannot see
    residual : relative weighted residual ``|r_w| / |vech_w(K)|``
    dof : residual degrees of freedom ``21 - rank``
    """

    names: tuple[str, ...]
    rates: NDArray[np.float64]
    std: NDArray[np.float64]
    identifiable: NDArray[np.bool_]
    rank: int
    cond: float
    null_space: NDArray[np.float64]
    residual: float
    dof: int
    #: the std come from given standard deviations of K (normal quantiles), not the residual
    known_variance: bool = False

    def ci95(self) -> NDArray[np.float64]:
        """(n, 3, 2) 95 % intervals ``rate -+ t(0.975, dof) std`` (Student's t: the residual
        gives few degrees of freedom), clipped at 0; nan where the std is nan."""
        import scipy.stats  # loaded when intervals are asked for, not with the module

        if self.known_variance:
            q = float(scipy.stats.norm.ppf(0.975))
        else:
            q = float(scipy.stats.t.ppf(0.975, self.dof)) if self.dof > 0 else float("nan")
        half = q * self.std
        return np.stack([np.maximum(self.rates - half, 0.0), self.rates + half], axis=-1)

    def undetermined(self) -> list[str]:
        """One sentence per null-space direction naming the rates it combines."""
        labels = [f"{n}.{a}" for n in self.names for a in "uvw"]
        out = []
        for v in self.null_space.T:
            big = np.abs(v) > 1e-3 * np.max(np.abs(v))
            terms = " ".join(f"{'+' if v[j] >= 0 else '-'}{abs(v[j]):.2f} {labels[j]}"
                             for j in np.flatnonzero(big))
            out.append(f"K does not change along {terms.lstrip('+')}: these springs' "
                       "stiffness matrices at O are linearly dependent (e.g. the same line of "
                       "action), so only their combination is measured")
        return out


def _svd(Dn: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], int,
                                          NDArray[np.float64], NDArray[np.bool_]]:
    """Singular values, right vectors, rank, null space and identifiable flags of the
    column-normalised design; refuses when no rate is determined."""
    n_r = Dn.shape[1]
    _, sv, Vt = np.linalg.svd(Dn, full_matrices=True)
    rank = int(np.sum(sv > RANK_TOL * sv[0])) if sv.size and sv[0] > 0 else 0
    null = Vt[rank:].T  # (3n, 3n - rank)
    ident = (np.linalg.norm(null, axis=1) < IDENTIFIABLE_TOL if null.size
             else np.ones(n_r, dtype=bool))
    if not np.any(ident):
        raise MountGeometryError(
            f"the mount geometry determines no rate: the 21 x {n_r} problem has rank {rank} "
            "and every rate lies in its null space; place the mounts so their springs' lines "
            "of action differ, or give fewer mounts")
    return sv, Vt, rank, null, ident


def check_mounts(mounts: Sequence[MountGeometry]) -> tuple[int, NDArray[np.bool_]]:
    """Rank of the design and which rates (n, 3) K can determine, from the geometry alone
    (weights do not change either); raises :class:`MountGeometryError` when none."""
    if len(mounts) == 0:
        raise MountGeometryError("no mount given: the mounts file needs at least one [[mount]]")
    W = _centroid_scaling(mounts)
    D = (vech(np.einsum("ki,jkl,lm->jim", W, mount_design(mounts), W)) * _OFF).T
    _, _, rank, _, ident = _svd(D / np.linalg.norm(D, axis=0))
    return rank, ident.reshape(-1, 3)


def fit_mount_rates(
    mounts: Sequence[MountGeometry],
    K: ArrayLike,
    K_std: ArrayLike | None = None,
    K_cov: ArrayLike | None = None,
) -> MountFit:
    """Non-negative rates of each mount's three springs that best reproduce K at O.

    Parameters
    ----------
    mounts : the mounts' positions and axes
    K : (6, 6) identified stiffness at O (or damping C: the rates are then N s/m)
    K_std : optional (6, 6) standard deviations of K's entries (weights 1 / std)
    K_cov : optional (36, 36) covariance of K's entries (row-major vec), e.g. the
        identification's: carried through the fit to first order and added to the
        residual-based variance (K's own scatter reaches the rates in full, not only the
        part the 21 - rank residual degrees of freedom see)

    Returns
    -------
    MountFit

    Raises
    ------
    MountGeometryError
        No mount given, K not 6x6 and finite, or the geometry determines no rate at all.

    Examples
    --------
    >>> m = [MountGeometry(f"m{i}", p, np.eye(3)) for i, p in
    ...      enumerate([(0, 0, 0), (1, 0, 0.3), (0.2, 1, 0)])]
    >>> fit = fit_mount_rates(m, mount_stiffness(m, np.full((3, 3), 1e5)))
    >>> bool(np.allclose(fit.rates, 1e5)), bool(fit.identifiable.all())
    (True, True)
    """
    import scipy.optimize  # loaded when mount rates are fitted, not with the module

    if len(mounts) == 0:
        raise MountGeometryError("no mount given: the mounts file needs at least one [[mount]]")
    Km = _symmetric_K(K)
    design = mount_design(mounts)  # (3n, 6, 6)
    n_r = design.shape[0]
    D, y = _weighted_problem(mounts, design, Km, K_std)
    scale = np.linalg.norm(D, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    Dn = D / scale
    sv, Vt, rank, null, ident = _svd(Dn)
    cond = float(sv[0] / sv[rank - 1]) if rank == n_r else float("inf")
    xn, rnorm = scipy.optimize.nnls(Dn, y, maxiter=50 * n_r)
    rates = xn / scale
    dof = D.shape[0] - rank
    # covariance of the scaled variables: (Dn^T Dn)^+ restricted to the row space
    inv = (Vt[:rank].T / sv[:rank] ** 2) @ Vt[:rank]
    s2 = _residual_variance(K_std is not None, float(rnorm), dof)
    var = np.clip(np.diag(inv), 0.0, None) * s2 / scale**2
    if K_cov is not None:
        var = np.fmax(var, _propagated_variance(mounts, Dn, scale, K_std, K_cov))
    std = np.sqrt(var)
    std = np.where(ident, std, np.nan)
    ynorm = float(np.linalg.norm(y))
    return MountFit(
        names=tuple(m.name for m in mounts),
        rates=rates.reshape(-1, 3),
        std=std.reshape(-1, 3),
        identifiable=ident.reshape(-1, 3),
        rank=rank,
        cond=cond,
        null_space=null,
        residual=float(rnorm / ynorm) if ynorm > 0 else 0.0,
        dof=dof,
        known_variance=K_std is not None,
    )


def _symmetric_K(K: ArrayLike) -> NDArray[np.float64]:
    """K as a finite, symmetrised 6x6 float matrix; raises :class:`MountGeometryError`."""
    Km = np.asarray(K, dtype=float)
    if Km.shape != (6, 6) or not np.all(np.isfinite(Km)):
        raise MountGeometryError("K must be a finite 6x6 matrix")
    return 0.5 * (Km + Km.T)


def _weighted_problem(mounts: Sequence[MountGeometry], design: NDArray[np.float64],
                      Km: NDArray[np.float64], K_std: ArrayLike | None,
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Design (21, 3n) and data (21,) of the rate fit, weighted by 1 / ``K_std`` when
    given, else by the centroid scaling of the mounts."""
    if K_std is None:
        W = _centroid_scaling(mounts)
        D = (vech(np.einsum("ki,jkl,lm->jim", W, design, W)) * _OFF).T  # (21, 3n)
        y = vech(W.T @ Km @ W) * _OFF
        return D, y
    s = np.asarray(K_std, dtype=float)
    if s.shape != (6, 6) or not np.all(s > 0):
        raise MountGeometryError("K_std must be a 6x6 matrix of positive numbers")
    w = 1.0 / vech(s)
    return (vech(design) * w).T, vech(Km) * w


def _residual_variance(known_variance: bool, rnorm: float, dof: int) -> float:
    """Variance of unit weight: 1 when the weights are K's standard deviations, else the
    residual's per degree of freedom (NaN without any)."""
    if known_variance:
        return 1.0
    if dof > 0:
        return float(rnorm**2 / dof)
    return float("nan")


def _propagated_variance(mounts: Sequence[MountGeometry], Dn: NDArray[np.float64],
                         scale: NDArray[np.float64], K_std: ArrayLike | None,
                         K_cov: ArrayLike) -> NDArray[np.float64]:
    """(3n,) variances of the rates carried from the (36, 36) covariance of vec(K)."""
    P = _rate_operator(mounts, Dn, scale, None if K_std is None else 1.0 / vech(
        np.asarray(K_std, dtype=float)))
    Sigma = np.asarray(K_cov, dtype=float)
    if Sigma.shape != (36, 36) or not np.all(np.isfinite(Sigma)):
        raise MountGeometryError("K_cov must be a finite 36x36 covariance of vec(K)")
    return np.einsum("rj,jk,rk->r", P, Sigma, P)


def _rate_operator(mounts: Sequence[MountGeometry], Dn: NDArray[np.float64],
                   scale: NDArray[np.float64], w: NDArray[np.float64] | None,
                   ) -> NDArray[np.float64]:
    """(3n, 36) first-order map from vec(K) (row-major) to the rates of the unconstrained
    weighted least squares (``w``: the entry weights, else the centroid scaling)."""
    E = np.eye(36).reshape(36, 6, 6)
    Ks = 0.5 * (E + np.swapaxes(E, 1, 2))  # symmetrised unit matrices
    if w is None:
        W = _centroid_scaling(mounts)
        Y = vech(np.einsum("ki,nkl,lm->nim", W, Ks, W)) * _OFF  # (36, 21)
    else:
        Y = vech(Ks) * w
    return np.asarray((np.linalg.pinv(Dn) @ Y.T) / scale[:, None])


@dataclass(frozen=True)
class MountRates:
    """Rates and loss factors of every mount (the result JSON's ``mounts``).

    Attributes
    ----------
    stiffness : the fit of K (rates N/m)
    damping : the fit of C with the same design (viscous rates N s/m), or None
    loss_factor_hz : frequency of the viscous part of the loss factors, Hz
    loss_factors : (n, 3) ``(d + 2 pi f c) / k`` (nan without C and D or where k = 0)
    loss_factors_std : (n, 3) first-order propagation of the fits' std (nan: undetermined)
    structural : the fit of the structural damping D (structural rates ``d``, N/m), or None
    """

    stiffness: MountFit
    damping: MountFit | None
    loss_factor_hz: float
    loss_factors: NDArray[np.float64]
    loss_factors_std: NDArray[np.float64]
    structural: MountFit | None = None

    def to_json(self) -> list[dict[str, Any]]:
        """One object per mount: ``rates``, ``loss_factors``, ``std`` of both,
        ``identifiable``, plus ``name``, ``damping_rates`` (N s/m), ``structural_rates``
        (N/m), ``loss_factor_hz``. Undetermined values are null."""
        k, c, d = self.stiffness, self.damping, self.structural

        def vals(a: NDArray[np.float64]) -> list[float | None]:
            return [float(v) if np.isfinite(v) else None for v in a]

        ci = k.ci95()
        out = []
        for i, name in enumerate(k.names):
            out.append({
                "name": name,
                "rates": vals(k.rates[i]),
                "loss_factors": vals(self.loss_factors[i]),
                "std": {"rates": vals(k.std[i]),
                        "loss_factors": vals(self.loss_factors_std[i])},
                "ci95": {"rates": [vals(iv) if np.all(np.isfinite(iv)) else None
                                   for iv in ci[i]]},
                "identifiable": [bool(v) for v in k.identifiable[i]],
                "damping_rates": None if c is None else vals(c.rates[i]),
                "structural_rates": None if d is None else vals(d.rates[i]),
                "loss_factor_hz": self.loss_factor_hz,
            })
        return out


def identify_mount_rates(
    mounts: Sequence[MountGeometry],
    K: ArrayLike,
    C: ArrayLike | None,
    loss_factor_hz: float,
    K_std: ArrayLike | None = None,
    C_std: ArrayLike | None = None,
    D: ArrayLike | None = None,
    D_std: ArrayLike | None = None,
    K_cov: ArrayLike | None = None,
    C_cov: ArrayLike | None = None,
) -> MountRates:
    """Rates from K, viscous rates from C, structural rates from D and the loss factors
    ``(d + 2 pi f c) / k``.

    Parameters
    ----------
    mounts : positions and axes
    K, C : (6, 6) stiffness and viscous damping at O (C may be None)
    loss_factor_hz : frequency ``f`` of the viscous part of the loss factors, Hz (> 0)
    K_std, C_std : optional (6, 6) standard deviations (weights, see :func:`fit_mount_rates`)
    D : (6, 6) structural damping at O (``K* = K + j w C + j D``), or None (or all zero:
        no structural part)
    D_std : optional (6, 6) standard deviations of D
    K_cov, C_cov : optional (36, 36) covariances of vec K and vec C (see
        :func:`fit_mount_rates`)

    Raises
    ------
    MountGeometryError
        As :func:`fit_mount_rates`, or a non-positive ``loss_factor_hz``.
    """
    if not loss_factor_hz > 0:
        raise MountGeometryError(
            f"the loss-factor frequency must be > 0 Hz, got {loss_factor_hz:g}")
    kf = fit_mount_rates(mounts, K, K_std, K_cov)
    cf = fit_mount_rates(mounts, C, C_std, C_cov) if C is not None else None
    has_d = D is not None and bool(np.any(np.asarray(D, dtype=float) != 0))
    df = fit_mount_rates(mounts, D, D_std) if D is not None and has_d else None
    if cf is None and df is None:
        nan = np.full_like(kf.rates, np.nan)
        return MountRates(kf, None, float(loss_factor_hz), nan, nan)
    w = 2 * np.pi * loss_factor_hz
    ok = kf.identifiable & (kf.rates > 0)
    k_safe = np.where(ok, kf.rates, 1.0)
    zero = np.zeros_like(kf.rates)
    # the loss's parts (d and w c, N/m) and their variances
    parts = [(w * f.rates, (w * f.std) ** 2) for f in (cf,) if f is not None]
    parts += [(f.rates, f.std**2) for f in (df,) if f is not None]
    loss = sum((p for p, _ in parts), zero)
    loss_var = sum((v for _, v in parts), zero)
    eta = np.where(ok, loss / k_safe, np.nan)
    rel_k = kf.std / k_safe
    with np.errstate(invalid="ignore", divide="ignore"):
        eta_std = np.sqrt(loss_var / k_safe**2 + (eta * rel_k) ** 2)
    eta_std = np.where(ok, eta_std, np.nan)
    return MountRates(kf, cf, float(loss_factor_hz), eta, eta_std, df)
