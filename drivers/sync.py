"""Aligning streams from devices on separate clocks.

Each streaming driver records, per frame, when it arrived on the host clock
(``time.monotonic()``) and how many samples it had by then. A frame cannot
arrive before its last sample was taken, so the lower envelope of these pairs
is the device clock plus the smallest transport latency. :func:`fit_clock`
fits that envelope (a linear programme, so late frames do not pull it): the
device's true rate (its drift against the host, ppm) and the host time of its
sample 0 (its start offset).

:func:`align` then resamples a stream onto the sample instants of a reference
stream (anti-aliased rate change, then cubic interpolation at the drifted
positions), so spectra are taken on one time base. :func:`check_alignment`
refuses a run whose streams cannot be aligned: too few timing pairs, a clock
fit too noisy to trust, a drift beyond the limit, lost samples, or streams that
do not overlap. Offsets measured this way are as good as the host's timing of
frame arrivals (about a millisecond over a pseudo-terminal or a USB adapter);
phase-accurate work needs a shared trigger or a reference signal recorded by
both devices. :func:`signal_delay` measures the delay between two recordings of
one signal (the hammer's force seen by its own digitiser and by a front-end
input) to a small fraction of a sample: cross-correlation peak, parabolic
interpolation, then the slope of the cross-spectrum's phase; :func:`align`
with the clock's ``t0`` corrected by it puts the stream on the reference's
instants to that accuracy.

Example
-------
>>> fit = fit_clock([(10.0 + k / 1000, k) for k in range(1, 2000, 50)], nominal_fs=1000)
>>> print(f"{abs(fit.ppm):.3f} ppm, sample 0 at {fit.t0 - 10.0:.6f} s")
0.000 ppm, sample 0 at 0.001000 s
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from fractions import Fraction

import numpy as np
import scipy.fft

from drivers.base import TIMING_SCATTER, TimeBlock
from drivers.errors import SyncError

__all__ = ["ClockFit", "align", "check_alignment", "fit_clock", "signal_delay"]


@dataclass(frozen=True)
class ClockFit:
    """A device clock on the host time base.

    Attributes
    ----------
    rate : float
        Measured samples per host second, Hz.
    t0 : float
        Host time of sample 0, s (plus the smallest transport latency).
    nominal : float
        The rate the device was set to, Hz.
    residual : float
        Lateness of the promptest frames after the fitted line, s (see
        :func:`fit_clock`).
    n_pairs : int
        Timing pairs used.
    span : float
        Host time covered by the pairs, s.
    """

    rate: float
    t0: float
    nominal: float
    residual: float
    n_pairs: int
    span: float

    @property
    def ppm(self) -> float:
        """Clock error against the host, parts per million (positive: device fast)."""
        return (self.rate / self.nominal - 1.0) * 1e6

    def host_time(self, index: np.ndarray | float) -> np.ndarray:
        """Host times of device samples ``index``."""
        return self.t0 + np.asarray(index, dtype=float) / self.rate


def fit_clock(pairs: Sequence[tuple[float, int]], nominal_fs: float,
              windows: int = 16, quantile: float = 0.75) -> ClockFit:
    """Fit a device clock to ``(host arrival time, samples received)`` pairs.

    The clock is the lower envelope of the pairs: the line below every pair
    with the least total lateness above it, a linear programme (the clock-skew
    estimator of Moon, Skelly and Towsley, 1999). A late frame only raises its
    pair above the line, so host load, a stall or a burst of queued frames
    leaves the line where it is as long as some frames in the run arrive
    promptly (a least-squares line is pulled up by them).

    ``residual`` is how late the promptest frame of each of ``windows`` equal
    stretches of the run arrives after the line, at the ``quantile`` over the
    stretches: near the host's timing resolution for a steady clock, large when
    the device's timing bends (samples lost unmarked, a rate that wanders),
    whatever the host did in a few stretches. Raises :class:`SyncError` with
    fewer than 10 pairs or pairs that cover no samples.
    """
    if len(pairs) < 10:
        raise SyncError(f"only {len(pairs)} timing pairs: stream too short to measure its clock")
    p = np.asarray(pairs, dtype=float)
    t, k = p[:, 0], p[:, 1] - 1.0  # host time, index of the frame's last sample
    if not (np.all(np.isfinite(p)) and np.ptp(k) > 0):
        raise SyncError(f"{len(pairs)} timing pairs cover no samples or are not finite: "
                        "cannot measure the clock; check the device's stream and restart it")
    # scaled for the solver: lateness about a first line in ms, samples in [-1, 1]
    slope0, icpt0 = np.polyfit(k, t, 1)
    kc, ks = 0.5 * (k.max() + k.min()), 0.5 * np.ptp(k)
    u, y = (k - kc) / ks, (t - icpt0 - slope0 * k) * 1e3
    # the height a + b u at the pairs' mean u, as high as every pair allows
    import scipy.optimize  # 0.1 s: loaded when a clock is fitted, not by every process

    lp = scipy.optimize.linprog(c=[-1.0, -u.mean()], A_ub=np.column_stack([np.ones_like(u), u]),
                                b_ub=y, bounds=[(None, None), (None, None)], method="highs")
    if lp.status != 0:
        raise SyncError(f"clock fit failed ({lp.message}): timing pairs unusable; check the "
                        "device's stream and restart it")
    a, b = lp.x
    slope = slope0 + b * 1e-3 / ks
    icpt = icpt0 + (a - b * kc / ks) * 1e-3
    late = t - (icpt + slope * k)
    edges = np.linspace(k.min(), k.max(), windows + 1)
    stretch = np.clip(np.searchsorted(edges, k, side="right") - 1, 0, windows - 1)
    prompt = np.full(windows, np.inf)
    np.minimum.at(prompt, stretch, late)
    return ClockFit(rate=1.0 / slope, t0=float(icpt), nominal=float(nominal_fs),
                    residual=float(np.quantile(prompt[np.isfinite(prompt)], quantile)),
                    n_pairs=len(pairs), span=float(t[-1] - t[0]))


def check_alignment(fits: Mapping[str, ClockFit], *, max_ppm: float = 10000.0,
                    max_residual: float = TIMING_SCATTER, min_span: float = 0.5) -> None:
    """Refuse (raise :class:`SyncError`) when any stream's clock cannot be trusted."""
    for name, fit in fits.items():
        if fit.span < min_span:
            raise SyncError(f"{name}: clock measured over {fit.span:.2f} s only; "
                            f"need {min_span:g} s", name)
        if fit.residual > max_residual:
            raise SyncError(f"{name}: frame timing scatters by {fit.residual * 1e3:.1f} ms "
                            f"(limit {max_residual * 1e3:.1f} ms): clock not measurable", name)
        if abs(fit.ppm) > max_ppm:
            raise SyncError(f"{name}: clock off by {fit.ppm:.0f} ppm (limit {max_ppm:g}): "
                            "check the device's rate setting", name)


def align(reference: TimeBlock, ref_fit: ClockFit, other: TimeBlock, other_fit: ClockFit,
          name: str = "stream") -> TimeBlock:
    """``other`` resampled onto the sample instants of ``reference``.

    The result has ``reference``'s rate, length and first sample index, and
    ``other``'s channels. Raises :class:`SyncError` if ``other`` has lost
    samples or does not cover ``reference``'s time span.
    """
    if other.missing:
        raise SyncError(f"{name}: {other.missing} samples lost; cannot align", name)
    # 0.4 s and 40 MB to import, paid by every acquiring process that imports this module:
    # loaded when streams are aligned
    import scipy.interpolate
    import scipy.signal

    data = other.data
    ratio = Fraction(reference.fs / other.fs).limit_denominator(1000)  # nominal rates
    if ratio != 1:
        data = scipy.signal.resample_poly(data, ratio.numerator, ratio.denominator, axis=-1)
    step = ratio.denominator / ratio.numerator  # original samples per resampled sample
    t_ref = ref_fit.host_time(reference.first_sample + np.arange(reference.n_samples))
    pos = (t_ref - other_fit.t0) * other_fit.rate - other.first_sample  # other's samples
    u = pos / step
    if u[0] < 0 or u[-1] > data.shape[-1] - 1:
        raise SyncError(
            f"{name}: covers {other.first_sample}..{other.first_sample + other.n_samples} but "
            f"the reference needs {pos[0] + other.first_sample:.0f}.."
            f"{pos[-1] + other.first_sample:.0f}: streams do not overlap", name)
    spline = scipy.interpolate.CubicSpline(np.arange(data.shape[-1]), data, axis=-1)
    return replace(reference, data=spline(u), channels=other.channels, missing=0,
                   overloaded=other.overloaded)


def signal_delay(reference: np.ndarray, other: np.ndarray, fs: float, *,
                 f_max: float | None = None) -> tuple[float, float]:
    """Delay of ``other`` behind ``reference``, two recordings of one signal at ``fs`` Hz.

    ``other(t) ~ g * reference(t - delay)``. The integer lag of the cross-correlation's
    peak is refined by a parabola through the peak and its neighbours, then by the
    weighted least-squares slope of the cross-spectrum's phase (after removing that
    delay) on the lines up to ``f_max`` (default ``fs / 2.56``, below the anti-alias
    filters) where the cross-spectrum exceeds 1e-3 of its peak. Exact for band-limited
    signals with zero-phase filters; a transient (a hit) inside both records is ideal.

    Parameters
    ----------
    reference, other : (n,) arrays
        The two recordings on one sample grid (same length), any unit.
    fs : float
        Sample rate, Hz.
    f_max : float, optional
        Highest frequency used by the phase-slope step, Hz.

    Returns
    -------
    delay : float
        s (positive: ``other`` lags).
    correlation : float
        Normalised correlation at the peak sample (integer lag), in [-1, 1]; near 1
        when both records see one signal.

    Raises
    ------
    SyncError
        If either record is zero or not finite.

    Notes
    -----
    The records are used as they are, without removing their means: a pedestal cut
    off at the record's ends would correlate at lag 0 and bias the delay. Give records
    whose signal starts and ends near zero (a hit with its pretrigger and decay).

    Examples
    --------
    >>> fs = 1000.0
    >>> t = np.arange(512) / fs
    >>> a = np.exp(-(((t - 0.2) / 0.004) ** 2))
    >>> b = np.exp(-(((t - 0.2 - 0.00237) / 0.004) ** 2))
    >>> d, c = signal_delay(a, b, fs)
    >>> print(f"{d * 1e3:.4f} ms, correlation {c:.3f}")
    2.3700 ms, correlation 0.996
    """
    a, b, energy = _delay_records(reference, other)
    n = a.size
    nfft = scipy.fft.next_fast_len(2 * n)
    A, B = scipy.fft.rfft(a, nfft), scipy.fft.rfft(b, nfft)
    S = np.conj(A) * B
    lag, peak = _correlation_peak(S, n, nfft)
    f = scipy.fft.rfftfreq(nfft, 1.0 / fs)
    f_hi = fs / 2.56 if f_max is None else f_max
    return _phase_slope_delay(S, f, lag, fs, f_hi), peak / energy


def _delay_records(reference: np.ndarray, other: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """The two records of :func:`signal_delay` as flat float arrays, and their joint energy.

    Raises :class:`SyncError` if they differ in length, are shorter than 8 samples,
    have lost (NaN) samples or one is all zero.
    """
    a = np.asarray(reference, dtype=float).ravel()
    b = np.asarray(other, dtype=float).ravel()
    if a.shape != b.shape or a.size < 8:
        raise SyncError(f"signal_delay needs two records of one length >= 8, got {a.size} "
                        f"and {b.size} samples")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise SyncError("signal_delay: a record has lost (NaN) samples")
    energy = float(np.sqrt(np.sum(a**2) * np.sum(b**2)))
    if energy == 0:
        raise SyncError("signal_delay: a record is all zero: no common signal to align on")
    return a, b, energy


def _correlation_peak(S: np.ndarray, n: int, nfft: int) -> tuple[float, float]:
    """Lag (samples, parabola-refined) and value of the cross-correlation's peak.

    ``S`` is the cross-spectrum ``conj(A) B`` of two ``n``-sample records zero-padded
    to ``nfft``; the value is taken at the peak's integer lag.
    """
    c = scipy.fft.irfft(S, nfft)  # c[k] = sum a[i] b[i + k]
    c = np.concatenate([c[nfft - n + 1:], c[:n]])  # lags -(n-1) .. n-1
    k = int(np.argmax(c))
    lag = float(k - (n - 1))
    if 0 < k < c.size - 1:
        y0, y1, y2 = c[k - 1], c[k], c[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            lag += 0.5 * float(y0 - y2) / float(den)
    return lag, float(c[k])


def _phase_slope_delay(S: np.ndarray, f: np.ndarray, lag: float, fs: float,
                       f_max: float) -> float:
    """Delay, s: ``lag`` samples refined by the weighted slope of the cross-spectrum's phase.

    Uses the lines ``0 < f <= f_max`` where ``|S|`` exceeds 1e-3 of its peak; without
    any, the delay is ``lag / fs``.
    """
    resid = S * np.exp(2j * np.pi * f * lag / fs)  # phase -2 pi f (delay - lag / fs)
    w = np.abs(resid)
    keep = (f > 0) & (f <= f_max) & (w > 1e-3 * w.max())
    if not np.any(keep):
        return lag / fs
    phi = np.angle(resid[keep])
    wf = w[keep] * f[keep]
    return lag / fs - float(np.sum(wf * phi) / (2 * np.pi * np.sum(wf * f[keep])))
