"""The identification engine: inertia parameters and system dynamic stiffness.

Two methods on the same data:

``plain``
    The article as written: X = E^+ H (eq. 6); inertia by least squares over
    the mass-band lines (eqs. 7-11) with the stiffness term from eq. (14)
    averaged over the stiffness band; iterated until theta converges
    (section 2.2); lines kept by the rules of section 3.
``improved`` (default)
    The same equations, plus: moment equations scaled by the size of the
    measurement (balanced rows); K and C fitted directly and symmetric over the
    stiffness band; the leakage of elastic modes into the mass line modelled
    by free terms with the shape of each elastic mode found in the data (and
    a ``w^2`` term for modes above it), eliminated by projection; the mass
    line allowed to extend close to the first elastic mode.

Both honour coherence (lines of an excitation with a response below the
threshold are dropped), the per-line rank and condition of T, and optional
physical consistency (``physical=True``).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from processing._kernels import real_times_complex
from processing.coherence import coherence_gate
from processing.data import FRFSet, InputError
from processing.geometry import (
    DEFAULT_MAX_COND_T,
    GeometryError,
    GeometryReport,
    check_geometry,
    excitation_matrix,
    response_matrix,
    scaling,
)
from processing.inertia import InertiaProperties, inertia_properties, mass_matrix
from processing.massline import MassLineProblem, stack_real
from processing.modes import rigid_body_modes
from processing.physical import constrain_physical
from processing.refine import point_offsets
from processing.rigidity import rigidity_check
from processing.selection import (
    BandChoice,
    ElasticPeak,
    choose_bands,
    elastic_peaks,
    mode_shape_basis,
    quick_rigid_modes,
    reconstruction_error,
    select_lines,
)
from processing.stiffness import (
    StiffnessMoments,
    dynamic_stiffness,
    fit_stiffness,
    line_operators,
    stiffness_moments,
)
from processing.synthesis import SynthesisError, synthesis_error, synthesise
from processing.windows import correct_dynamic_stiffness

__all__ = ["IdentificationResult", "IdentifyOptions", "identify", "identify_arrays"]

log = logging.getLogger(__name__)

Method = Literal["improved", "plain"]


@dataclass(frozen=True)
class IdentifyOptions:
    """Options of :func:`identify`. Bands in Hz; ``None`` chooses them from the data."""

    method: Method = "improved"
    mass_band: tuple[float, float] | None = None
    stiffness_band: tuple[float, float] | None = None
    physical: bool = False
    #: section 3: keep lines whose reconstruction error is below level x the band mean
    level: float = 3.0
    max_cond_T: float = DEFAULT_MAX_COND_T
    coherence_threshold: float = 0.8
    max_iter: int = 50
    tol: float = 1e-10
    #: improved method: model elastic leakage when elastic modes are seen ("auto") or never
    leakage: Literal["auto", "off"] = "auto"
    symmetric: bool = True
    #: relative FRF noise above which elastic leakage is not modelled
    leakage_max_noise: float = 0.002
    #: rounds of response-point location refinement (:mod:`processing.refine`); 0 = off
    refine_points: int = 0
    #: bound the automatic mass-line band by the rigidity check (article section 5.1)
    use_rigidity: bool = True


@dataclass(frozen=True)
class IdentificationResult:
    """Everything identified, with the evidence. All SI, global frame of the input."""

    method: Method
    theta: NDArray[np.float64]
    M: NDArray[np.float64]
    K: NDArray[np.float64]
    C: NDArray[np.float64]
    properties: InertiaProperties
    mass_band: tuple[float, float]
    stiffness_band: tuple[float, float]
    mass_lines: NDArray[np.float64]
    stiffness_lines: NDArray[np.float64]
    iterations: int
    converged: bool
    geometry: GeometryReport
    elastic_modes: tuple[ElasticPeak, ...]
    rigid_modes_hz: NDArray[np.float64]
    reconstruction_error: NDArray[np.float64]
    synthesis: SynthesisError
    coherence_dropped: int
    coherence_checked: bool
    coherence_min: float
    physical_enforced: bool
    warnings: tuple[str, ...] = ()
    stiffness_per_line: NDArray[np.complex128] | None = field(default=None, repr=False)
    #: estimated response-point location errors (n_resp, 3), m, when refined
    point_corrections: NDArray[np.float64] | None = None
    #: frequency ranges (f_low, f_high), Hz, of the lines of the mass and stiffness bands
    #: left out because some FRF's coherence is below ``coherence_threshold``
    coherence_ranges_hz: tuple[tuple[float, float], ...] = ()
    coherence_threshold: float = 0.8

    def checks(self) -> dict[str, dict[str, Any]]:
        """Named pass/fail checks with their figures (result JSON ``checks``)."""
        p = self.properties
        rel = self.reconstruction_error
        return {
            "geometry": {
                "pass": self.geometry.ok and self.geometry.cond_T <= DEFAULT_MAX_COND_T,
                "rank_E": self.geometry.rank_E,
                "cond_E": self.geometry.cond_E,
                "rank_T": self.geometry.rank_T,
                "cond_T": self.geometry.cond_T,
            },
            "coherence": {
                "pass": (not self.coherence_checked) or self.coherence_dropped == 0,
                "checked": self.coherence_checked,
                "threshold": self.coherence_threshold,
                "min_in_mass_band": self.coherence_min,
                "dropped_lines": self.coherence_dropped,
                "dropped_ranges_hz": [list(r) for r in self.coherence_ranges_hz],
            },
            "rigidity": {
                "pass": bool(np.max(rel) < 0.1) if rel.size else True,
                "max_reconstruction_error_in_mass_band": float(np.max(rel)) if rel.size else 0.0,
                "mean_reconstruction_error_in_mass_band": float(np.mean(rel)) if rel.size else 0.0,
            },
            "physical_consistency": {
                "pass": p.physically_consistent,
                "positive_definite": p.positive_definite,
                "triangle_inequality": p.triangle_inequality,
                "triangle_margin": p.triangle_margin,
                "enforced": self.physical_enforced,
            },
            "reconstruction_error": {
                "pass": self.synthesis.overall < 0.1,
                "synthesis_error_overall": self.synthesis.overall,
                "synthesis_error_max_frf": float(np.max(self.synthesis.per_frf)),
                "band": list(self.synthesis.band),
            },
            "convergence": {"pass": self.converged, "iterations": self.iterations},
        }

    def to_json(self) -> dict[str, Any]:
        """The result JSON of ``METHOD.md`` (plus extra keys)."""
        p = self.properties
        return {
            "mass": p.mass,
            "cog": p.cog.tolist(),
            "inertia_cog": p.inertia_cog.tolist(),
            "inertia_origin": p.inertia_origin.tolist(),
            "principal_moments": p.principal_moments.tolist(),
            "principal_axes": p.principal_axes.tolist(),
            "stiffness": self.K.tolist(),
            "damping": self.C.tolist(),
            "bands": {"mass_line": list(self.mass_band), "stiffness": list(self.stiffness_band)},
            "checks": _jsonable(self.checks()),
            "theta": self.theta.tolist(),
            "method": self.method,
            "rigid_modes_hz": self.rigid_modes_hz.tolist(),
            "elastic_modes": [
                {"frequency_hz": e.frequency, "damping_ratio": e.damping}
                for e in self.elastic_modes
            ],
            "lines_used": {
                "mass_line": len(self.mass_lines), "stiffness": len(self.stiffness_lines)
            },
            "warnings": list(self.warnings),
            "response_point_corrections": (None if self.point_corrections is None
                                           else self.point_corrections.tolist()),
            "modes": _modes_json(self.M, self.K, self.C),
        }


def _modes_json(M: NDArray[np.float64], K: NDArray[np.float64], C: NDArray[np.float64]
                ) -> list[dict[str, Any]]:
    """The six rigid-body modes (``METHOD.md`` key ``modes``); empty when M is not positive
    definite (no modes exist)."""
    try:
        return rigid_body_modes(M, K, C).to_json()
    except ValueError:
        return []


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def _noise_level(
    rel_err: NDArray[np.float64], freq: NDArray[np.float64], peaks: tuple[ElasticPeak, ...],
    n_r: int,
) -> float:
    """Relative FRF noise from the rigid-body reconstruction residual (lower quartile over the
    lines below a third of the first elastic mode, corrected for the 6 fitted DOFs)."""
    top = min(p.frequency for p in peaks) / 3 if peaks else freq[-1]
    sel = freq <= top
    if n_r <= 6 or not np.any(sel):
        return 0.0
    return float(np.percentile(rel_err[sel], 25) * np.sqrt(n_r / (n_r - 6)))


def _band_mask(freq: NDArray[np.float64], band: tuple[float, float], what: str) -> (
    NDArray[np.bool_]
):
    lo, hi = float(band[0]), float(band[1])
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
        raise InputError(f"{what} band {lo:g}-{hi:g} Hz is empty: give LO < HI")
    if lo < freq[0] - 1e-9 or hi > freq[-1] + 1e-9:
        raise InputError(
            f"{what} band {lo:g}-{hi:g} Hz is outside the data ({freq[0]:g}-{freq[-1]:g} Hz): "
            "choose a band inside it"
        )
    m = (freq >= lo) & (freq <= hi)
    if np.count_nonzero(m) < 2:
        raise InputError(f"{what} band {lo:g}-{hi:g} Hz holds fewer than 2 lines: widen it")
    return m


def _line_weights(
    coherence: NDArray[np.float64] | None, threshold: float, T: NDArray[np.float64],
    max_cond: float, L: float,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Weights (n_exc, n_f): 0 where a column has low coherence; lines where T stays usable."""
    n_e = T.shape[1]
    if coherence is None:
        return np.ones((n_e, 0)), np.ones(0, bool)
    good = np.all(coherence >= threshold, axis=0)  # (n_e, n_f)
    Ts = T / scaling(L)[:, None]
    masked = Ts[None, :, :] * np.moveaxis(good, -1, 0)[:, None, :]  # (n_f, 6, n_e)
    s = np.linalg.svd(masked, compute_uv=False)
    ok = (s[:, 5] > 1e-12 * s[:, 0]) & (s[:, 0] <= max_cond * np.maximum(s[:, 5], 1e-300))
    return good.astype(float), ok


def identify(frf: FRFSet, options: IdentifyOptions | None = None) -> IdentificationResult:
    """Identify the ten inertia parameters and K, C at O from an :class:`FRFSet`.

    Uses what the FRF set carries besides H: its coherence (lines below the
    threshold are kept out of the fit), the rigidity check of its response nodes
    (bounds the automatic mass-line band) and ``meta["exponential_tau"]`` (the
    damping an exponential window added is removed from C).

    Raises
    ------
    InputError, GeometryError
        With a one-line message naming the problem and what to do.
    """
    opt = options or IdentifyOptions()
    rigid_top: float | None = None
    notes: list[str] = []
    if opt.use_rigidity and (opt.mass_band is None or opt.stiffness_band is None):
        try:
            rc = rigidity_check(frf, fmin=float(frf.freq[frf.freq > 0][0]))
        except (GeometryError, IndexError):
            rc = None  # fewer than 3 response nodes: the elastic-mode detection still bounds it
        if rc is not None:
            if rc.band is None:
                notes.append("rigidity check: no rigid band found (check sensor mounting "
                             "and coordinates)")
            elif rc.band[1] < frf.freq[-1]:
                rigid_top = rc.band[1]
    tau = frf.meta.get("exponential_tau") if frf.meta else None
    result = identify_arrays(
        frf.freq, frf.H, frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
        coherence=frf.coherence, options=opt, rigid_band_top=rigid_top,
        exponential_tau=float(tau) if isinstance(tau, int | float) and tau > 0 else None,
    )
    if notes:
        result = dataclasses.replace(result, warnings=(*result.warnings, *notes))
    return result


def identify_arrays(
    freq: NDArray[np.float64],
    H: NDArray[np.complex128],
    resp_xyz: NDArray[np.float64],
    resp_dirs: NDArray[np.float64],
    exc_xyz: NDArray[np.float64],
    exc_dirs: NDArray[np.float64],
    *,
    coherence: NDArray[np.float64] | None = None,
    options: IdentifyOptions | None = None,
    rigid_band_top: float | None = None,
    exponential_tau: float | None = None,
) -> IdentificationResult:
    """:func:`identify` on plain arrays (shapes as in :class:`FRFSet`).

    ``rigid_band_top`` (Hz) bounds the automatic mass-line band; ``exponential_tau``
    (s) is the time constant of an exponential window applied to the records.
    """
    opt = options or IdentifyOptions()
    if opt.refine_points > 0:
        return _refined(freq, H, resp_xyz, resp_dirs, exc_xyz, exc_dirs, coherence, opt,
                        rigid_band_top, exponential_tau)
    freq = np.asarray(freq, dtype=float)
    H = np.asarray(H)
    if H.ndim != 3 or H.shape[-1] != freq.size:
        raise InputError(f"H must be (n_resp, n_exc, {freq.size}), got {H.shape}")
    if not np.all(np.isfinite(H)):
        n_bad = int(np.count_nonzero(~np.isfinite(H)))
        raise InputError(f"the FRFs hold {n_bad} NaN or infinite values: re-measure or drop them")
    if not np.all(np.isfinite(freq)) or np.any(np.diff(freq) <= 0):
        raise InputError("frequencies must be finite and strictly increasing")
    k0 = int(np.searchsorted(freq, 0.0, side="right"))  # lines at 0 Hz carry no mass line
    H_all = np.ascontiguousarray(H)
    freq, H = freq[k0:], H_all[..., k0:]
    if coherence is not None:
        coherence = np.asarray(coherence, float)[..., k0:]
        if not np.all(np.isfinite(coherence)):
            raise InputError("the coherence holds NaN values: re-measure or drop it")
    if freq.size < 8:
        raise InputError(f"only {freq.size} frequency lines: at least 8 are needed")
    geo = check_geometry(resp_xyz, resp_dirs, exc_xyz, exc_dirs, max_cond_T=1e300)
    if not geo.ok:
        raise GeometryError("; ".join(geo.messages))
    warnings: list[str] = list(geo.messages)
    if geo.cond_T > opt.max_cond_T:
        warnings.append(
            f"cond(T) = {geo.cond_T:.1f} exceeds {opt.max_cond_T:g}: spread the excitations"
        )
    E = response_matrix(resp_xyz, resp_dirs)
    T = excitation_matrix(exc_xyz, exc_dirs)
    n_r, n_e, n_f = H.shape
    Ep = np.asarray(np.linalg.pinv(E), dtype=np.float64)
    X = real_times_complex(Ep, H_all.reshape(n_r, -1)).reshape(6, n_e, -1)[..., k0:]
    w_all = 2 * np.pi * freq
    improved = opt.method == "improved"
    L = geo.length
    row_scale = 1.0 / scaling(L) if improved else None

    # --- coherence and per-line T checks -------------------------------------------------------
    colw, line_ok = _line_weights(coherence, opt.coherence_threshold, T, opt.max_cond_T, L)
    if coherence is None:
        colw = np.ones((n_e, n_f))
        line_ok = np.ones(n_f, bool)

    # --- elastic modes and bands -----------------------------------------------------------------
    _, rel_err = reconstruction_error(H, E, Ep, X)
    peaks = elastic_peaks(freq, H, E, rel_err=rel_err, Epinv=Ep) if n_r > 6 else ()
    # Leakage terms are free per equation entry: on noisy data the regressors left after
    # eliminating them are dominated by noise and the fit is biased low (errors in
    # variables). Model the leakage only when the FRF noise, read off the rigid-body
    # reconstruction residual well below the first elastic mode, is small.
    noise = _noise_level(rel_err, freq, peaks, n_r)
    use_leak = (improved and opt.leakage == "auto" and len(peaks) > 0
                and noise <= opt.leakage_max_noise)
    if improved and peaks and not use_leak:
        warnings.append(
            f"elastic leakage not modelled (FRF noise {noise * 100:.2f} % > "
            f"{opt.leakage_max_noise * 100:g} %): mass line kept to half the elastic mode"
        )
    choice: BandChoice | None = None
    if opt.mass_band is None or opt.stiffness_band is None:
        # bands from the lines where every FRF is coherent and T stays usable
        clean = line_ok & np.all(colw > 0, axis=0)
        if np.count_nonzero(clean) < 8:
            clean = np.ones(n_f, bool)
        choice = choose_bands(freq[clean], X[..., clean], T, peaks,
                              elastic_margin=0.7 if use_leak else 0.5,
                              rigid_band_top=rigid_band_top)
    mass_band = opt.mass_band or (choice.mass_band if choice else (0.0, 0.0))
    stiff_band = opt.stiffness_band or (choice.stiffness_band if choice else (0.0, 0.0))
    in_mass = _band_mask(freq, mass_band, "mass-line")
    in_stiff = _band_mask(freq, stiff_band, "stiffness")
    mass_sel = select_lines(rel_err, in_mass & line_ok, opt.level)
    stiff_sel = in_stiff & line_ok
    if np.count_nonzero(mass_sel) < 2:
        raise InputError(
            f"fewer than 2 usable lines in the mass-line band {mass_band[0]:g}-{mass_band[1]:g} Hz "
            "(coherence, rank or condition of T): widen the band or re-measure"
        )
    if np.count_nonzero(stiff_sel) < 2:
        raise InputError(
            f"fewer than 2 usable lines in the stiffness band {stiff_band[0]:g}-{stiff_band[1]:g}"
            " Hz: widen the band or re-measure"
        )
    coh_dropped = int(np.count_nonzero(colw[:, in_mass | in_stiff] == 0))
    coh_min = float(np.min(coherence[..., in_mass])) if coherence is not None else 1.0
    coh_ranges = () if coherence is None else coherence_gate(  # lines outside the bands pass
        np.where(in_mass | in_stiff, coherence, 1.0), freq, opt.coherence_threshold).ranges

    Xm, wm, Wm = X[..., mass_sel], w_all[mass_sel], colw[:, mass_sel]
    Xs, ws, Ws = X[..., stiff_sel], w_all[stiff_sel], colw[:, stiff_sel]

    # leakage shapes (improved method, elastic modes seen)
    shapes_c: list[NDArray[np.complex128]] = []
    if use_leak:
        shapes_c = [mode_shape_basis(w_all, p) for p in peaks]
        shapes_c.append((w_all / w_all[-1]) ** 2 + 0j)
    shapes_m = np.array([stack_real(s[mass_sel]) for s in shapes_c]) if shapes_c else None

    # --- iteration (section 2.2) --------------------------------------------------------------
    K = np.zeros((6, 6))
    C = np.zeros((6, 6))
    theta = np.zeros(10)
    X_clean_m = Xm
    X_clean_s = Xs
    converged = False
    it = 0
    fit = None
    s_moments: StiffnessMoments | None = None

    ops = line_operators(X[..., in_stiff], T, w_all[in_stiff])  # eq. 14 operators, per line
    mean_stiffness = ops.mean_kc(stiff_sel[in_stiff])
    problem = MassLineProblem(Xm, weights=Wm, row_scale=row_scale, shapes=shapes_m)

    def stiffness_step(M: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """K, C for the current mass matrix on the current (leakage-cleaned) stiffness lines."""
        nonlocal s_moments
        if a_exp:  # per line, undo the window's pole shift, then average (viscous model)
            P = -(s_s**2 / ws**2)[:, None, None] * dynamic_stiffness(X_clean_s, T, ws, M)
            C_ = np.tensordot(ws, P.imag, axes=1) / np.sum(ws**2)  # least squares, Im P = w C
            K_ = np.mean(P.real, axis=0) - a_exp * C_
            return (0.5 * (K_ + K_.T), 0.5 * (C_ + C_.T)) if opt.symmetric else (K_, C_)
        if improved:  # direct symmetric fit; moments reused until X_clean_s changes
            if s_moments is None:
                s_moments = stiffness_moments(X_clean_s, T, ws, Ws)
            sf = fit_stiffness(s_moments, T, ws, M, row_scale=row_scale, symmetric=opt.symmetric)
            return sf.K, sf.C
        return mean_stiffness(M)  # the article: eq. 14 per line, averaged

    # An exponential window exp(-a t) on force and responses measures H(j w + a): the
    # stiffness seen is K*_m = -(w^2 / s^2) (K + a C + j w C) with s = j w + a.
    a_exp = 1.0 / exponential_tau if exponential_tau else 0.0
    s_s = 1j * ws + a_exp
    s_m = 1j * wm + a_exp
    if not improved and not a_exp:
        # the article's iteration is affine in theta here: its limit is solved directly
        fit = problem.fixed_point_affine(T, mean_stiffness.w2, mean_stiffness.KB,
                                         mean_stiffness.C, wm)
        theta = fit.theta
        K, C = stiffness_step(mass_matrix(theta))
        it, converged = 1, True
    for it in range(1, opt.max_iter + 1) if improved or a_exp else ():  # noqa: B007
        if a_exp:  # B = T + K*_m X / w^2 with the windowed K*_m
            Xf = X_clean_m.reshape(6, -1)
            KX = ((K + a_exp * C) @ Xf).reshape(Xm.shape) + 1j * wm * (C @ Xf).reshape(Xm.shape)
            fit = problem.solve(T[:, :, None] - KX / s_m**2 + 0j)
        else:
            fit = problem.solve_kc(T, K, C, X_clean_m, wm)
        new = fit.theta
        M = mass_matrix(new)
        if fit.leakage is not None:
            Minv = np.linalg.inv(M)
            Yk = -np.einsum("ia,aks->iks", Minv, fit.leakage)  # B - M X = -M Y b
            leak_all = np.einsum("iks,sl->ikl", Yk, np.array(shapes_c)[problem.shape_index])
            X_clean_m = Xm - leak_all[..., mass_sel]
            X_clean_s = Xs - leak_all[..., stiff_sel]
            s_moments = None
        K, C = stiffness_step(M)
        change = np.max(np.abs(new - theta) / np.maximum(np.abs(new), 1e-12 * abs(new[0])))
        theta = new
        if change < opt.tol:
            converged = True
            break
    assert fit is not None
    physical_enforced = False
    if opt.physical:
        theta_c = constrain_physical(theta, fit.normal)
        physical_enforced = not np.array_equal(theta_c, theta)
        if physical_enforced:
            theta = theta_c
            K, C = stiffness_step(mass_matrix(theta))
    M = mass_matrix(theta)
    if exponential_tau:
        warnings.append(f"exponential window (tau = {exponential_tau:g} s): its damping "
                        "was removed from C")
    props = inertia_properties(theta)
    if not props.physically_consistent:
        warnings.append(
            "identified inertia is not physically consistent "
            f"(triangle margin {props.triangle_margin:+.3f}): use --physical or check the data"
        )
    try:
        import scipy.linalg

        w2 = scipy.linalg.eigh(0.5 * (K + K.T), M, eigvals_only=True)
        rigid_hz = np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi)
    except (np.linalg.LinAlgError, ValueError):
        rigid_hz = quick_rigid_modes(X[..., stiff_sel | mass_sel], T,
                                     w_all[stiff_sel | mass_sel])
    H_syn = synthesise(freq, E, T, M, K, C)
    syn_band = (float(freq[0]), float(mass_band[1]))
    syn = synthesis_error(freq, H, H_syn, syn_band)
    Ks_line = ops.stiffness(M)
    if exponential_tau:
        Ks_line = np.moveaxis(correct_dynamic_stiffness(
            np.moveaxis(Ks_line, 0, -1), freq[in_stiff], exponential_tau), -1, 0)
    return IdentificationResult(
        method=opt.method,
        theta=theta,
        M=M,
        K=K,
        C=C,
        properties=props,
        mass_band=(float(mass_band[0]), float(mass_band[1])),
        stiffness_band=(float(stiff_band[0]), float(stiff_band[1])),
        mass_lines=freq[mass_sel],
        stiffness_lines=freq[stiff_sel],
        iterations=it,
        converged=converged,
        geometry=geo,
        elastic_modes=peaks,
        rigid_modes_hz=rigid_hz,
        reconstruction_error=rel_err[mass_sel],
        synthesis=syn,
        coherence_dropped=coh_dropped,
        coherence_checked=coherence is not None,
        coherence_min=coh_min,
        coherence_ranges_hz=coh_ranges,
        coherence_threshold=opt.coherence_threshold,
        physical_enforced=physical_enforced,
        warnings=tuple(warnings),
        stiffness_per_line=Ks_line,
    )


def _refined(
    freq: NDArray[np.float64], H: NDArray[np.complex128], resp_xyz: NDArray[np.float64],
    resp_dirs: NDArray[np.float64], exc_xyz: NDArray[np.float64], exc_dirs: NDArray[np.float64],
    coherence: NDArray[np.float64] | None, opt: IdentifyOptions,
    rigid_band_top: float | None, exponential_tau: float | None,
) -> IdentificationResult:
    """Identification alternated ``opt.refine_points`` times with response-point refinement
    on the mass-line lines (:mod:`processing.refine`)."""
    once = dataclasses.replace(opt, refine_points=0)

    def identify_at(xyz: NDArray[np.float64]) -> IdentificationResult:
        return identify_arrays(freq, H, xyz, resp_dirs, exc_xyz, exc_dirs, coherence=coherence,
                               options=once, rigid_band_top=rigid_band_top,
                               exponential_tau=exponential_tau)

    result = identify_at(np.asarray(resp_xyz, dtype=float))
    xyz = np.array(resp_xyz, dtype=float)
    T = excitation_matrix(exc_xyz, exc_dirs)
    freq = np.asarray(freq, dtype=float)
    for _ in range(opt.refine_points):
        lines = np.isin(freq, result.mass_lines)
        w = 2 * np.pi * freq[lines]
        shapes = [mode_shape_basis(w, p) for p in result.elastic_modes]
        shapes.append(np.asarray(w**2, dtype=np.complex128))  # quasi-static, modes above
        xyz = xyz - point_offsets(freq[lines], np.asarray(H)[..., lines], xyz, resp_dirs, T,
                                  result.M, result.K, result.C, shapes=np.array(shapes))
        result = identify_at(xyz)
    return dataclasses.replace(result, point_corrections=np.asarray(resp_xyz, float) - xyz)

