"""Bootstrap over hits (hammer) or blocks (shaker): how far the FRFs' own noise moves a result.

A point's FRF column from time data is a ratio of averaged spectra: H1 is
``sum_u S_fx,u / sum_u S_ff,u`` over the point's averaging units ``u`` (the accepted hits
of a hammer test, the blocks of a shaker test), H2 ``sum S_xx / sum conj(S_fx)``. The
units are independent measurements of the same column, so resampling them with
replacement (each point on its own: the points were measured apart) and forming the
FRFs again gives draws of what another test of the same engine, as noisy, could have
given (Efron's bootstrap). Each resample is identified again with everything the main
fit chose held fixed: bands, lines, coherence weights, leakage shapes, damping model
(band selection is not re-run), and the spread of each result over the resamples is its
bootstrap uncertainty.

Units
    :class:`processing.units.TimeUnits` (per column, the spectra of each unit), attached by
    the pipeline to the measurement's provenance
    (:attr:`processing.measurement.Provenance.units`).

Re-identification
    Without modelled leakage the coupled inertia-stiffness iteration (section 2.2) is an
    affine map of theta for fixed data (the mass-line solve is linear in K, C, D and the
    stiffness step affine in M), so each resample's fixed point is found exactly from
    eleven evaluations of one iteration step and one 10x10 solve; with leakage shapes the
    iteration itself runs, from the main fit's solution, for the resamples of a chunk at
    once, each stopping where it converges (what does not depend on the resample, and the
    moments of the accelerances with the leakage shapes, formed once). The FRFs of all
    resamples and their rigid-body accelerances are formed at once (vectorised over
    resamples).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from processing.data import InputError
from processing.inertia import MASS_BASIS
from processing.massline import stack_real
from processing.physical import constrain_physical
from processing.problem import Problem, h1_variances, typical_rms
from processing.results import UNCERTAIN_KEYS
from processing.stages import (
    Bands,
    Fit,
    LineWeights,
    leakage_shapes,
    upper_residual,
)
from processing.stiffness import (
    DAMPING_BLOCKS,
    DUPLICATION,
    line_functions,
    stiffening_factor,
    stiffness_normal,
    vech_index,
    vech_normal,
)
from processing.uncertainty import derived_of_draws, draw_covariance
from processing.units import TimeUnits, UnitKind

__all__ = ["DEFAULT_RESAMPLES", "Bootstrap", "Progress", "about_the_data", "resample",
           "resampled_frfs", "weighted_accelerances"]

#: resamples when none are asked for
DEFAULT_RESAMPLES = 200
#: most FRF values (resamples x columns x lines x responses) formed at once (memory bound)
CHUNK_VALUES = 4_000_000
#: the resamples are solved in at least this many chunks (each reported to ``progress``)
PROGRESS_STEPS = 4

#: ``progress(done, total)``: how many of the resamples are solved
Progress = Callable[[int, int], None]

# --- resampling ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Bootstrap:
    """Resampled identifications: theta (n, 10), K, C (n, 6, 6); ``counts`` (n, n_units)
    how often each unit was drawn; ``groups`` the column label of each unit."""

    theta: NDArray[np.float64]
    K: NDArray[np.float64]
    C: NDArray[np.float64]
    counts: NDArray[np.float64]
    groups: tuple[str, ...]
    kind: UnitKind
    units: tuple[int, ...]

    @property
    def n(self) -> int:
        return int(self.theta.shape[0])

    def describe(self) -> str:
        """One line: what was resampled."""
        return (f"bootstrap over {self.kind}s ({self.n} resamples; {min(self.units)}-"
                f"{max(self.units)} {self.kind}s a point; bands, weights and models held fixed)")

    def values(self) -> dict[str, NDArray[np.float64]]:
        """Every key of :data:`UNCERTAIN_KEYS` for each resample, (n, *shape)."""
        return derived_of_draws(self.theta, self.K, self.C)

    def covariance(self) -> NDArray[np.float64]:
        """(82, 82) covariance of ``[theta, vec K, vec C]`` over the resamples."""
        return draw_covariance(self.theta, self.K, self.C)

    def variances(self) -> dict[str, dict[str, NDArray[np.float64]]]:
        """Per key, the variance of each entry over the resamples split by column.

        First order: a linear regression of the resamples on the counts; column g gets
        the variance of its fitted linear part ``z_g beta_g``; what the linear part leaves
        is ``"bootstrap (non-linear part)"``. Parts are scaled down when the regression's
        noise makes them exceed the total. Entries with a non-finite resample (rigid modes
        of a resample whose M is not positive definite) are left out.
        """
        values = self.values()
        keys = list(values)
        flat = np.concatenate([values[k].reshape(self.n, -1) for k in keys], axis=1)
        ok = np.all(np.isfinite(flat), axis=0)
        y = np.where(ok, flat, 0.0)
        y = y - y.mean(axis=0)
        z = self.counts - self.counts.mean(axis=0)
        total = np.var(y, axis=0, ddof=1)
        beta = np.linalg.lstsq(z, y, rcond=None)[0]
        names = list(dict.fromkeys(self.groups))
        gidx = np.array([names.index(g) for g in self.groups])
        per = np.stack([np.var(z[:, gidx == i] @ beta[gidx == i], axis=0, ddof=1)
                        for i in range(len(names))])
        lin = per.sum(axis=0)
        per *= np.where(lin > total, total / np.maximum(lin, 1e-300), 1.0)
        rest = np.clip(total - per.sum(axis=0), 0.0, None)
        out: dict[str, dict[str, NDArray[np.float64]]] = {}
        col = 0
        for k in keys:
            shape = UNCERTAIN_KEYS[k]
            sl = slice(col, col + int(np.prod(shape, dtype=int)))
            col = sl.stop
            if not np.all(ok[sl]):
                continue
            parts = {g: per[i, sl].reshape(shape) for i, g in enumerate(names)}
            parts["bootstrap (non-linear part)"] = rest[sl].reshape(shape)
            out[k] = parts
        return out

    def intervals(self, theta: NDArray[np.float64], K: NDArray[np.float64],
                  C: NDArray[np.float64], std: dict[str, NDArray[np.float64]],
                  ) -> dict[str, NDArray[np.float64]]:
        """Asymmetric 95 % intervals (shape + (2,)) of the keys in ``std`` about the result
        ``theta``, ``K``, ``C``: the percentile interval of the resamples, ``[q2.5, q97.5]``,
        widened about the result's value ``x`` to ``x + r (q - x)`` by the ratio ``r`` of
        ``std`` (every source) to the resamples' own std when that is above 1; the value
        always lies inside.
        """
        nominal = {k: v[0] for k, v in derived_of_draws(theta[None], K[None], C[None]).items()}
        out: dict[str, NDArray[np.float64]] = {}
        for k, v in self.values().items():
            x = nominal[k]
            if k not in std or not (np.all(np.isfinite(v)) and np.all(np.isfinite(x))):
                continue
            q = np.percentile(v, [2.5, 97.5], axis=0)
            sb = np.std(v, axis=0, ddof=1)
            r = np.maximum(np.where(sb > 0, std[k] / np.where(sb > 0, sb, 1.0), 1.0), 1.0)
            lo = np.minimum(x + r * (q[0] - x), x)
            hi = np.maximum(x + r * (q[1] - x), x)
            out[k] = np.stack([lo, hi], axis=-1)
        return out


def _inverse_variances(problem: Problem, H: NDArray[np.complex128],
                       coherence: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse variances (.., n_resp) of H1 values, with the floors of
    :func:`processing.problem.prepare` (:func:`processing.problem.h1_variances`)."""
    return np.asarray(1.0 / h1_variances(H, coherence,
                                         problem.coherence_floor * typical_rms(problem.H)))


def weighted_accelerances(problem: Problem, used: NDArray[np.bool_], H: NDArray[np.complex128],
                          coherence: NDArray[np.float64],
                          ) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """Rigid-body accelerances X (n, n_l, 6, n_e) and column weights (n, n_e, n_l) of
    resamples' FRFs ``H`` and coherence (n_e, n_l, n_resp, n) on the lines ``used``.

    X is the main fit's map from each column's responses to its accelerances at O (the
    least squares of :func:`processing.problem.prepare` weighted by each FRF's median
    variance over the lines, or ``E^+``),
    applied to the resample's FRFs; each column's weight on each line follows the
    resample's own coherence: the main fit's weight times the ratio of the summed inverse
    H1 variances (:func:`processing.problem.h1_variances`) of its responses (resample over main
    fit). Without coherence: ``E^+ H`` and the main fit's weights."""
    n_r, n = problem.E.shape[0], H.shape[-1]
    colw0 = problem.col_weights[:, used]  # (n_e, n_l)
    if problem.coherence is None:
        op = np.broadcast_to(problem.Epinv, (*colw0.shape, 6, n_r))
        scale = np.ones((n, *colw0.shape))
    else:
        H0 = np.moveaxis(problem.H[..., used], 0, -1)  # (n_e, n_l, n_r)
        W0 = _inverse_variances(problem, H0, np.moveaxis(problem.coherence[..., used], 0, -1))
        if problem.from_time_records:
            # time-data FRFs: the main fit's responses weighed by each FRF's median
            # variance over all lines
            Wm = 1.0 / np.median(
                1.0 / _inverse_variances(problem, problem.H, problem.coherence),
                axis=-1).T  # (n_e, n_r)
            Wn = np.broadcast_to((Wm / np.max(Wm, axis=-1, keepdims=True))[:, None, :],
                                 W0.shape)
        else:  # FRFs given: line by line
            Wn = W0 / np.max(W0, axis=-1, keepdims=True)
        A = np.einsum("ri,elr,rj->elij", problem.E, Wn, problem.E)
        op = np.linalg.solve(A, np.einsum("ri,elr->elir", problem.E, Wn))  # (e, l, 6, r)
        Wb = _inverse_variances(problem, H, coherence).sum(axis=2)  # (e, l, n)
        scale = np.moveaxis(Wb / W0.sum(-1)[..., None], -1, 0)
    X = np.ascontiguousarray(np.transpose(op @ H, (3, 1, 2, 0)))  # (n, l, 6, e)
    return X, colw0 * scale


def _line_index(units_freq: NDArray[np.float64], freq: NDArray[np.float64]) -> (
    NDArray[np.int64] | None
):
    """Index into ``units_freq`` of each line of ``freq`` (None when one is missing)."""
    idx = np.clip(np.searchsorted(units_freq, freq), 0, units_freq.size - 1)
    lo = np.clip(idx - 1, 0, None)
    idx = np.where(np.abs(units_freq[lo] - freq) < np.abs(units_freq[idx] - freq), lo, idx)
    tol = 1e-6 * max(float(np.max(np.abs(freq))), 1.0)
    return idx if np.all(np.abs(units_freq[idx] - freq) <= tol) else None


def _mix(S: NDArray[Any], lines: NDArray[np.int64], cw: NDArray[np.float64]) -> NDArray[Any]:
    """(n_l, n_r, n) spectra of n resamples: per-unit spectra S (n_u, n_r, n_f) on ``lines``
    mixed with the resamples' unit weights ``cw`` (n_u, n)."""
    part = np.swapaxes(S[..., lines], 1, 2).reshape(S.shape[0], -1)
    return np.asarray((part.T @ cw).reshape(lines.size, S.shape[1], cw.shape[1]))


def resampled_frfs(units: TimeUnits, lines: NDArray[np.float64], counts: list[
        NDArray[np.float64]]) -> tuple[NDArray[np.complex128], NDArray[np.float64]] | None:
    """FRFs and coherence (n_exc, n_lines, n_resp, n) of the n resamples on ``lines`` (Hz):
    each column's units weighted by how often each was drawn; None when a column lacks a
    line."""
    from processing.spectral import CrossSpectra, frf  # the numba kernels: with time data only

    n = counts[0].shape[0]
    n_l, n_r = lines.size, units.columns[0].Sfx.shape[1]
    H = np.empty((len(units.columns), n_l, n_r, n), complex)
    G = np.empty((len(units.columns), n_l, n_r, n))
    est = units.estimator.upper()
    for k, (col, c) in enumerate(zip(units.columns, counts, strict=True)):
        li = _line_index(col.freq, lines)
        if li is None:
            return None
        mean = col.weight / col.weight.sum()
        cw = c * col.weight  # (n, n_u)
        cw = cw / cw.sum(axis=1, keepdims=True)
        # a resample's deviation from the mean, scaled by sqrt(n / (n - 1)): the bootstrap's
        # variance of a mean of n units is (n - 1) / n of the unbiased estimate
        cw = (mean + np.sqrt(col.n_units / (col.n_units - 1)) * (cw - mean)).T  # (n_u, n)
        Sfx, Sxx = _mix(col.Sfx, li, cw), _mix(col.Sxx, li, cw)
        Sff = (col.Sff[:, li].T @ cw)[:, None, :]  # (n_l, 1, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            G[k] = np.clip(np.abs(Sfx) ** 2 / (Sff * Sxx), 0.0, 1.0)
            if est == "H1":
                H[k] = Sfx / Sff
            elif est == "H2":
                H[k] = Sxx / np.conj(Sfx)
            else:  # Hv (and any other): the estimator itself on the resampled spectra
                flat = np.moveaxis(Sfx, 1, 0).reshape(n_r, -1)  # (n_r, n_l n)
                sp = CrossSpectra(np.zeros(n_l * n), Sff.reshape(1, 1, -1) + 0j, flat[None],
                                  np.moveaxis(Sxx, 1, 0).reshape(n_r, -1), 1, (0,),
                                  tuple(range(1, n_r + 1)))
                H[k] = np.moveaxis(frf(sp, units.estimator)[0][:, 0].reshape(n_r, n_l, n), 0, 1)
    return H, G


def about_the_data(problem: Problem, used: NDArray[np.bool_], nominal: tuple[
        NDArray[np.complex128], NDArray[np.float64]], drawn: tuple[
        NDArray[np.complex128], NDArray[np.float64]]) -> tuple[NDArray[np.complex128],
                                                            NDArray[np.float64]]:
    """Resamples' FRFs and coherence (:func:`resampled_frfs`, ``drawn``) moved onto the
    data: the FRFs (coherence) the fit used on the lines ``used`` plus each resample's
    deviation from ``nominal``, the units' own mean (every unit once). The units are kept in
    single precision (:mod:`processing.units`); their rounding then reaches a resample only
    through its deviation, and the resample of every unit once is the data to the last
    digit."""
    H = drawn[0] + (np.transpose(problem.H[..., used], (1, 2, 0))[..., None] - nominal[0])
    if problem.coherence is None:
        return H, drawn[1]
    G0 = np.transpose(problem.coherence[..., used], (1, 2, 0))[..., None]
    return H, np.clip(drawn[1] + (G0 - nominal[1]), 0.0, 1.0)


Triple = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def _line_inverses(Xs: NDArray[np.complex128], T: NDArray[np.float64]) -> (
    NDArray[np.complex128]
):
    """Apparent masses ``B_j = T X_j^+`` (n, n_l, 6, 6) of resamples' lines Xs (n, n_l, 6, n_e)
    (:func:`processing.stiffness.line_operators`, vectorised over resamples)."""
    Xl = Xs
    Xh = np.conj(np.swapaxes(Xl, -1, -2))
    try:
        Xp = Xh @ np.linalg.inv(Xl @ Xh)
    except np.linalg.LinAlgError:
        Xp = np.linalg.pinv(Xl)
    return np.asarray(T @ Xp)


def _article_stiffness_affine(problem: Problem, Xs: NDArray[np.complex128],
                              w: NDArray[np.float64]) -> tuple[Triple, Triple]:
    """:func:`_stiffness_affine` of the plain method: eq. 14 averaged over the stiffness lines
    w (rad/s) of resamples' Xs (n, n_l, 6, n_e), with an exponential window's correction."""
    n = Xs.shape[0]
    a, T, symmetric = problem.window_decay, problem.T, problem.solver.symmetric
    MB = MASS_BASIS[None]  # (1, 10, 6, 6), symmetric
    zero, zl = np.zeros((n, 6, 6)), np.zeros((n, 10, 6, 6))
    B = _line_inverses(Xs, T)
    if a:  # P_j = -s_j^2 (M - B_j); C: least squares of Im P = w C; K = mean Re P - a C
        sq = (1j * w + a) ** 2
        C0 = np.einsum("l,nlij->nij", w, (sq[:, None, None] * B).imag) / np.sum(w**2)
        K0 = np.mean((sq[:, None, None] * B).real, axis=1) - a * C0
        cc = float(np.sum(w * (-sq).imag) / np.sum(w**2))
        kk = float(np.mean((-sq).real)) - a * cc
        Kl, Cl = np.broadcast_to(kk * MB, zl.shape), np.broadcast_to(cc * MB, zl.shape)
        if symmetric:
            K0, C0 = 0.5 * (K0 + np.swapaxes(K0, 1, 2)), 0.5 * (C0 + np.swapaxes(C0, 1, 2))
        return (K0, C0, zero), (Kl, Cl, zl)
    # the article's line average of eq. 14: K = mean(w^2) M - mean(w^2 Re B), C
    K0 = -np.mean((w**2)[:, None, None] * B.real, axis=1)
    C0 = -np.mean(w[:, None, None] * B.imag, axis=1)
    return (K0, C0, zero), (np.broadcast_to(np.mean(w**2) * MB, zl.shape), zl, zl)


def _stiffness_affine(problem: Problem, weights: LineWeights, model: str,
                      Xs: NDArray[np.complex128], ws_: NDArray[np.float64],
                      stiffening: NDArray[np.float64] | None = None,
                      ) -> tuple[Triple, Triple]:
    """The stiffness step of the main fit, M -> (K, C, D), for resamples' stiffness lines Xs
    (n, n_l, 6, n_e) with column weights ``ws_`` (n, n_e, n_l): it is affine in M, returned
    as its value at M = 0, (K, C, D) each (n, 6, 6), and its change per unit of each
    parameter, each (n, 10, 6, 6)
    (:class:`processing.stages.StiffnessStep`, vectorised over resamples); ``stiffening``:
    the main fit's ``g(w)`` on the stiffness lines (improved method without a window)."""
    n = Xs.shape[0]
    w = problem.w[weights.stiffness_lines]
    a, T, symmetric = problem.window_decay, problem.T, problem.solver.symmetric
    MB = MASS_BASIS[None]  # (1, 10, 6, 6), symmetric
    zero, zl = np.zeros((n, 6, 6)), np.zeros((n, 10, 6, 6))
    if not problem.improved:
        return _article_stiffness_affine(problem, Xs, w)
    # improved: the direct fit from 6x6 moments (processing.stiffness.fit_stiffness, with
    # an exponential window's decay a: K + a C for K and -s^2 for w^2 on the right)
    # moments sum wt w^p conj(x) x^T (and t^T) as sums over lines of per-line 6x6 sums
    Cw = np.conj(Xs) * ws_.transpose(0, 2, 1)[:, :, None, :]
    Z = Cw @ np.swapaxes(Xs, -1, -2)  # (n, n_l, 6, 6)
    R = Cw @ T.T  # (n, n_l, 6, 6)
    # the moments' per-line factors: powers 0..3 of w (and w^2 again for C with C), or with
    # the mounts' stiffening g those of processing.stiffness.line_functions
    funcs = line_functions(w, stiffening).T + 0j  # (n_l, 5)
    Gs = (Z.reshape(n, -1, 36).transpose(0, 2, 1) @ funcs).reshape(n, 6, 6, 5)
    Qs = (R.reshape(n, -1, 36).transpose(0, 2, 1) @ funcs).reshape(n, 6, 6, 5)
    G = [Gs[..., p] for p in range(4)]
    # sum wt w^q conj(x) (-s^2) x^T and .. t^T, q = 0, 1 (-s^2 = w^2 without a window)
    A0, A1 = (G[q + 2] - a**2 * G[q] - 2j * a * G[q + 1] for q in (0, 1))
    Q2, Q3 = (Qs[..., q + 2] - a**2 * Qs[..., q] - 2j * a * Qs[..., q + 1] for q in (0, 1))
    s2 = (np.ones(6) if problem.row_scale is None
          else np.asarray(problem.row_scale, dtype=np.float64) ** 2)
    G0r, G0i, G1r, G1i = G[0].real, G[0].imag, G[1].real, G[1].imag
    full = [[G0r, -G1i, -G0i], [G1i, Gs[..., 4].real, G1r], [G0i, G1r, G0r]]
    blocks = DAMPING_BLOCKS[model]
    k = len(blocks)
    Nb = np.concatenate([np.concatenate([full[r][c] for c in blocks], axis=2)
                         for r in blocks], axis=1)  # (n, 6k, 6k)
    Nb = Nb.reshape(n, k, 6, k, 6)
    blocks7 = np.zeros((n, k, 6, 6, k, 6, 6))
    for i in range(6):  # row blocks s2_i Nb on the diagonal of the equation rows
        blocks7[:, :, i, :, :, i, :] = s2[i] * Nb
    Nfull = blocks7.reshape(n, 36 * k, 36 * k)

    def rhs(R0: NDArray[Any], R1: NDArray[Any]) -> NDArray[np.float64]:
        parts = (R0.real, R1.imag, R0.imag)
        return np.concatenate([np.swapaxes(parts[b] * s2, -1, -2).reshape(*R0.shape[:-2], 36)
                               for b in blocks], axis=-1)

    # the value at M = 0 and the change per parameter: eleven right-hand sides at once
    r = np.concatenate([rhs(-Q2, -Q3)[:, None],
                        rhs(A0[:, None] @ (MB + 0j), A1[:, None] @ (MB + 0j))], axis=1)
    if symmetric:
        dup = np.kron(np.eye(k), DUPLICATION)
        v = np.linalg.solve(dup.T @ Nfull @ dup, dup.T @ np.swapaxes(r, 1, 2))
        v = np.swapaxes(dup @ v, 1, 2)  # (n, 11, 36 k)
    else:
        v = np.swapaxes(np.linalg.solve(Nfull, np.swapaxes(r, 1, 2)), 1, 2)
    v0, vl = v[:, 0], v[:, 1:]
    const, lin = [zero] * 3, [zl] * 3
    for j, b in enumerate(blocks):
        const[b] = v0[:, 36 * j:36 * (j + 1)].reshape(n, 6, 6)
        lin[b] = vl[..., 36 * j:36 * (j + 1)].reshape(n, 10, 6, 6)
    # the fit's K is K + a C with a window
    return ((const[0] - a * const[1], const[1], const[2]),
            (lin[0] - a * lin[1], lin[1], lin[2]))


def _solve_batch(problem: Problem, weights: LineWeights, fitted: Fit,
                 Xm: NDArray[np.complex128], Xs: NDArray[np.complex128],
                 wm_: NDArray[np.float64], ws_: NDArray[np.float64]) -> Triple:
    """theta (n, 10), K, C (n, 6, 6) of resamples' accelerances on the mass lines Xm
    (n, n_lm, 6, n_e) and on the stiffness lines Xs (n, n_ls, 6, n_e), with their column
    weights ``wm_`` (n, n_e, n_lm) and ``ws_`` (n, n_e, n_ls): the main fit's model (no
    leakage shapes) with its lines and damping model, solved for the fixed point of the
    inertia-stiffness iteration directly.

    For fixed data the iteration (:func:`processing.stages.iterate`) is affine in theta:
    the stiffness step is affine in M, the mass-line solve linear in K, C, D. So
    ``theta = t0 + L theta`` is one 10x10 solve a resample.
    """
    n = Xm.shape[0]
    wm = problem.w[weights.mass_lines]
    a, T = problem.window_decay, problem.T
    sw = np.sqrt(wm_).transpose(0, 2, 1)[:, :, None, :]  # (n, n_lm, 1, n_e)
    Xw = Xm * sw
    # the real-stacked mass-line moments sum Re(z) Re(x) + Im(z) Im(x) over the weighted
    # equations (MassLineProblem) are Re sum_l f_l Y_l for z = f_l x: per-line 6x6 sums
    Y = Xw @ np.conj(np.swapaxes(Xw, -1, -2))  # (n, n_lm, 6, 6)

    Yf = Y.reshape(n, -1, 36).transpose(0, 2, 1)  # (n, 36, n_lm)

    def moment(f: NDArray[Any] | complex) -> NDArray[np.float64]:
        return np.asarray((Yf @ np.broadcast_to(f, wm.shape)).real.reshape(n, 6, 6))

    s2 = (np.ones(6) if problem.row_scale is None
          else np.asarray(problem.row_scale, dtype=np.float64) ** 2)
    MBs = (MASS_BASIS * s2[None, :, None]).reshape(10, 36)
    op = np.einsum("pia,qib->pqab", MASS_BASIS * s2[None, :, None], MASS_BASIS).reshape(100, 36)
    N = (moment(1.0 + 0j).reshape(n, 36) @ op.T).reshape(n, 10, 10)
    solver = np.linalg.solve(N, np.broadcast_to(MBs, (n, 10, 36)))
    WT = T[None] @ np.swapaxes(np.sum(Xw * sw, axis=1).real, 1, 2)
    if a:  # B = T - ((K + a C) X + j w C X) / s^2
        s_2 = (1j * wm + a) ** 2
        AK = -moment(1.0 / s_2)
        AC = a * AK - moment(1j * wm / s_2)
        AD = np.zeros_like(AK)
    else:  # B = T + (g (K + j D) + j w C) X / w^2, g the mounts' stiffening (or 1)
        g = 1.0 if fitted.stiffening is None else fitted.stiffening.factor(wm)
        AK = moment(g / wm**2 + 0j)
        AC = moment(1j / wm)
        AD = moment(1j * g / wm**2)
    ws = problem.w[weights.stiffness_lines]
    (K0, C0, D0), (Kl, Cl, Dl) = _stiffness_affine(
        problem, weights, fitted.damping_model, Xs, ws_, stiffening_factor(fitted.stiffening, ws))
    W0 = WT + K0 @ AK + C0 @ AC + D0 @ AD
    Wl = Kl @ AK[:, None] + Cl @ AC[:, None] + Dl @ AD[:, None]  # (n, 10, 6, 6)
    t0 = np.einsum("npq,nq->np", solver, W0.reshape(n, 36))
    L = np.einsum("npq,nkq->npk", solver, Wl.reshape(n, 10, 36))
    theta = np.linalg.solve(np.eye(10)[None] - L, t0[..., None])[..., 0]
    if problem.options.physical:  # few resamples leave the consistent set: one at a time
        theta = np.array([constrain_physical(t, Nk) for t, Nk in zip(theta, N, strict=True)])
    K = K0 + np.einsum("np,npij->nij", theta, Kl)
    C = C0 + np.einsum("np,npij->nij", theta, Cl)
    return theta, K, C


def _mass_basis_moments(s2: NDArray[np.float64]) -> tuple[NDArray[np.float64],
                                                           NDArray[np.float64]]:
    """The (100, 36) map from vec of the 6x6 moment ``G = sum x x^T`` to the 10x10 normal
    matrix of the mass-line least squares, and the (10, 36) map ``MBs`` from vec W to its
    right-hand side, for row scales ``s2``."""
    MBs = MASS_BASIS * s2[None, :, None]
    return (np.einsum("pia,qib->pqab", MBs, MASS_BASIS).reshape(100, 36),
            MBs.reshape(10, 36))


def _masses(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mass matrices (n, 6, 6) of parameters theta (n, 10)."""
    return np.asarray((theta @ MASS_BASIS.reshape(10, 36)).reshape(-1, 6, 6))


class _MassLines:
    """The mass-line problems of resamples with leakage shapes: :class:`MassLineProblem`
    vectorised over resamples (accelerances Xm (n, 6, n_e, n_l), column weights ``wm_``
    (n, n_e, n_l), the kept real-stacked shapes ``Sh`` (n_s, 2 n_l)), for right-hand sides
    ``B = T + sum_k L_k (f_k Xc)`` (6x6 ``L_k`` times the accelerances cleaned of leakage,
    ``Xc = Xm - Y shp``, on each line scaled by ``f_k`` (n_k, n_l), e.g. K, C, D and
    ``1 / w^2``, ``j / w``, ``j / w^2``). B is linear in Xc and Xc in Y: its moments with
    the regressors and the shapes are formed once from those of Xm and of the shapes
    ``shp`` (n_s, n_l), so that each solve costs sums over columns and shapes only."""

    def __init__(self, Xm: NDArray[np.complex128], wm_: NDArray[np.float64],
                 Sh: NDArray[np.float64], s2: NDArray[np.float64], T: NDArray[np.float64],
                 f: NDArray[np.complex128], shp: NDArray[np.complex128]) -> None:
        n, n_l = Xm.shape[0], Xm.shape[-1]
        Xr = stack_real(Xm)
        wf = np.concatenate([wm_, wm_], axis=-1)  # (n, n_e, 2 n_l)
        sw = np.sqrt(wf)
        # per resample and column: the weighted shapes orthonormalised, X without them
        Q = np.linalg.qr(Sh.T[None, None] * sw[..., None])[0]  # (n, n_e, 2 n_l, n_s)
        Xw = np.swapaxes(Xr * sw[:, None], 1, 2)  # (n, n_e, 6, 2 n_l)
        Xp = np.swapaxes(Xw - (Xw @ Q) @ np.swapaxes(Q, -1, -2), 1, 2)  # (n, 6, n_e, 2 n_l)
        op, MBs = _mass_basis_moments(s2)
        Xpf = Xp.reshape(n, 6, -1)
        self.normal = ((Xpf @ np.swapaxes(Xpf, 1, 2)).reshape(n, 36) @ op.T).reshape(n, 10, 10)
        try:
            self.solver = np.linalg.solve(self.normal, np.broadcast_to(MBs, (n, 10, 36)))
        except np.linalg.LinAlgError:  # singular: the minimum-norm solution
            self.solver = np.linalg.pinv(self.normal) @ MBs
        # the leakage coefficients' normal matrices, per resample and column
        self.leak_normal = np.einsum("sl,nkl,tl->nkst", Sh, wf, Sh, optimize=True)
        wS = wf[..., None] * Sh.T  # (n, n_e, 2 n_l, n_s)
        fX = stack_real(f[:, None, None, :] * Xm[:, None])  # (n, n_k, 6, n_e, 2 n_l)
        fS = stack_real(f[:, None] * shp)  # (n_k, n_s, 2 n_l)
        # W = sum_l B Xp^T (weighted) and r = sum_l (B - M Xm) wf Sh, term by term
        self.WT = np.einsum("ie,nel,njel->nij", T, sw[..., :n_l], Xp[..., :n_l], optimize=True)
        self.WX = np.einsum("nkiel,njel->nkij", fX * sw[:, None, None], Xp, optimize=True)
        self.WY = np.einsum("ksl,nel,njel->nkesj", fS, sw, Xp, optimize=True)
        self.rT = np.einsum("ie,nels->nies", T, wS[:, :, :n_l], optimize=True)
        self.rM = np.einsum("nael,nels->naes", Xr, wS, optimize=True)
        self.rX = np.einsum("nkiel,nels->nkies", fX, wS, optimize=True)
        self.rY = np.einsum("ktl,nels->nkets", fS, wS, optimize=True)

    def solve(self, idx: NDArray[np.intp], L: NDArray[np.float64], Y: NDArray[np.float64],
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """theta (m, 10) and the leakage coefficients (m, 6, n_e, n_s) of resamples ``idx``
        for the matrices L (m, n_k, 6, 6) and the cleaning Y (m, 6, n_e, n_s)
        (:meth:`MassLineProblem.solve` of B)."""
        m, (_, k, n_e, n_s, _) = idx.size, self.WY.shape
        WY = self.WY[idx].reshape(m, k, n_e * n_s, 6)
        WX = self.WX[idx] - Y.reshape(m, 1, 6, -1) @ WY  # (m, k, 6, 6)
        W = self.WT[idx] + (L @ WX).sum(axis=1)
        theta = (self.solver[idx] @ W.reshape(m, 36, 1))[..., 0]
        Yt = np.swapaxes(Y, 1, 2)[:, None]  # (m, 1, n_e, 6, n_s)
        rX = self.rX[idx] - np.swapaxes(Yt @ self.rY[idx], 2, 3)  # (m, k, 6, n_e, n_s)
        r = (self.rT[idx] - (_masses(theta) @ self.rM[idx].reshape(m, 6, -1)).reshape(Y.shape)
             + (L @ rX.reshape(m, k, 6, -1)).sum(axis=1).reshape(Y.shape))
        return theta, np.linalg.solve(self.leak_normal[idx, None], r[..., None])[..., 0]


def _stiffness_solve(problem: Problem, model: str, G: list[NDArray[np.complex128]],
                     Q: list[NDArray[np.complex128]], M: NDArray[np.float64]) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
]:
    """K, C, D (m, 6, 6) of the improved method's stiffness step for mass matrices M (m, 6,
    6) from the stiffness moments G0..G3, G2c and Q0..Q3 (m, 6, 6) of
    :class:`processing.stiffness.StiffnessMoments` (:func:`processing.stiffness.
    fit_stiffness`, vectorised)."""
    m, a = M.shape[0], problem.window_decay
    R0, R1 = ((G[q + 2] - a**2 * G[q] - 2j * a * G[q + 1]) @ np.swapaxes(M, 1, 2)
              - (Q[q + 2] - a**2 * Q[q] - 2j * a * Q[q + 1]) for q in (0, 1))
    s2 = (np.ones(6) if problem.row_scale is None
          else np.asarray(problem.row_scale, dtype=np.float64) ** 2)
    parts_rhs = (R0.real, R1.imag, R0.imag)
    blocks = DAMPING_BLOCKS[model]
    r = np.concatenate([np.swapaxes(parts_rhs[b] * s2, 1, 2).reshape(m, 36) for b in blocks],
                       axis=1)
    N = stiffness_normal(G[0], G[1], G[4], s2, model)  # type: ignore[arg-type]
    if problem.solver.symmetric:
        first, second, off, back = vech_index(len(blocks))
        v = np.linalg.solve(vech_normal(N), (r[:, first] + np.where(off, r[:, second], 0.0))
                            [..., None])[:, back, 0]
    else:
        v = np.linalg.solve(N, r[..., None])[..., 0]
    parts = [np.zeros((m, 6, 6))] * 3
    for k, b in enumerate(blocks):
        parts[b] = v[:, 36 * k:36 * (k + 1)].reshape(m, 6, 6)
    return parts[0] - a * parts[1], parts[1], parts[2]


class _StiffnessLines:
    """The stiffness moments of resamples' stiffness lines Xs (n, 6, n_e, n_l) at ``w``
    (n_l,) rad/s with column weights ``ws_`` (n, n_e, n_l), cleaned of leakage ``Y shp``
    (Y (n, 6, n_e, n_s) real, the shapes ``shp`` (n_s, n_l)): formed from the moments of Xs,
    of Xs with the shapes and of the shapes, computed once, so that an iteration's
    cleaning costs sums over columns and shapes only (``Xc = Xs - Y shp``:
    ``G(Xc) = G(Xs) - P Y^T - (P Y^T)^H + Y S Y^T``)."""

    def __init__(self, w: NDArray[np.float64], Xs: NDArray[np.complex128],
                 ws_: NDArray[np.float64], shp: NDArray[np.complex128],
                 T: NDArray[np.float64], stiffening: NDArray[np.float64] | None = None,
                 ) -> None:
        n = Xs.shape[0]
        self.T = T
        self.A, self.P, self.S, self.x, self.c = [], [], [], [], []
        Xf = np.swapaxes(Xs.reshape(n, 6, -1), 1, 2)
        # the per-line factors of G0..G3 and G2c (processing.stiffness.line_functions)
        for f in line_functions(w, stiffening):
            wt = ws_ * f  # (n, n_e, n_l)
            Xw = np.conj(Xs) * wt[:, None]
            self.A.append(Xw.reshape(n, 6, -1) @ Xf)
            self.P.append(Xw @ shp.T)  # (n, 6, n_e, n_s)
            self.S.append(np.einsum("nel,sl,tl->nest", wt, np.conj(shp), shp, optimize=True))
            self.x.append(Xw.sum(axis=-1))  # (n, 6, n_e)
            self.c.append(wt @ np.conj(shp).T)  # (n, n_e, n_s)

    def moments(self, idx: NDArray[np.intp], Y: NDArray[np.float64] | None) -> tuple[
        list[NDArray[np.complex128]], list[NDArray[np.complex128]]
    ]:
        """G0..G3, G2c and Q0..Q3, G2c's (m, 6, 6) of resamples ``idx`` cleaned of ``Y shp``
        (none when Y is None)."""
        G, Q = [], []
        for p in range(5):
            A, x = self.A[p][idx], self.x[p][idx]
            if Y is not None:
                m = idx.size
                Yf = Y.reshape(m, 6, -1)
                t2 = self.P[p][idx].reshape(m, 6, -1) @ np.swapaxes(Yf, 1, 2)
                YS = np.swapaxes(np.swapaxes(Y, 1, 2) @ self.S[p][idx], 1, 2)  # (m, 6, e, s)
                A = A - t2 - np.conj(np.swapaxes(t2, 1, 2)) + YS.reshape(m, 6, -1) @ np.swapaxes(
                    Yf, 1, 2)
                x = x - (Y * self.c[p][idx][:, None]).sum(axis=-1)
            G.append(A)
            Q.append(x @ self.T.T)
        return G, Q


def _solve_iterated(problem: Problem, weights: LineWeights, fitted: Fit, bands: Bands,
                    Xm: NDArray[np.complex128], Xs: NDArray[np.complex128],
                    wm_: NDArray[np.float64], ws_: NDArray[np.float64]) -> Triple:
    """:func:`_solve_batch` for a fit with leakage shapes (improved method: the cleaning of
    the accelerances makes the iteration non-linear): the iteration of
    :func:`processing.stages.iterate` itself, from the main fit's solution, for every
    resample at once (accelerances Xm (n, 6, n_e, n_lm) on the mass lines, Xs on the
    stiffness lines, with their column weights ``wm_``, ``ws_``); each resample stops where
    its own theta converges."""
    msel, ssel, a = weights.mass_lines, weights.stiffness_lines, problem.window_decay
    ml0 = fitted.mass_line
    assert ml0 is not None and ml0.shapes is not None
    shapes = leakage_shapes(problem, bands) or [upper_residual(problem.w)]
    shp = np.array(shapes)[ml0.shape_index]  # (n_s, n_f) the kept shapes
    shp_m, shp_s = shp[:, msel], shp[:, ssel]
    s2 = (np.ones(6) if problem.row_scale is None
          else np.asarray(problem.row_scale, dtype=np.float64) ** 2)
    wm, ws, n = problem.w[msel], problem.w[ssel], Xm.shape[0]
    model = "viscous" if a else fitted.damping_model
    # B = T + K*_m Xc / w^2 as sum_k L_k (f_k Xc): with an exponential window's decay a,
    # (K + a C + j w C) Xc / -s^2, else (K + j w C + j D) Xc / w^2
    s_2 = (1j * wm + a) ** -2
    g = 1.0 if fitted.stiffening is None else fitted.stiffening.factor(wm)
    f = (np.array([-s_2, -(a + 1j * wm) * s_2]) if a
         else np.array([g * wm**-2 + 0j, 1j / wm, 1j * g / wm**2]))
    lines = _MassLines(Xm, wm_, ml0.shapes, s2, problem.T, f, shp_m)
    tol = max(problem.solver.tol, 1e-9)
    theta = np.broadcast_to(fitted.theta, (n, 10)).copy()
    stiff = _StiffnessLines(ws, Xs, ws_, shp_s, problem.T,
                            stiffening_factor(fitted.stiffening, ws))
    K, C, D = _stiffness_solve(problem, model, *stiff.moments(np.arange(n), None),
                               _masses(theta))
    Y = np.zeros((n, 6, Xm.shape[2], shp.shape[0]))
    idx = np.arange(n)
    for _ in range(problem.solver.max_iter):
        L = np.stack([K[idx], C[idx]] if a else [K[idx], C[idx], D[idx]], axis=1)
        new, leakage = lines.solve(idx, L, Y[idx])
        M = _masses(new)
        # B - M X = -M Y b: clean X of the fitted leakage
        Yk = -(np.linalg.pinv(M) @ leakage.reshape(leakage.shape[0], 6, -1)).reshape(
            leakage.shape)
        Y[idx] = Yk
        K[idx], C[idx], D[idx] = _stiffness_solve(problem, model, *stiff.moments(idx, Yk), M)
        change = np.max(np.abs(new - theta[idx]) / np.maximum(
            np.abs(new), 1e-12 * np.abs(new[:, :1])), axis=1)
        theta[idx] = new
        idx = idx[change >= tol]
        if not idx.size:
            break
    if problem.options.physical:  # K, C on the cleaned lines, as the main fit
        theta = np.array([constrain_physical(t, N) for t, N in zip(theta, lines.normal,
                                                                   strict=True)])
        K, C, _D = _stiffness_solve(problem, model, *stiff.moments(np.arange(n), Y),
                                    _masses(theta))
    return theta, K, C


def resample(problem: Problem, bands: Bands, weights: LineWeights, fitted: Fit,
             units: TimeUnits, n: int = DEFAULT_RESAMPLES, seed: int = 0,
             progress: Progress | None = None) -> Bootstrap | str:
    """Bootstrap the main fit over the time data's units; or, when it cannot run, why not.

    Parameters
    ----------
    problem, bands, weights, fitted : the main identification's stages
    units : the units of the problem's columns, in its column order
    n : resamples (at least 2)
    seed : of the resampling (the same seed gives the same resamples)
    progress : called with (resamples done, n) before the first chunk of resamples and
        after each (at least :data:`PROGRESS_STEPS` of them)
    """
    if n < 2:
        raise InputError(f"the bootstrap needs at least 2 resamples, got {n}")
    few = [(lab, c.n_units) for lab, c in zip(units.labels(), units.columns, strict=True)
           if c.n_units < 2]
    if few:
        return (f"no bootstrap over {units.kind}s: {few[0][0]} has {few[0][1]} "
                f"(at least 2 needed)")
    used = weights.mass_lines | weights.stiffness_lines
    rng = np.random.default_rng([seed, 15])
    counts = [rng.multinomial(c.n_units, np.full(c.n_units, 1.0 / c.n_units), size=n)
              .astype(float) for c in units.columns]
    # the units must give the FRFs the fit used (the nominal: every unit once)
    lines = problem.freq[used]
    nominal = resampled_frfs(units, lines, [np.ones((1, c.n_units)) for c in units.columns])
    if nominal is None:
        return f"no bootstrap over {units.kind}s: their lines differ from the FRFs'"
    ref = problem.H[..., used]
    # the units are kept in single precision (processing.units): their sums are exact to
    # a few of its rounding steps, the FRFs to the last digit
    eps = float(np.finfo(units.columns[0].Sff.dtype).eps)
    if not np.allclose(np.transpose(nominal[0][..., 0], (2, 0, 1)), ref, rtol=100 * eps,
                       atol=10 * eps * float(np.max(np.abs(ref)))):
        return f"no bootstrap over {units.kind}s: their spectra do not give the FRFs identified"
    idx = np.flatnonzero(used)
    mass = np.isin(idx, np.flatnonzero(weights.mass_lines))
    stiff = np.isin(idx, np.flatnonzero(weights.stiffness_lines))
    shapes = fitted.mass_line is not None and fitted.mass_line.shapes is not None
    # resamples in chunks: the FRFs of a chunk hold at most CHUNK_VALUES values
    size = len(units.columns) * lines.size * problem.H.shape[0]
    step = max(1, min(n, CHUNK_VALUES // max(size, 1), -(-n // PROGRESS_STEPS)))
    out = []
    for lo in range(0, n, step):
        if progress is not None:
            progress(lo, n)
        drawn = resampled_frfs(units, lines, [c[lo:lo + step] for c in counts])
        assert drawn is not None
        X, colw = weighted_accelerances(problem, used, *about_the_data(problem, used, nominal,
                                                                       drawn))
        wm_ = colw[..., mass] * (weights.mass > 0)  # a column the main fit dropped stays out
        ws_ = colw[..., stiff] * (weights.stiffness > 0)
        if shapes:
            Xt = np.transpose(X, (0, 2, 3, 1))  # (m, 6, e, l)
            out.append(_solve_iterated(problem, weights, fitted, bands, Xt[..., mass],
                                       Xt[..., stiff], wm_, ws_))
        else:
            out.append(_solve_batch(problem, weights, fitted, X[:, mass], X[:, stiff], wm_,
                                    ws_))
    if progress is not None:
        progress(n, n)
    theta, K, C = (np.concatenate([o[k] for o in out]) for k in range(3))
    labels = units.labels()
    groups = tuple(lab for lab, c in zip(labels, units.columns, strict=True)
                   for _ in range(c.n_units))
    return Bootstrap(theta, K, C, np.concatenate(counts, axis=1),
                     groups, units.kind, tuple(c.n_units for c in units.columns))
