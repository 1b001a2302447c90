"""The article's plain method, written independently as a validation baseline.

Equations of "Identification of Engine Inertia Parameters and System Dynamic Stiffness via
In Situ Method" (the article in the project's reference material), nothing more:

- eq. 6: rigid-body accelerances at O, ``X = (E^T E)^-1 E^T H`` per line, with the rows of
  E ``d^T [I, -[r]x]`` (sensor along ``d`` at ``r``) and the columns of T ``[e; p x e]``;
- eqs. 7-11: ``X^T M = T^T + X^T K*^T / w^2`` stacked (real and imaginary parts) over the
  kept lines of the mass line, solved by least squares for the ten parameters of M (eq. 2);
- eq. 14: ``K*(w) = w^2 (M X - T) X^+`` per line of the stiffness band (``X^+`` the
  Moore-Penrose pseudo-inverse); K is the mean of Re K*, C the mean of Im K* / w, and
  ``K*(w) = K + j w C`` goes back into eq. 7: section 2.2's iteration, until the ten
  parameters change by less than ``tol`` (relative);
- section 3 line selection: per line ``err_j`` = mean |H - E X| over the FRFs (eq. 15),
  ``err`` its mean over the mass line (eq. 16); lines with ``err_j >= level * err`` are
  dropped; T must have rank 6 and cond(T) < ``max_cond`` (moment rows divided by the RMS
  distance of the force points from O), else the method refuses.

Band rule (:func:`article_bands`), from the article's two examples (block: rigid modes
below 35 Hz, first elastic mode 177 Hz, mass line 90-150 Hz; engine: below 30 Hz, 118.5 Hz,
60-85 Hz, stiffness 3-35 Hz): mass line from 2x the highest rigid-body mode to 0.8x the
first elastic mode (or the end of the data), stiffness band from the first line to 1.2x
the highest rigid-body mode. The two frequencies are what the article reads off its FRF
plots; :func:`identify_scenario` gives it the reference system's true ones (a favourable
baseline: an engineer who reads every peak right).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hardware_mocks.reference.kinematics import rigid_map
from hardware_mocks.reference.scenarios import Scenario

__all__ = ["ArticleRefusalError", "ArticleResult", "article_bands", "article_identify",
           "identify_scenario", "mass_matrix_from_theta"]


class ArticleRefusalError(ValueError):
    """The article's method cannot be applied (no band, rank or condition of T)."""


def _basis() -> NDArray[np.float64]:
    """(10, 6, 6): M = sum theta_k B_k for theta = [m, mxc, myc, mzc, Jxx, Jyy, Jzz, Jxy,
    Jxz, Jyz] (eq. 2 of the article)."""
    B = np.zeros((10, 6, 6))
    B[0, [0, 1, 2], [0, 1, 2]] = 1.0
    for k, entries in ((1, [(1, 5, 1), (2, 4, -1)]), (2, [(0, 5, -1), (2, 3, 1)]),
                       (3, [(0, 4, 1), (1, 3, -1)]), (7, [(3, 4, -1)]), (8, [(3, 5, -1)]),
                       (9, [(4, 5, -1)])):
        for i, j, v in entries:
            B[k, i, j] = B[k, j, i] = v
    B[4, 3, 3] = B[5, 4, 4] = B[6, 5, 5] = 1.0
    return B


_B = _basis()


def mass_matrix_from_theta(theta: ArrayLike) -> NDArray[np.float64]:
    """The 6 x 6 mass matrix of eq. 2 from the ten parameters."""
    return np.asarray(np.einsum("k,kij->ij", np.asarray(theta, dtype=float), _B))


@dataclass(frozen=True)
class ArticleResult:
    """What the article's method identifies (SI, global frame)."""

    theta: NDArray[np.float64]
    K: NDArray[np.float64]
    C: NDArray[np.float64]
    mass_band: tuple[float, float]
    stiffness_band: tuple[float, float]
    mass_lines: int
    stiffness_lines: int
    iterations: int
    converged: bool

    @property
    def mass(self) -> float:
        return float(self.theta[0])

    @property
    def cog(self) -> NDArray[np.float64]:
        return np.asarray(self.theta[1:4] / self.theta[0])

    @property
    def inertia_origin(self) -> NDArray[np.float64]:
        return np.asarray(mass_matrix_from_theta(self.theta)[3:, 3:])

    @property
    def inertia_cog(self) -> NDArray[np.float64]:
        c = self.cog
        return self.inertia_origin - self.mass * (c @ c * np.eye(3) - np.outer(c, c))


def article_bands(freq: ArrayLike, rigid_max_hz: float, first_elastic_hz: float,
                  ) -> tuple[tuple[float, float], tuple[float, float]]:
    """Mass-line and stiffness bands by the article's rule (module notes), Hz.

    Raises ArticleRefusalError when the mass line holds fewer than 10 lines.
    """
    f = np.asarray(freq, dtype=float)
    mass = (2.0 * rigid_max_hz, min(0.8 * first_elastic_hz, float(f[-1])))
    if np.count_nonzero((f >= mass[0]) & (f <= mass[1])) < 10:
        raise ArticleRefusalError(
            f"no mass line: 2x the highest rigid mode ({mass[0]:.1f} Hz) is not 10 lines below "
            f"0.8x the first elastic mode or the end of the data ({mass[1]:.1f} Hz)")
    return mass, (float(f[0]), 1.2 * rigid_max_hz)


def article_identify(freq: ArrayLike, H: ArrayLike, resp_xyz: ArrayLike, resp_dirs: ArrayLike,
                     exc_xyz: ArrayLike, exc_dirs: ArrayLike, mass_band: tuple[float, float],
                     stiffness_band: tuple[float, float], *, level: float = 3.0,
                     max_cond: float = 20.0, max_iter: int = 500, tol: float = 1e-10,
                     ) -> ArticleResult:
    """The article's method on accelerances ``H`` (n_r, n_e, n_f) at the given geometry.

    Parameters
    ----------
    freq : (n_f,) Hz
    H : (n_r, n_e, n_f) accelerance, (m/s^2)/N
    resp_xyz, resp_dirs : (n_r, 3) response points (m) and unit directions
    exc_xyz, exc_dirs : (n_e, 3) force points (m) and unit directions
    mass_band, stiffness_band : Hz
    level, max_cond : section 3's line-selection factor and the bound on cond(T)
    """
    f = np.asarray(freq, dtype=float)
    Hc = np.asarray(H, dtype=complex)
    E = np.einsum("ni,nij->nj", np.asarray(resp_dirs, float), rigid_map(resp_xyz))
    exyz = np.asarray(exc_xyz, float).reshape(-1, 3)
    T = np.einsum("nji,nj->in", rigid_map(exyz), np.asarray(exc_dirs, float))
    Ts = T.copy()
    Ts[3:] /= np.sqrt(np.mean(np.sum(exyz**2, axis=1)))
    sv = np.linalg.svd(Ts, compute_uv=False)
    if np.linalg.matrix_rank(T) < 6 or sv[0] / sv[-1] >= max_cond:
        raise ArticleRefusalError(f"the excitations fail rank(T) = 6, cond(T) < {max_cond:g} "
                             f"(cond {sv[0] / sv[-1]:.1f})")
    X = np.einsum("ar,rel->ael", np.linalg.pinv(E), Hc)  # (6, n_e, n_f), eq. 6
    in_mass = (f >= mass_band[0]) & (f <= mass_band[1])
    err_j = np.mean(np.abs(Hc - np.einsum("ra,ael->rel", E, X)), axis=(0, 1))  # eq. 15
    keep = in_mass & (err_j < level * np.mean(err_j[in_mass]))  # eq. 16 and the rule
    in_stiff = (f >= stiffness_band[0]) & (f <= stiffness_band[1])
    if keep.sum() < 2 or in_stiff.sum() < 1:
        raise ArticleRefusalError("fewer than 2 mass lines or no stiffness line in the bands")
    Xm, wm = X[..., keep], 2 * np.pi * f[keep]
    Xs, ws = X[..., in_stiff], 2 * np.pi * f[in_stiff]
    # eq. 7 for all kept lines: A theta = b, rows (line, excitation, column), Re and Im
    A = np.einsum("ael,kac->leck", Xm, _B).reshape(-1, 10)
    A = np.concatenate([A.real, A.imag])
    XsT = np.moveaxis(Xs, -1, 0)  # (n_s, 6, n_e)
    pinv_s = np.linalg.pinv(XsT)  # (n_s, n_e, 6)
    theta = np.zeros(10)
    K = np.zeros((6, 6))
    C = np.zeros((6, 6))
    it, converged = 0, False
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        Kstar = K[None] + 1j * wm[:, None, None] * C[None]  # (n_m, 6, 6)
        rhs = T.T[None] + np.einsum("ael,lca->lec", Xm, Kstar) / (wm**2)[:, None, None]
        b = rhs.reshape(-1)
        b = np.concatenate([b.real, b.imag])
        new = np.linalg.lstsq(A, b, rcond=None)[0]
        M = mass_matrix_from_theta(new)
        Kl = (ws**2)[:, None, None] * ((M[None] @ XsT - T[None]) @ pinv_s)  # eq. 14
        K = np.mean(Kl.real, axis=0)
        C = np.mean(Kl.imag / ws[:, None, None], axis=0)
        step = np.linalg.norm(new - theta) / np.linalg.norm(new)
        theta = new
        if step < tol:
            converged = True
            break
    return ArticleResult(theta, K, C, mass_band, stiffness_band, int(keep.sum()),
                         int(in_stiff.sum()), it, converged)


def identify_scenario(sc: Scenario) -> ArticleResult:
    """The article's method with its band rule on a scenario's measured FRFs and reported
    geometry; the highest rigid-body and first elastic frequencies are the system's own."""
    nat = sc.natural_frequencies_hz
    mass_band, stiff_band = article_bands(sc.freq, float(nat[5]), sc.first_elastic_hz)
    return article_identify(sc.freq, sc.H, sc.sensors.reported_xyz, sc.sensors.reported_dirs,
                            sc.forces.reported_xyz, sc.forces.reported_dirs, mass_band,
                            stiff_band)

