"""Frequency-line and band selection (article section 3, and automatic bands).

- Reconstruction error (eqs. 15-16): how far each line's FRFs are from a
  rigid-body motion, ``H - E E^+ H``.
- Elastic modes: peaks of the non-rigid residual, fitted with a single-mode
  shape to get their frequency and damping (used to model their leakage).
- Rigid-body modes: from a quick fit of the apparent mass ``T X^+ = M - K*/w^2``.
- Bands: the mass line above the rigid-body modes and below the first elastic
  mode, the stiffness band through the rigid-body modes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from processing._kernels import real_times_complex, sumsq_columns
from processing.peaks import find_prominent, running_median
from processing.stiffness import line_operators

__all__ = [
    "BandChoice",
    "ElasticPeak",
    "choose_bands",
    "elastic_peaks",
    "mode_shape_basis",
    "reconstruction_error",
    "select_lines",
]


def reconstruction_error(
    H: NDArray[np.complex128],
    E: NDArray[np.float64],
    Epinv: NDArray[np.float64] | None = None,
    X: NDArray[np.complex128] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-line rigid-body reconstruction error (eq. 15), absolute and relative.

    Returns ``(abs_err, rel_err)``, each (n_f,): the Frobenius norm over all FRFs
    of ``H_j - E E^+ H_j``, and that divided by the norm of ``H_j``. Computed as
    ``||H||^2 - ||E X||^2`` (``E E^+`` is an orthogonal projection) from the
    rigid-body motions ``X = E^+ H`` (passed when already known), so no array
    the size of H is formed; relative errors below about 1e-7 are rounding.
    """
    n_r, n_e, n_f = H.shape
    if X is None:
        Ep = np.linalg.pinv(E) if Epinv is None else Epinv
        X = real_times_complex(Ep, np.ascontiguousarray(H).reshape(n_r, -1)).reshape(6, n_e, n_f)
    L = np.linalg.cholesky(E.T @ E)  # ||E x||^2 = ||L^T x||^2
    Y = real_times_complex(L.T, np.ascontiguousarray(X).reshape(6, -1))
    h2 = sumsq_columns(H)
    a2 = np.clip(h2 - sumsq_columns(Y.reshape(6, n_e, n_f)), 0.0, None)
    a = np.sqrt(a2)
    return a, a / np.where(h2 > 0, np.sqrt(h2), np.inf)


def select_lines(rel_err: NDArray[np.float64], in_band: NDArray[np.bool_], level: float) -> (
    NDArray[np.bool_]
):
    """Section 3 rule: keep band lines whose error is below ``level`` x the band's mean error."""
    if not np.any(in_band):
        return in_band
    mean = float(np.mean(rel_err[in_band]))
    return in_band & (rel_err <= level * mean + 1e-300)


#: least damping ratio of an elastic-mode fit (its bound); a fit at it is no mode
MIN_PEAK_DAMPING = 1e-4


@dataclass(frozen=True)
class ElasticPeak:
    """An elastic mode seen in the non-rigid residual: frequency (Hz), damping ratio."""

    frequency: float
    damping: float


def mode_shape_basis(w: NDArray[np.float64], peak: ElasticPeak) -> NDArray[np.complex128]:
    """Frequency shape of a mode's accelerance: ``-w^2 / (w_e^2 - w^2 + 2 j zeta w_e w)``."""
    we = 2 * np.pi * peak.frequency
    return np.asarray(-(w**2) / (we**2 - w**2 + 2j * peak.damping * we * w), dtype=complex)


def _fit_peak(freq: NDArray[np.float64], R: NDArray[np.complex128], f0: float) -> ElasticPeak:
    """Fit one mode ``U b(w) + V w^2`` to the residual FRFs R (n, n_f) near ``f0``."""
    sel = (freq > 0.7 * f0) & (freq < 1.3 * f0)
    if np.count_nonzero(sel) < 4:
        sel = np.isin(np.arange(freq.size), np.argsort(np.abs(freq - f0))[:6])
    f = freq[sel]
    w = 2 * np.pi * f
    Rs = R[:, sel]

    def resid(p: NDArray[np.float64]) -> NDArray[np.float64]:
        b = mode_shape_basis(w, ElasticPeak(p[0], p[1]))
        A = np.stack([b, w**2 + 0j], axis=1)  # (n_l, 2)
        Ar = np.concatenate([A.real, A.imag])
        Yr = np.concatenate([Rs.real.T, Rs.imag.T])
        coef, *_ = np.linalg.lstsq(Ar, Yr, rcond=None)
        return np.asarray((Yr - Ar @ coef).ravel())

    import scipy.optimize  # 0.1 s to import: loaded when a residual peak is fitted

    best = None
    for z0 in (0.005, 0.02, 0.06):
        sol = scipy.optimize.least_squares(
            resid, x0=[f0, z0], bounds=([0.8 * f0, MIN_PEAK_DAMPING], [1.2 * f0, 0.3]),
            x_scale=[f0, 0.01]
        )
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    return ElasticPeak(float(best.x[0]), float(best.x[1]))


def elastic_peaks(
    freq: NDArray[np.float64],
    H: NDArray[np.complex128],
    E: NDArray[np.float64],
    *,
    min_rel: float = 0.01,
    rel_err: NDArray[np.float64] | None = None,
    Epinv: NDArray[np.float64] | None = None,
    line_snr: NDArray[np.float64] | None = None,
    fmax: float | None = None,
) -> tuple[ElasticPeak, ...]:
    """Elastic modes seen in the data: peaks of the non-rigid residual.

    A peak counts where the non-rigid residual stands out of its surroundings by a
    factor 3 (prominence in log scale), either relative to the response (the relative
    reconstruction error) or in absolute power (a resonance still stands out when higher
    modes keep the relative error near 1 above it), and where the relative error exceeds
    ``min_rel`` and three times its floor (the least of its 9-line running median, where
    the rigid-body motion dominates; the noise floor there), ten times for a peak in power
    only: a peak of the residual's power at a rigid-body resonance (sensor or location
    errors) is a small part of the response there. With ``line_snr`` (n_f,), the
    signal-to-noise power ratio of each line, peaks on lines under 1 are noise (the lowest
    lines, where accelerances are small). Peaks on lines above ``fmax`` (Hz) are not
    counted (a hammer's force falls to its pulse's spectral zero there, where an FRF is
    noise over almost nothing: a spike with a lightly damped mode's shape).
    ``rel_err`` and ``Epinv`` may be passed when already computed.
    """
    n_r, n_e, n_f = H.shape
    if n_r <= 6 or n_f < 5:
        return ()
    Ep = np.asarray(np.linalg.pinv(E) if Epinv is None else Epinv, dtype=np.float64)
    rel = reconstruction_error(H, E, Ep)[1] if rel_err is None else rel_err
    P = np.eye(n_r) - E @ Ep
    R = (P @ H.reshape(n_r, -1)).reshape(n_r * n_e, n_f)
    power = np.sum(np.abs(R) ** 2, axis=0)
    prominence = np.log10(3.0)
    by_rel = find_prominent(np.log10(np.maximum(rel, 1e-12)), prominence)
    by_abs = find_prominent(np.log10(np.maximum(power, 1e-300)), 2 * prominence)  # |.|^2
    floor = float(np.min(running_median(rel, 9)))
    idx = np.union1d(by_rel[rel[by_rel] > max(min_rel, 3.0 * floor)],
                     by_abs[rel[by_abs] > max(min_rel, 10.0 * floor)])
    if line_snr is not None:
        idx = idx[line_snr[idx] >= 1.0]
    if fmax is not None:
        idx = idx[freq[idx] <= fmax]
    if idx.size == 0:
        return ()
    # keep the strongest residual directions only, for speed
    if R.shape[0] > 4:  # the leading left singular vectors, from the Hermitian R R^H
        _ev, U = np.linalg.eigh(R @ R.conj().T)
        R = U[:, ::-1][:, :4].conj().T @ R
    # at either bound of the damping (0.3, or MIN_PEAK_DAMPING: narrower than the lines
    # resolve) the residual has no mode's shape there: noise
    fitted = sorted((p for p in (_fit_peak(freq, R, float(freq[i])) for i in idx)
                     if 1.5 * MIN_PEAK_DAMPING < p.damping < 0.29), key=lambda p: p.frequency)
    # two residual peaks of one mode (a dip on its flank) fit to the same mode: keep it once
    unique: list[ElasticPeak] = []
    for p in fitted:
        if not unique or p.frequency > 1.02 * unique[-1].frequency:
            unique.append(p)
    return tuple(unique)


@dataclass(frozen=True)
class BandChoice:
    """Bands chosen from the data, with the evidence used and the reason, in words."""

    mass_band: tuple[float, float]
    stiffness_band: tuple[float, float]
    rigid_mode_max: float
    rigid_modes: NDArray[np.float64]
    elastic: tuple[ElasticPeak, ...]
    reason: str = ""
    #: True when a limit (rigidity check or elastic mode) had to be set aside
    relaxed: bool = False


def quick_rigid_modes(
    X: NDArray[np.complex128], T: NDArray[np.float64], w: NDArray[np.float64],
    line_weights: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Rigid-body mode frequencies (Hz) from a fit of ``Re(T X^+) = M - K / w^2``.

    Lines whose apparent mass is far above the mass line's (the lowest lines,
    where K / w^2 dominates and leakage or an exponential window distort the
    estimate most) are weighted down in proportion, so they cannot swamp the fit.
    ``line_weights`` (n_lines,) weigh the lines further, e.g. by their signal-to-noise
    ratio: noise on X biases ``X^+`` towards zero, and with it K (errors in variables),
    most on the low lines where the accelerances are small.
    """
    A = line_operators(X, T, w).B  # apparent mass T X^+ per line (n_l, 6, 6)
    size = np.linalg.norm(A.reshape(len(w), 36), axis=1)
    ref = float(np.median(size[w >= np.median(w)]))
    wt = np.minimum(1.0, ref / np.maximum(size, 1e-300))
    if line_weights is not None:
        wt = wt * line_weights
    u = 1.0 / w**2
    D = np.stack([np.ones_like(u), -u], axis=1)
    coef, *_ = np.linalg.lstsq(D * wt[:, None], A.real.reshape(len(w), 36) * wt[:, None],
                               rcond=None)
    M = coef[0].reshape(6, 6)
    K = coef[1].reshape(6, 6)
    M = 0.5 * (M + M.T)
    K = 0.5 * (K + K.T)
    try:
        w2 = scipy.linalg.eigh(K, M, eigvals_only=True)
    except (np.linalg.LinAlgError, ValueError):
        w2 = scipy.linalg.eigvals(K, M).real  # generalised: M may be singular here
        w2 = np.where(np.isfinite(w2), w2, 0.0)  # a singular direction of M: no mode
    return np.sort(np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi))


def _mass_line_low(freq: NDArray[np.float64], f_rig: float, f_hi: float,
                   low_factor: float) -> float | None:
    """Bottom of the mass line below ``f_hi``: ``low_factor`` (else 1.3) times the highest
    rigid-body mode, or None when fewer than 3 lines remain."""
    lo = low_factor * f_rig
    if lo >= 0.8 * f_hi:
        lo = 1.3 * f_rig
    if lo >= 0.9 * f_hi or np.count_nonzero((freq >= lo) & (freq <= f_hi)) < 3:
        return None
    return lo


def choose_bands(
    freq: NDArray[np.float64],
    X: NDArray[np.complex128],
    T: NDArray[np.float64],
    elastic: tuple[ElasticPeak, ...],
    *,
    rigid_band_top: float | None = None,
    rigid_band_fallback: float | None = None,
    mass_low_factor: float = 2.0,
    elastic_margin: float = 0.7,
    line_weights: NDArray[np.float64] | None = None,
    stiffness_low: float | None = None,
    rigid_floor: float | None = None,
) -> BandChoice:
    """Automatic mass-line and stiffness bands, with the reason.

    The mass line starts ``mass_low_factor`` times above the highest rigid-body
    mode and ends at ``elastic_margin`` times the first elastic mode, or at the
    rigidity limit ``rigid_band_top``, or at the end of the data. A limit that
    leaves no mass line above the rigid-body modes is set aside (the rigidity
    check first, upset by noise or location errors, for ``rigid_band_fallback``,
    its limit at a threshold above its error floor; then the elastic margin,
    up to 0.9x the mode) and the reason says so: a band is always returned when
    the data hold at least 8 lines. The rigid-body modes are read from the lines under
    the first limit, or, when that puts the highest over twice the limit and the limit
    is under the elastic margin, from the lines up to twice the limit (at least 8) when
    these give a lower one (the lines under the limit were too few or too noisy); and
    bottom-up, over the lines up to tops doubling from the eighth line until the top is
    twice the highest mode read there (and within 15 % of the readings at half and a
    quarter of that top, and at least 3x the first line), kept when the other reading's
    highest mode is more than :data:`BOTTOM_UP_GAP` times above (lines far past the modes,
    where the body flexes, decided it). The
    stiffness band runs from the first line (or ``stiffness_low``, Hz, when given: the
    lines given may leave out noisy ones the stiffness fit weighs down itself) to 1.5
    times the highest rigid-body mode (not into the mass line). ``line_weights`` (n_f,)
    weigh the lines in the rigid-body mode estimate (:func:`quick_rigid_modes`).
    ``rigid_floor`` (Hz): the highest rigid-body mode is taken at least there (the top mode
    of a fit whose mass line the lines' estimate had put among the modes).
    """
    limits, top = _band_limits(freq, elastic, rigid_band_top, rigid_band_fallback,
                               elastic_margin)
    fr = _rigid_modes_for_bands(freq, X, T, limits[0][0], top, line_weights)
    floor = rigid_floor is not None and rigid_floor > fr[-1]
    if rigid_floor is not None and floor:
        fr = np.append(fr[fr < rigid_floor], rigid_floor)[-fr.size:]
    f_rig = float(fr[-1])
    lo, f_hi, name, set_aside = _mass_line(freq, f_rig, limits, mass_low_factor)
    reason = (f"mass line {lo:.1f}-{f_hi:.1f} Hz: from {lo / f_rig:.2g}x the highest "
              f"rigid-body mode ({f_rig:.1f} Hz"
              + (", raised by the fit on a lower mass line: the lines' estimate put it "
                 "among the modes" if floor else "") + f") to {name}")
    if set_aside:
        reason += ("; set aside, as it leaves no mass line above the rigid-body modes: "
                   + ", ".join(set_aside))
    s_lo, s_hi = _stiffness_band(freq, f_rig, lo, stiffness_low)
    return BandChoice((float(lo), float(f_hi)), (s_lo, float(s_hi)), f_rig, fr, elastic,
                      reason, bool(set_aside))


def _band_limits(freq: NDArray[np.float64], elastic: tuple[ElasticPeak, ...],
                 rigid_band_top: float | None, rigid_band_fallback: float | None,
                 elastic_margin: float) -> tuple[list[tuple[float, str]], float]:
    """The candidate tops of the mass line (Hz, with their names), in the order
    :func:`choose_bands` tries them, and the top the elastic margin sets (Hz)."""
    f_end = float(freq[-1])
    f_el = min(p.frequency for p in elastic) if elastic else None
    limits: list[tuple[float, str]] = []
    top = min(f_end, elastic_margin * f_el) if f_el else f_end
    why = (f"{elastic_margin:g}x the first elastic mode ({f_el:.1f} Hz)" if f_el and top < f_end
           else "the end of the data")
    if rigid_band_top is not None and rigid_band_top < top:
        limits.append((rigid_band_top, "the rigidity check's limit"))
    if rigid_band_fallback is not None and rigid_band_fallback < top:
        limits.append((rigid_band_fallback, "the rigidity check's limit at 3x its error floor"))
    limits.append((top, why))
    if f_el and 0.9 * f_el < f_end:
        limits.append((0.9 * f_el, f"0.9x the first elastic mode ({f_el:.1f} Hz)"))
    limits.append((f_end, "the end of the data"))
    return limits, top


def _rigid_modes_for_bands(freq: NDArray[np.float64], X: NDArray[np.complex128],
                           T: NDArray[np.float64], first_limit: float, top: float,
                           line_weights: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """Rigid-body mode frequencies (Hz) read from the lines under ``first_limit``, with the
    fallbacks :func:`choose_bands` describes."""
    rig_lines = (freq > 0) & (freq <= first_limit)  # rigid modes from below the first limit
    if np.count_nonzero(rig_lines) < 4:
        rig_lines = (freq > 0) & (freq <= max(top, float(freq[min(7, freq.size - 1)])))
    fr = quick_rigid_modes(X[..., rig_lines], T, 2 * np.pi * freq[rig_lines],
                           None if line_weights is None else line_weights[rig_lines])
    if fr[-1] <= 0 and line_weights is not None:  # no estimate: try the lines unweighted
        fr = quick_rigid_modes(X[..., rig_lines], T, 2 * np.pi * freq[rig_lines])
    if fr[-1] <= 0:  # still none: the strongest resonance of the rigid-body accelerances
        power = np.sum(np.abs(X[..., rig_lines]) ** 2, axis=(0, 1))
        fr = np.full(6, float(freq[rig_lines][np.argmax(power)]))
    if fr[-1] > 2 * first_limit and first_limit < top:
        # far above the first limit: the lines under it are too few or too noisy to read
        # the modes from; read them again over the lines up to twice the limit
        wide = (freq > 0) & (freq <= min(top, max(2 * first_limit,
                                                  float(freq[min(7, freq.size - 1)]))))
        fw = quick_rigid_modes(X[..., wide], T, 2 * np.pi * freq[wide],
                               None if line_weights is None else line_weights[wide])
        if 0 < fw[-1] < fr[-1]:
            fr = fw
    # without a rigidity limit near the modes, the lines read run far past them, where the
    # body's flexibility and the sensors' errors bend the apparent mass and, weighed by their
    # signal, the lines far above the modes decide K (it is read as a higher mode than any):
    # the modes read bottom-up instead, when they are well under that
    fb = _rigid_modes_bottom_up(freq, X, T, top, line_weights)
    if 0 < BOTTOM_UP_GAP * fb[-1] < fr[-1]:
        fr = fb
    return fr


#: the bottom-up reading of the rigid-body modes is kept when the one over every line puts
#: the highest mode more than this many times above it
BOTTOM_UP_GAP = 2.0
#: the bottom-up reading's highest mode agrees with those at half and a quarter of the
#: lines' top to this
BOTTOM_UP_STABLE = 0.15
#: and is at least this many times the first line (a reading near the first line comes from
#: lines that all lie under the modes, where K / w^2 swamps M: M, and the modes, unread)
BOTTOM_UP_FIRST = 3.0


def _rigid_modes_bottom_up(freq: NDArray[np.float64], X: NDArray[np.complex128],
                           T: NDArray[np.float64], top: float,
                           line_weights: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """Rigid-body modes (Hz) read on the lines up to tops doubling from the eighth line, at
    the first top at least twice the highest mode read there (the lines then reach into the
    mass line, which pins M) where the highest is within
    :data:`BOTTOM_UP_STABLE` of the readings at half and a quarter of that top (not the
    noise of the lowest lines) and :data:`BOTTOM_UP_FIRST` times the first line or more;
    zeros when none is under ``top``."""
    pos = freq[freq > 0]
    if pos.size < 8:
        return np.zeros(6)
    upto, before = float(pos[7]), [0.0, 0.0]
    while upto <= top:
        sel = (freq > 0) & (freq <= upto)
        fr = quick_rigid_modes(X[..., sel], T, 2 * np.pi * freq[sel],
                               None if line_weights is None else line_weights[sel])
        if (BOTTOM_UP_FIRST * float(pos[0]) <= fr[-1] and 2 * fr[-1] <= upto
                and all(abs(fr[-1] - b) <= BOTTOM_UP_STABLE * fr[-1] for b in before)):
            return fr
        upto, before = 2 * upto, [before[1], float(fr[-1])]
    return np.zeros(6)


def _mass_line(freq: NDArray[np.float64], f_rig: float, limits: list[tuple[float, str]],
               mass_low_factor: float) -> tuple[float, float, str, list[str]]:
    """Bottom and top (Hz) of the mass line under the first limit that leaves one, the
    top's name, and the limits set aside on the way."""
    set_aside: list[str] = []
    for f_hi, name in limits:
        lo = _mass_line_low(freq, f_rig, f_hi, mass_low_factor)
        if lo is not None:
            return lo, f_hi, name, set_aside
        set_aside.append(f"{name} ({f_hi:.1f} Hz)")
    # the rigid-body modes reach the end of the data: the top third of the lines
    lo = float(freq[max(0, (2 * freq.size) // 3 - 1)])
    set_aside.append(f"{mass_low_factor:g}x the highest rigid-body mode")
    return lo, float(freq[-1]), "the end of the data", set_aside


#: fewest lines of an automatic stiffness band
MIN_STIFFNESS_LINES = 4


def _stiffness_band(freq: NDArray[np.float64], f_rig: float, lo: float,
                    stiffness_low: float | None) -> tuple[float, float]:
    """Stiffness band (Hz): from the first line (or ``stiffness_low``) to 1.5 times the
    highest rigid-body mode, not into the mass line starting at ``lo``; at least
    :data:`MIN_STIFFNESS_LINES` lines, into the mass line if need be (rigid-body modes read
    under the first lines: the fit's own modes then move both bands, see
    :func:`processing.stages.mass_line_among_modes`)."""
    s_hi = min(1.5 * f_rig, lo)
    s_lo = float(freq[freq > 0][0]) if stiffness_low is None else float(stiffness_low)
    if s_hi <= s_lo:  # the rigid-body modes lie under the first line given: up to the mass line
        above = freq[freq > s_lo]
        s_hi = max(lo, float(above[0])) if above.size else lo
    held = freq[freq >= s_lo]
    if np.count_nonzero(held <= s_hi) < 2 and held.size:
        s_hi = max(s_hi, float(held[min(MIN_STIFFNESS_LINES, held.size) - 1]))
    return s_lo, s_hi
