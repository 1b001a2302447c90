"""The prepared identification problem: what every stage of :mod:`processing.identify` reads.

:func:`prepare` checks the input once and computes, once, everything that does not
depend on the bands: the geometry (E, T and their checks), the rigid-body
accelerances at O ``X = E^+ H`` (eq. 6), the per-line reconstruction error
(eqs. 15-16), the elastic modes seen in the residual, the FRF noise level, and the
coherence weights of each excitation column. The stages that follow (bands,
weights, fit, checks) take the :class:`Problem` and return their own results.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from processing._kernels import real_times_complex
from processing.data import InputError
from processing.geometry import (
    DEFAULT_MAX_COND_T,
    GeometryError,
    GeometryReport,
    check_geometry,
    excitation_matrix,
    response_matrix,
    scaling,
)
from processing.montecarlo import StatedUncertainty
from processing.results import Method
from processing.selection import ElasticPeak, elastic_peaks, reconstruction_error

__all__ = ["IdentifyOptions", "Problem", "SolverSettings", "prepare"]


#: noise floor of every FRF value, relative to the FRFs' median RMS over lines, for FRFs
#: given with their coherence (an analyser's, a file's): the coherence stands for their noise
COHERENCE_NOISE_FLOOR = 1e-3
#: error floor of every FRF value, relative to the FRFs' median RMS over lines, for FRFs
#: estimated here from time records (hits, blocks): their estimation errors (leakage, windows,
#: responses settling) do not show in the coherence, which stays close to 1 at small values
TIME_DATA_ERROR_FLOOR = 3e-2


@dataclass(frozen=True)
class IdentifyOptions:
    """The user's choices for :func:`processing.identify.fit`. Bands in Hz; ``None`` chooses
    them. How the solver works is apart (:class:`SolverSettings`); what is read from the data
    lives in the measurement (:class:`processing.measurement.Provenance`) and the result."""

    method: Method = "improved"
    mass_band: tuple[float, float] | None = None
    stiffness_band: tuple[float, float] | None = None
    physical: bool = False
    #: coherence under which an FRF value counts as low (it is weighed down, never dropped)
    coherence_threshold: float = 0.8
    #: rounds of response-point location refinement (:mod:`processing.refine`); 0 = off
    refine_points: int = 0
    #: standard deviations of the results from the fit's covariance (:mod:`processing.uncertainty`)
    uncertainty: bool = True
    #: damping model of K*: chosen from the data ("auto") or viscous K + jwC only
    damping: Literal["auto", "viscous"] = "auto"
    #: improved method: the mounts' stiffening with frequency read from the stiffness lines
    #: and carried into the mass line when they call for it ("auto"), or K constant
    stiffening: Literal["auto", "constant"] = "auto"
    #: improved method: each response channel's delay against the force read from the FRFs'
    #: phase and taken out when it shows ("auto"), or the FRFs taken as they are
    #: (:mod:`processing.delays`)
    channel_delays: Literal["auto", "off"] = "auto"
    #: stated test uncertainties propagated by Monte Carlo (:mod:`processing.montecarlo`)
    stated: StatedUncertainty | None = None
    #: resamples of the bootstrap over the hits or blocks of time data
    #: (:mod:`processing.bootstrap`); None: 200 when every point has at least 3; 0: none
    bootstrap: int | None = None


@dataclass(frozen=True)
class SolverSettings:
    """How the identification's solver works (the defaults serve every test)."""

    #: section 3: keep lines whose reconstruction error is below level x the band mean
    level: float = 3.0
    max_cond_T: float = DEFAULT_MAX_COND_T
    max_iter: int = 50
    #: largest relative change of theta's entries between iterations at convergence: the
    #: fixed point's error is of that order (1e-10 left 1e-9 of K on exact data, where the
    #: article's direct solve reaches 1e-11; 1e-12 costs 38 iterations for 32 at the median
    #: of the accuracy suite, and no more time)
    tol: float = 1e-12
    #: improved method: model elastic leakage when elastic modes are seen ("auto") or never
    leakage: Literal["auto", "off"] = "auto"
    symmetric: bool = True
    #: relative FRF noise above which elastic leakage is not modelled
    leakage_max_noise: float = 0.002
    #: bound the automatic mass-line band by the rigidity check (article section 5.1)
    use_rigidity: bool = True


@dataclass(frozen=True)
class Problem:
    """The identification problem, prepared once (lines above 0 Hz only).

    Attributes
    ----------
    options : IdentifyOptions
    solver : SolverSettings
    freq, w : (n_f,) line frequencies, Hz and rad/s
    H : (n_resp, n_exc, n_f) complex accelerances, (m/s^2)/N
    coherence : (n_resp, n_exc, n_f) or None
    geometry : GeometryReport
    E, Epinv : (n_resp, 6), (6, n_resp) response matrix and its pseudo-inverse
    T : (6, n_exc) generalised unit forces at O
    X : (6, n_exc, n_f) rigid-body accelerances at O (eq. 6; each response weighted by its
        coherence when given)
    rel_err : (n_f,) relative rigid-body reconstruction error (eq. 15)
    peaks : elastic modes seen in the non-rigid residual
    noise : relative FRF noise read from the reconstruction residual
    col_weights : (n_exc, n_f) weight of each excitation column on each line, from the
        coherence of its FRF values (1 without coherence; see :func:`_weighted_accelerances`)
    line_ok : (n_f,) lines where T restricted to the coherent columns has rank 6 and
        condition at most ``solver.max_cond_T``
    row_scale : (6,) scale of the equation rows (1/L on moments, improved method) or None
    exponential_tau : time constant of an exponential window on the records, s, or None
    warnings : messages of the geometry checks
    coherence_floor : floor of every FRF value's error under the coherence, relative to the
        FRFs' typical RMS (see :func:`prepare`)
    """

    options: IdentifyOptions
    solver: SolverSettings
    freq: NDArray[np.float64]
    w: NDArray[np.float64]
    H: NDArray[np.complex128]
    coherence: NDArray[np.float64] | None
    geometry: GeometryReport
    E: NDArray[np.float64]
    Epinv: NDArray[np.float64]
    T: NDArray[np.float64]
    X: NDArray[np.complex128]
    rel_err: NDArray[np.float64]
    peaks: tuple[ElasticPeak, ...]
    noise: float
    col_weights: NDArray[np.float64]
    line_ok: NDArray[np.bool_]
    row_scale: NDArray[np.float64] | None
    exponential_tau: float | None
    warnings: tuple[str, ...]
    #: (n_resp, 3), (n_exc, 3) the points as given, m
    resp_xyz: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    exc_xyz: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    #: floor of every FRF value's error under the coherence, relative to the FRFs' typical RMS
    coherence_floor: float = COHERENCE_NOISE_FLOOR

    @property
    def improved(self) -> bool:
        """True for the improved method, False for the article's plain one."""
        return self.options.method == "improved"

    @property
    def from_time_records(self) -> bool:
        """True for FRFs estimated here from time records (:func:`time_records_floor`)."""
        return time_records_floor(self.coherence_floor)

    @property
    def window_decay(self) -> float:
        """Decay rate ``a = 1 / tau`` of the exponential window, 1/s (0 without one)."""
        return 1.0 / self.exponential_tau if self.exponential_tau else 0.0

    @property
    def line_snr(self) -> NDArray[np.float64] | None:
        """(n_f,) signal-to-noise power ratio of each line, ``g / (1 - g)`` of its FRF values'
        median coherence ``g`` (at most 1e4), or None without coherence."""
        return None if self.coherence is None else _line_snr(self.coherence)

    @property
    def clean_lines(self) -> NDArray[np.bool_]:
        """(n_f,) lines where T is usable and no column weighs under a tenth of its median
        over the lines, nor under a tenth of the median column (all lines if under 8): a
        column dropping out on some lines (shaker force drop-outs at resonances) makes them
        unclean. For FRFs estimated here from time records (their error floor,
        :data:`TIME_DATA_ERROR_FLOOR`) only the first counts: a column weaker everywhere (a
        point far from the body's centre, a lower force) leaves the lines clean."""
        w = self.col_weights
        own = np.median(w, axis=1, keepdims=True)
        ref = own if self.from_time_records else np.maximum(own, 1.0)
        clean = self.line_ok & np.all(w >= 0.1 * ref, axis=0)
        return clean if np.count_nonzero(clean) >= 8 else np.ones(self.freq.size, bool)


def time_records_floor(floor: float) -> bool:
    """True when a coherence error floor is that of FRFs estimated here from time records
    (at least :data:`TIME_DATA_ERROR_FLOOR`): they are weighed by each FRF's median
    variance and their clean lines follow each column's own median only."""
    return floor >= TIME_DATA_ERROR_FLOOR


def _line_snr(coherence: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n_f,) ``g / (1 - g)`` of each line's median coherence ``g``, at most 1e4."""
    g = np.median(coherence, axis=(0, 1))
    return np.asarray(np.minimum(g / np.maximum(1.0 - g, 1e-300), 1e4))


def _checked_arrays(
    freq: NDArray[np.float64], H: NDArray[np.complex128],
    coherence: NDArray[np.float64] | None,
) -> tuple[NDArray[np.float64], NDArray[np.complex128], NDArray[np.float64] | None, int]:
    """Validated ``freq``, ``H`` (contiguous, all lines), coherence above 0 Hz, index of 0+ Hz."""
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
    if coherence is not None:
        coherence = np.asarray(coherence, float)[..., k0:]
        if not np.all(np.isfinite(coherence)):
            raise InputError("the coherence holds NaN values: re-measure or drop it")
    if freq.size - k0 < 8:
        raise InputError(f"only {freq.size - k0} frequency lines: at least 8 are needed")
    return freq, np.ascontiguousarray(H), coherence, k0


def _checked_geometry(
    resp_xyz: NDArray[np.float64], resp_dirs: NDArray[np.float64],
    exc_xyz: NDArray[np.float64], exc_dirs: NDArray[np.float64], max_cond_T: float,
) -> tuple[GeometryReport, list[str]]:
    """Geometry report (raises :class:`GeometryError` below rank 6) and its warnings."""
    geo = check_geometry(resp_xyz, resp_dirs, exc_xyz, exc_dirs, max_cond_T=1e300)
    if not geo.ok:
        raise GeometryError("; ".join(geo.messages))
    warnings = list(geo.messages)
    if geo.cond_T > max_cond_T:
        warnings.append(
            f"cond(T) = {geo.cond_T:.1f} exceeds {max_cond_T:g}: spread the excitations"
        )
    return geo, warnings


def h1_variances(H: NDArray[np.complex128], coherence: NDArray[np.float64],
                 floor: float) -> NDArray[np.float64]:
    """Variance of each H1 value, up to the common factor ``1 / (2 n)`` of ``n`` averages:
    ``|H|^2 (1 - g) / g`` for coherence ``g``, plus ``floor^2`` (same units as H)."""
    g = np.clip(coherence, 1e-12, 1.0)
    return np.asarray(np.abs(H) ** 2 * (1.0 - g) / g + max(float(floor) ** 2, 1e-300))


def typical_rms(H: NDArray[np.complex128]) -> float:
    """The FRFs' median RMS over lines (same units as H)."""
    return float(np.median(np.sqrt(np.mean(np.abs(H) ** 2, axis=(0, 1)))))


def _weighted_accelerances(
    H: NDArray[np.complex128], E: NDArray[np.float64], coherence: NDArray[np.float64],
    length: float, floor: float,
) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """Rigid-body accelerances weighted by each FRF value's noise, and each column's weight.

    An H1 estimate's variance is ``|H|^2 (1 - g) / (2 n g)`` for coherence ``g`` over
    ``n`` averages (Bendat & Piersol); ``n`` is common to all values and drops out of
    the weights. Per excitation column, ``X = (E' W E)^-1 E' W H`` with ``W`` the inverse
    variances of its responses (``E^+ H`` when they are equal), and the
    column's weight in the mass-line and stiffness fits is the inverse of X's variance
    (translations plus rotations times ``length^2``), relative to the median column.
    An error floor of ``floor`` times the FRFs' typical RMS is added to every value's
    variance (:func:`h1_variances`; the model's own errors, which the coherence does not
    show): with a coherence of 1 everywhere the weights are equal. FRFs estimated here from
    time records (``floor`` at least :data:`TIME_DATA_ERROR_FLOOR`) have their responses
    weighed against each other by each FRF's median variance over the lines, the same on
    every line: a coherence over a few averages (a hammer test's five hits) scatters from
    line to line by more than the noise does, and a projection that follows it moves X line
    by line by the FRFs' departure from the rigid-body model (body flexibility, sensor
    positions); a channel noisy throughout still weighs less. FRFs given with their
    coherence are weighed line by line (their coherence stands for their noise). The column
    weights follow each line's variance (a force dropping out at a resonance).
    """
    var = h1_variances(H, coherence, floor * typical_rms(H))  # (n_r, n_e, n_f)
    typical = np.median(var, axis=-1, keepdims=True) if time_records_floor(floor) else var
    W = 1.0 / typical  # (n_r, n_e, n_f), or (n_r, n_e, 1) the same on every line
    W = W / np.max(W, axis=0, keepdims=True)  # per column: only the ratios matter
    # per column and line: A = E' W E, P = A^-1 E' W, as stacked matrix products (once a
    # column when W is the same on every line)
    n_r = E.shape[0]
    Wt = np.moveaxis(W, 0, -1)  # (n_e, n_f or 1, n_r)
    A = (Wt @ (E[:, :, None] * E[:, None, :]).reshape(n_r, 36)).reshape(*Wt.shape[:2], 6, 6)
    Ainv = np.linalg.inv(A)
    X = (Ainv @ ((Wt * np.moveaxis(H, 0, -1)) @ E)[..., None])[..., 0]  # (n_e, n_f, 6)
    X = np.moveaxis(X, -1, 0)  # (6, n_e, n_f)
    # X's variance on each line (n_e, n_f, 6): X = A^-1 E' W H, so sum_r P_ir^2 var_r with
    # P = A^-1 E' W, formed as (A^-1 E')^2 against W^2 var
    P2 = Ainv @ E.T
    P2 **= 2
    dvar = (P2 @ (Wt**2 * np.moveaxis(var, 0, -1))[..., None])[..., 0]
    v = dvar[..., :3].sum(-1) + length**2 * dvar[..., 3:].sum(-1)
    return X, np.median(v) / v


def _usable_lines(col_weights: NDArray[np.float64], T: NDArray[np.float64], max_cond: float,
                  L: float) -> NDArray[np.bool_]:
    """(n_f,) lines where T restricted to the weighted columns has rank 6 and a condition
    under ``max_cond``."""
    Ts = T / scaling(L)[:, None]
    masked = Ts[None, :, :] * np.moveaxis(col_weights > 0, -1, 0)[:, None, :]  # (n_f, 6, n_e)
    s = np.linalg.svd(masked, compute_uv=False)
    ok = (s[:, 5] > 1e-12 * s[:, 0]) & (s[:, 0] <= max_cond * np.maximum(s[:, 5], 1e-300))
    return np.asarray(ok)


def noise_level(
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


def prepare(
    freq: NDArray[np.float64],
    H: NDArray[np.complex128],
    resp_xyz: NDArray[np.float64],
    resp_dirs: NDArray[np.float64],
    exc_xyz: NDArray[np.float64],
    exc_dirs: NDArray[np.float64],
    *,
    coherence: NDArray[np.float64] | None,
    options: IdentifyOptions,
    exponential_tau: float | None,
    coherence_floor: float = COHERENCE_NOISE_FLOOR,
    solver: SolverSettings | None = None,
    elastic_top: float | None = None,
) -> Problem:
    """Check the input and build the :class:`Problem` (shapes as in :class:`FRFSet`).

    ``coherence_floor`` is the floor of every FRF value's error under the coherence,
    relative to the FRFs' typical RMS (:data:`COHERENCE_NOISE_FLOOR` for FRFs given,
    :data:`TIME_DATA_ERROR_FLOOR` for FRFs estimated here from time records); residual
    peaks above ``elastic_top`` (Hz) are not taken for elastic modes (a hammer's force falls
    to a spectral zero there).

    Raises
    ------
    InputError, GeometryError
        With a one-line message naming the problem and what to do.
    """
    solver = solver or SolverSettings()
    freq, H_all, coherence, k0 = _checked_arrays(freq, H, coherence)
    geo, warnings = _checked_geometry(resp_xyz, resp_dirs, exc_xyz, exc_dirs, solver.max_cond_T)
    E = response_matrix(resp_xyz, resp_dirs)
    T = excitation_matrix(exc_xyz, exc_dirs)
    n_r, n_e = H_all.shape[:2]
    Ep = np.asarray(np.linalg.pinv(E), dtype=np.float64)
    X0 = real_times_complex(Ep, H_all.reshape(n_r, -1)).reshape(6, n_e, -1)[..., k0:]
    freq, H = freq[k0:], H_all[..., k0:]
    _, rel_err = reconstruction_error(H, E, Ep, X0)
    if coherence is None:
        X, colw = X0, np.ones((n_e, freq.size))
    else:
        X, colw = _weighted_accelerances(H, E, coherence, geo.length, coherence_floor)
    line_ok = _usable_lines(colw, T, solver.max_cond_T, geo.length)
    snr = None if coherence is None else _line_snr(coherence)
    peaks = (elastic_peaks(freq, H, E, rel_err=rel_err, Epinv=Ep, line_snr=snr,
                           fmax=elastic_top) if n_r > 6 else ())
    return Problem(
        options=options, solver=solver, freq=freq, w=2 * np.pi * freq, H=H,
        coherence=coherence, geometry=geo,
        E=E, Epinv=Ep, T=T, X=X, rel_err=rel_err, peaks=peaks,
        noise=noise_level(rel_err, freq, peaks, n_r), col_weights=colw, line_ok=line_ok,
        row_scale=1.0 / scaling(geo.length) if options.method == "improved" else None,
        exponential_tau=exponential_tau, warnings=tuple(warnings),
        resp_xyz=np.asarray(resp_xyz, float), exc_xyz=np.asarray(exc_xyz, float),
        coherence_floor=coherence_floor,
    )
