"""Monte Carlo of the test's stated uncertainties (the article's section 4, done per result).

The user states how well the test knows its own geometry and sensors:

``location`` (m)
    standard deviation of each coordinate of each measured point (response and
    excitation points; channels at one point move together);
``angle`` (rad)
    standard deviation of each response channel's direction about each of the two axes
    perpendicular to it (mounting misalignment and transverse sensitivity);
``gain`` (relative)
    standard deviation of each channel's gain (every response channel and every
    excitation's force channel).

Each draw perturbs the geometry and gains and re-solves the identification with the
nominal bands, lines, weights and mass-line model (leakage shapes and their projection)
fixed. The re-solve is exact algebra on moments: ``X = E^+ H`` is linear in the data, and
the projection and weights act on lines and columns while ``E^+`` acts on channels, so
every moment the mass-line and stiffness fits need is ``E_d^+ (sum_k f_k^2 Gamma_k)
E_d^+^T`` with per-excitation channel-space moments ``Gamma_k`` formed once. A draw then
costs a few 6x6 and 42x42 solves, vectorised over draws; the coupled inertia-stiffness
iteration of section 2.2 is linear in theta on moments, and its fixed point is solved
directly (one 10x10 solve a draw). The leakage
cleaning of the stiffness lines is not redone per draw: a draw's result is the nominal
result plus the change the fast path gives between that draw and the unperturbed
geometry.

Available for the improved method. With an exponential window the re-solve leaves the
window's decay out (a draw's change is that of the unwindowed fit, to first order in
``1 / (tau w)`` the windowed fit's). :func:`simulate` is pure and its inputs are plain
arrays (picklable), so draws can be spread over processes: ``simulate(model, stated,
seeds)`` for any list of seeds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.inertia import MASS_BASIS
from processing.massline import MassLineProblem
from processing.stiffness import DUPLICATION

__all__ = ["Draws", "MonteCarloModel", "StatedUncertainty", "build_model", "simulate"]


@dataclass(frozen=True)
class StatedUncertainty:
    """The test's stated standard uncertainties (SI: m, rad, relative) and the draws."""

    location: float = 0.0
    angle: float = 0.0
    gain: float = 0.0
    draws: int = 1000
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("location", "angle", "gain"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} uncertainty must be a finite number >= 0, got {v!r}")
        if self.draws < 2:
            raise ValueError(f"draws must be at least 2, got {self.draws}")

    @property
    def stated(self) -> bool:
        """True when any uncertainty is above 0."""
        return self.location > 0 or self.angle > 0 or self.gain > 0

    def describe(self) -> str:
        """One line: what was propagated."""
        return (f"Monte Carlo of the stated test uncertainties ({self.draws} draws): location "
                f"{self.location * 1000:g} mm, angle {np.rad2deg(self.angle):g} deg, gain "
                f"{self.gain * 100:g} % (standard deviations)")


@dataclass(frozen=True)
class MonteCarloModel:
    """What a draw needs: nominal geometry, the fits' channel-space moments, the nominal
    solution. Plain arrays only (picklable). Shapes: n_r response channels, n_e excitations,
    n_p distinct points."""

    resp_xyz: NDArray[np.float64]  # (n_r, 3)
    resp_dirs: NDArray[np.float64]  # (n_r, 3) unit
    exc_xyz: NDArray[np.float64]  # (n_e, 3)
    exc_dirs: NDArray[np.float64]  # (n_e, 3) unit
    resp_point: NDArray[np.int64]  # (n_r,) index into the points
    exc_point: NDArray[np.int64]  # (n_e,)
    point_names: tuple[str, ...]  # (n_p,)
    resp_names: tuple[str, ...]  # (n_r,) channel labels
    exc_names: tuple[str, ...]  # (n_e,)
    s2: NDArray[np.float64]  # (6,) squared row scales
    symmetric: bool
    gamma: NDArray[np.float64]  # (n_e, n_r, n_r) mass line: Hp_k Hp_k^T
    a2: NDArray[np.float64]  # (n_e, n_r, n_r) weighted(H / w^2) Hp_k^T
    a1: NDArray[np.float64]  # (n_e, n_r, n_r) weighted(j H / w) Hp_k^T
    hbar: NDArray[np.float64]  # (n_r, n_e) sum over a column's real rows of sw Hp
    gs: NDArray[np.complex128]  # (4, n_e, n_r, n_r) stiffness: sum wt w^p conj(h) h^T
    hq: NDArray[np.complex128]  # (2, n_e, n_r) sum wt w^(2, 3) conj(h)
    theta: NDArray[np.float64]  # (10,) nominal result
    K: NDArray[np.float64]
    C: NDArray[np.float64]


@dataclass(frozen=True)
class Draws:
    """Results of the draws: theta (n, 10), K and C (n, 6, 6); the perturbations ``z``
    (n, n_in) and the name of the input group of each column (for contributions)."""

    theta: NDArray[np.float64]
    K: NDArray[np.float64]
    C: NDArray[np.float64]
    z: NDArray[np.float64]
    groups: tuple[str, ...]
    converged: NDArray[np.bool_]


def _points(resp_xyz: NDArray[np.float64], exc_xyz: NDArray[np.float64]) -> tuple[
    NDArray[np.int64], NDArray[np.int64], int
]:
    allp = np.round(np.concatenate([resp_xyz, exc_xyz]), 9)
    _, inv = np.unique(allp, axis=0, return_inverse=True)
    inv = inv.ravel()
    n_r = resp_xyz.shape[0]
    return inv[:n_r], inv[n_r:], int(inv.max()) + 1


def build_model(ml: MassLineProblem, H_mass: NDArray[np.complex128],
                w_mass: NDArray[np.float64], H_stiff: NDArray[np.complex128],
                w_stiff: NDArray[np.float64], stiff_weights: NDArray[np.float64],
                resp_xyz: NDArray[np.float64], resp_dirs: NDArray[np.float64],
                exc_xyz: NDArray[np.float64], exc_dirs: NDArray[np.float64],
                row_scale: NDArray[np.float64] | None, symmetric: bool,
                theta: NDArray[np.float64], K: NDArray[np.float64], C: NDArray[np.float64],
                resp_ids: NDArray[np.int64] | None = None,
                exc_ids: NDArray[np.int64] | None = None) -> MonteCarloModel:
    """The :class:`MonteCarloModel` of a fit (the mass-line problem ``ml`` on ``H_mass``
    (n_r, n_e, n_lm) at ``w_mass`` rad/s; the stiffness lines ``H_stiff`` at ``w_stiff``
    with weights (n_e, n_ls)). ``resp_ids``, ``exc_ids``: node ids of the channels (points
    are then the distinct ids, else the distinct coordinates)."""
    Hp = ml.stacked(H_mass, project=True)  # (n_r, n_e, 2 n_lm)
    n_l = w_mass.size
    gamma = np.einsum("rkc,skc->krs", Hp, Hp)
    a2 = np.einsum("rkc,skc->krs", ml.stacked(H_mass / w_mass**2, project=False), Hp)
    a1 = np.einsum("rkc,skc->krs", ml.stacked(1j * H_mass / w_mass, project=False), Hp)
    ones = ml.stacked(np.ones((1, *H_mass.shape[1:]), complex), project=False)[0]
    ones[:, n_l:] = 0.0  # T is real: only the real rows carry it
    hbar = np.einsum("kc,rkc->rk", ones, Hp)
    wt = np.asarray(stiff_weights, float)
    gs = np.stack([np.einsum("kl,rkl,skl->krs", wt * w_stiff**p, np.conj(H_stiff), H_stiff)
                   for p in range(4)])
    hq = np.stack([np.einsum("kl,rkl->rk", wt * w_stiff**p, np.conj(H_stiff)).T
                   for p in (2, 3)])
    n_r, n_e = resp_xyz.shape[0], exc_xyz.shape[0]
    if resp_ids is not None and exc_ids is not None:
        ids, inv = np.unique(np.concatenate([resp_ids, exc_ids]), return_inverse=True)
        rp, ep, names = inv[:n_r], inv[n_r:], tuple(f"node {i}" for i in ids)
        resp_names = tuple(f"node {i}" for i in np.asarray(resp_ids))
        exc_names = tuple(f"node {i}{_axis(d)} force" for i, d in zip(exc_ids, exc_dirs,
                                                                       strict=True))
    else:
        rp, ep, n_p = _points(resp_xyz, exc_xyz)
        names = tuple(f"point {i + 1}" for i in range(n_p))
        resp_names = tuple(f"point {i + 1}" for i in rp)
        exc_names = tuple(f"excitation {k + 1} force" for k in range(n_e))
    s2 = np.ones(6) if row_scale is None else np.asarray(row_scale, float) ** 2
    return MonteCarloModel(
        resp_xyz=np.asarray(resp_xyz, float), resp_dirs=_unit(resp_dirs),
        exc_xyz=np.asarray(exc_xyz, float), exc_dirs=_unit(exc_dirs),
        resp_point=np.asarray(rp, np.int64), exc_point=np.asarray(ep, np.int64),
        point_names=names, resp_names=resp_names, exc_names=exc_names,
        s2=s2, symmetric=symmetric, gamma=gamma, a2=a2, a1=a1, hbar=hbar, gs=gs, hq=hq,
        theta=np.asarray(theta, float), K=np.asarray(K, float), C=np.asarray(C, float))


def _axis(d: NDArray[np.float64]) -> str:
    """``:+x`` style label of a direction (the nearest global axis)."""
    k = int(np.argmax(np.abs(d)))
    return f":{'+' if d[k] >= 0 else '-'}{'xyz'[k]}"


def _unit(d: NDArray[np.float64]) -> NDArray[np.float64]:
    d = np.asarray(d, float)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _perpendiculars(d: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors perpendicular to each row of d and to each other."""
    helper = np.where(np.abs(d[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(d, u)


def _solve_draws(model: MonteCarloModel, dP: NDArray[np.float64], tilt: NDArray[np.float64],
                 g_r: NDArray[np.float64], g_e: NDArray[np.float64]) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]
]:
    """theta, K, C of draws with point offsets dP (n, n_p, 3), response tilts (n, n_r, 2),
    response and excitation gain errors (n, n_r), (n, n_e)."""
    m = model
    n = dP.shape[0]
    u1, u2 = _perpendiculars(m.resp_dirs)
    d = m.resp_dirs[None] + tilt[..., :1] * u1[None] + tilt[..., 1:] * u2[None]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    r = m.resp_xyz[None] + dP[:, m.resp_point]
    E = np.concatenate([d, np.cross(r, d)], axis=-1)  # (n, n_r, 6)
    Et = np.swapaxes(E, 1, 2)
    Ep = np.linalg.solve(Et @ E, Et) / (1.0 + g_r)[:, None, :]  # (n, 6, n_r)
    p = m.exc_xyz[None] + dP[:, m.exc_point]
    T = np.swapaxes(np.concatenate([np.broadcast_to(m.exc_dirs, p.shape),
                                    np.cross(p, m.exc_dirs[None])], axis=-1), 1, 2)  # (n,6,n_e)
    f = 1.0 + g_e  # (n, n_e) force-gain correction of each column
    f2 = f**2
    EpT = np.swapaxes(Ep, 1, 2)

    def sandwich(A: NDArray[np.floating]) -> NDArray[np.floating]:
        return np.asarray(Ep @ np.einsum("nk,k...->n...", f2, A) @ EpT)

    G = sandwich(m.gamma)
    P2 = sandwich(m.a2)
    P1 = sandwich(m.a1)
    WT = (T * f[:, None, :]) @ m.hbar.T[None] @ EpT  # (n, 6, 6)
    MBs = (MASS_BASIS * m.s2[None, :, None]).reshape(10, 36)
    op = np.einsum("pia,qib->pqab", MBs.reshape(10, 6, 6), MASS_BASIS).reshape(100, 36)
    N = (G.reshape(n, 36) @ op.T).reshape(n, 10, 10)
    NinvMB = (np.linalg.inv(N) @ MBs).reshape(n, 10, 6, 6)  # theta = NinvMB . vec(W)
    Gp = [sandwich(m.gs[q]) for q in range(4)]
    Q2, Q3 = ((Ep @ np.einsum("nk,rk,nik->nri", f, m.hq[q].T, T)) for q in (0, 1))
    Nb = np.zeros((n, 2, 6, 2, 6))
    Nb[:, 0, :, 0], Nb[:, 0, :, 1] = Gp[0].real, -Gp[1].imag
    Nb[:, 1, :, 0], Nb[:, 1, :, 1] = Gp[1].imag, Gp[2].real
    blocks = np.zeros((n, 2, 6, 6, 2, 6, 6))
    for i in range(6):  # row blocks s2_i Nb on the diagonal of the equation rows
        blocks[:, :, i, :, :, i, :] = m.s2[i] * Nb
    Nfull = blocks.reshape(n, 72, 72)
    if m.symmetric:
        _DUP2 = np.kron(np.eye(2), DUPLICATION)  # [vech K; vech C] -> [vec K; vec C]
        S = _DUP2[None] @ np.linalg.solve(_DUP2.T[None] @ Nfull @ _DUP2[None], _DUP2.T[None])
    else:
        S = np.linalg.inv(Nfull)

    def vecs(rK: NDArray[np.float64], rC: NDArray[np.float64]) -> NDArray[np.float64]:
        """[vec rK^T, vec rC^T] (..., 72) of (..., 6, 6) right-hand sides."""
        lead = rK.shape[:-2]
        return np.concatenate([np.swapaxes(rK, -1, -2).reshape(*lead, 36),
                               np.swapaxes(rC, -1, -2).reshape(*lead, 36)], axis=-1)

    # the coupled fixed point of section 2.2 is linear in theta: solve it directly
    # theta = t0 + L v, v = [vec K, vec C] = s0 + S_theta theta
    t0 = np.einsum("npia,nia->np", NinvMB, WT)
    L = np.concatenate([(NinvMB @ np.swapaxes(P2, 1, 2)[:, None]).reshape(n, 10, 36),
                        (NinvMB @ np.swapaxes(P1, 1, 2)[:, None]).reshape(n, 10, 36)], axis=2)
    s0 = np.einsum("nij,nj->ni", S, vecs(-Q2.real * m.s2, -Q3.imag * m.s2))
    MBT = np.swapaxes(MASS_BASIS, 1, 2)[None]  # (1, 10, 6, 6)
    R = vecs((Gp[2][:, None] @ MBT).real * m.s2, (Gp[3][:, None] @ MBT).imag * m.s2)
    S_theta = S @ np.swapaxes(R, 1, 2)  # (n, 72, 10)
    A = np.eye(10)[None] - L @ S_theta
    theta = np.linalg.solve(A, (t0 + np.einsum("npv,nv->np", L, s0))[..., None])[..., 0]
    v = s0 + np.einsum("nvp,np->nv", S_theta, theta)
    K, C = v[:, :36].reshape(n, 6, 6), v[:, 36:].reshape(n, 6, 6)
    done = np.all(np.isfinite(theta), axis=1)
    return theta, K, C, done


def simulate(model: MonteCarloModel, stated: StatedUncertainty,
             seeds: NDArray[np.int64] | list[int] | None = None) -> Draws:
    """Draws of the identification under the stated uncertainties.

    Parameters
    ----------
    model : from :func:`build_model`
    stated : the standard uncertainties; ``stated.draws`` draws from ``stated.seed`` unless
        ``seeds`` is given (one draw per seed: the same seed gives the same draw, so draws
        can be split over processes and joined)

    Returns
    -------
    :class:`Draws`: each draw's result (the nominal result plus the draw's change) and its
    perturbations.
    """
    m = model
    seeds_arr = (np.arange(stated.draws) + stated.seed * 1_000_003 if seeds is None
                 else np.asarray(seeds, dtype=np.int64))
    n_p, n_r, n_e = len(m.point_names), m.resp_xyz.shape[0], m.exc_xyz.shape[0]
    n_in = 3 * n_p + 2 * n_r + n_r + n_e
    z = np.stack([np.random.default_rng([int(s), 15]).standard_normal(n_in)
                  for s in seeds_arr]) if seeds_arr.size else np.zeros((0, n_in))
    scale = np.concatenate([np.full(3 * n_p, stated.location), np.full(2 * n_r, stated.angle),
                            np.full(n_r + n_e, stated.gain)])
    x = z * scale
    n = x.shape[0]
    dP = x[:, :3 * n_p].reshape(n, n_p, 3)
    tilt = x[:, 3 * n_p:3 * n_p + 2 * n_r].reshape(n, n_r, 2)
    g_r = x[:, 3 * n_p + 2 * n_r:3 * n_p + 3 * n_r]
    g_e = x[:, 3 * n_p + 3 * n_r:]
    zero = [np.zeros((1, *a.shape[1:])) for a in (dP, tilt, g_r, g_e)]
    t0, K0, C0, _ = _solve_draws(m, *zero)
    theta, K, C, done = _solve_draws(m, dP, tilt, g_r, g_e)
    groups = (*(f"{name} location" for name in m.point_names for _ in range(3)),
              *(f"{name} angle" for name in m.resp_names for _ in range(2)),
              *(f"{name} gain" for name in m.resp_names),
              *(f"{name} gain" for name in m.exc_names))
    return Draws(theta=m.theta + (theta - t0), K=m.K + (K - K0), C=m.C + (C - C0), z=x,
                 groups=groups, converged=done)
