"""Shaker excitation signals: continuous random, burst random and periodic chirp.

Every generator is deterministic for a given ``seed`` and returns float64 samples
(time last), in the unit of ``rms`` / ``amplitude`` (usually the drive voltage
or the force, N).

How each is analysed (see ``docs/processing.md``):

- continuous random: Welch averaging with a Hann window and overlap
  (:class:`processing.spectral.SpectralAccumulator` defaults);
- burst random: records of ``record_length`` samples, each a burst followed by
  silence long enough for the response to die out, analysed with a rectangular
  window, no overlap and no detrend: no leakage;
- periodic chirp: a sweep repeated every ``period`` samples; after the first
  period(s) the response is periodic too, and each period analysed with a
  rectangular window is leakage-free.

:func:`shaker_signal` tells them apart on a recorded force, and :func:`burst_onsets`,
:func:`steady_periods` place the records of the last two; :func:`settled_records` finds the
burst records at the start that still hold the sensors' settling.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.signal
from numpy.typing import NDArray

__all__ = ["ShakerSignal", "burst_onsets", "burst_random", "continuous_random", "periodic_chirp",
           "settled_records", "shaker_signal", "steady_periods"]


def _check(fs: float, band: tuple[float, float] | None) -> None:
    if not np.isfinite(fs) or fs <= 0:
        raise ValueError(f"sample rate must be positive, got {fs}")
    if band is not None and not 0 <= band[0] < band[1] <= fs / 2:
        raise ValueError(f"band must satisfy 0 <= low < high <= fs/2 = {fs / 2}, got {band}")


def _white(
    rng: np.random.Generator, shape: tuple[int, ...], fs: float, band: tuple[float, float] | None
) -> NDArray[np.float64]:
    x = rng.standard_normal(shape)
    if band is None or (band[0] == 0 and band[1] >= fs / 2):
        return x
    lo, hi = band
    if lo == 0:
        sos = scipy.signal.butter(8, hi, "lowpass", fs=fs, output="sos")
    elif hi >= fs / 2:
        sos = scipy.signal.butter(8, lo, "highpass", fs=fs, output="sos")
    else:
        sos = scipy.signal.butter(8, (lo, hi), "bandpass", fs=fs, output="sos")
    return np.asarray(scipy.signal.sosfilt(sos, x, axis=-1))


def continuous_random(
    n: int,
    fs: float,
    *,
    rms: float = 1.0,
    band: tuple[float, float] | None = None,
    n_channels: int = 1,
    seed: int | None = None,
) -> NDArray[np.float64]:
    """Gaussian random noise (n_channels, n), independent between channels.

    Parameters
    ----------
    n : int
        Samples per channel.
    fs : float
        Sample rate, Hz.
    rms : float
        RMS value of each channel.
    band : (low, high) Hz, optional
        Eighth-order Butterworth band limit (white up to fs/2 by default).
    n_channels : int
        Independent signals, e.g. one per shaker.
    seed : int, optional
    """
    _check(fs, band)
    x = _white(np.random.default_rng(seed), (n_channels, n), fs, band)
    return rms * x / np.sqrt(np.mean(x**2, axis=-1, keepdims=True))


def burst_random(
    n_bursts: int,
    record_length: int,
    fs: float,
    *,
    burst_fraction: float = 0.5,
    rms: float = 1.0,
    band: tuple[float, float] | None = None,
    n_channels: int = 1,
    seed: int | None = None,
) -> NDArray[np.float64]:
    """Burst random (n_channels, n_bursts * record_length): noise on the first part of each record.

    Each burst covers ``burst_fraction`` of its record (tapered over 1 % of the
    record at both ends), then the drive is silent; ``rms`` is the RMS within the bursts.
    """
    _check(fs, band)
    if not 0 < burst_fraction <= 1:
        raise ValueError(f"burst_fraction must be in (0, 1], got {burst_fraction}")
    n_on = max(round(burst_fraction * record_length), 2)
    x = _white(np.random.default_rng(seed), (n_channels, n_bursts, n_on), fs, band)
    x *= rms / np.sqrt(np.mean(x**2, axis=-1, keepdims=True))
    x *= scipy.signal.windows.tukey(n_on, min(1.0, 2 * 0.01 * record_length / n_on))
    out = np.zeros((n_channels, n_bursts, record_length))
    out[..., :n_on] = x
    return out.reshape(n_channels, n_bursts * record_length)


def periodic_chirp(
    n_periods: int,
    period: int,
    fs: float,
    *,
    band: tuple[float, float] | None = None,
    amplitude: float = 1.0,
) -> NDArray[np.float64]:
    """A linear sweep over ``band`` (Hz) in each period of ``period`` samples, repeated.

    The start and end frequencies are rounded to lines of ``fs / period`` Hz with an
    even sum of line numbers, so the phase closes on itself and the signal is
    exactly periodic. Returns (n_periods * period,).
    """
    _check(fs, band)
    df = fs / period
    lo, hi = (df, fs / 2 - df) if band is None else band
    k0 = max(int(np.floor(lo / df)), 0)
    k1 = min(int(np.ceil(hi / df)), period // 2)
    if (k0 + k1) % 2:
        k1 = k1 - 1 if k1 > k0 + 1 else k1 + 1
    if k1 <= k0:
        raise ValueError(f"band {band} holds no frequency line at {df:g} Hz spacing")
    t = np.arange(period) / fs
    T = period / fs
    f0, f1 = k0 * df, k1 * df
    one = amplitude * np.sin(2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * T)))
    return np.tile(one, n_periods)


# ---- what a recorded shaker force is ----

#: a force whose autocorrelation (normalised, unbiased) reaches this at a lag of at least
#: :data:`MIN_PERIOD` s and at most half the recording is periodic
PERIODIC_CORRELATION = 0.9
#: shortest period looked for, s
MIN_PERIOD = 0.05
#: a block whose RMS is under this fraction of the loud blocks' (90th percentile) is quiet
QUIET_FRACTION = 0.1
#: burst onsets this close to their median spacing (relative) make a regular burst train
BURST_REGULARITY = 0.05


@dataclass(frozen=True)
class ShakerSignal:
    """What a shaker's force looks like (:func:`shaker_signal`).

    Attributes
    ----------
    kind : 'periodic' (repeats every ``period`` samples), 'burst' (bursts starting every
        ``period`` samples, quiet in between) or 'continuous'
    period : samples (None for continuous)
    correlation : the force's normalised autocorrelation at ``period`` (periodic), else its
        largest value over the lags looked at
    duty : fraction of the recording where the force is on (1 for a continuous drive)
    """

    kind: Literal["periodic", "burst", "continuous"]
    period: int | None
    correlation: float
    duty: float


def _blocks(x: NDArray[np.float64], fs: float) -> tuple[int, NDArray[np.bool_]]:
    """Block length (samples, about 10 ms) and which blocks are loud (RMS above
    :data:`QUIET_FRACTION` of the 90th percentile), with dips of one or two blocks filled."""
    b = max(4, round(0.01 * fs))
    nb = x.size // b
    rms = np.sqrt(np.mean(x[: nb * b].reshape(nb, b) ** 2, axis=1))
    loud = rms > QUIET_FRACTION * np.percentile(rms, 90)
    pad = np.pad(loud, 2)  # a centred maximum over five blocks: random dips filled
    filled = np.any(np.lib.stride_tricks.sliding_window_view(pad, 5), axis=1)
    return b, np.asarray(filled)


def burst_onsets(force: NDArray[np.float64], fs: float) -> NDArray[np.int64]:
    """First sample of each burst of a burst-random force (N), in order: the start of each
    loud stretch (10 ms blocks) that follows a quiet one."""
    x = np.asarray(force, dtype=float).ravel()
    b, loud = _blocks(x - np.median(x), fs)
    rise = np.flatnonzero(loud[1:] & ~loud[:-1]) + 1
    if loud.size and loud[0]:
        rise = np.r_[0, rise]
    return np.asarray(rise * b, dtype=np.int64)


def shaker_signal(force: NDArray[np.float64], fs: float) -> ShakerSignal:
    """Periodic, burst or continuous, from a recorded shaker force (N) at ``fs`` Hz.

    Periodic: the autocorrelation (about the median, unbiased, normalised) reaches
    :data:`PERIODIC_CORRELATION` at some lag from :data:`MIN_PERIOD` s to half the
    recording; the period is the shortest lag within 2 % of the highest peak. Burst: quiet
    stretches (:func:`burst_onsets`), at least three bursts whose onsets are evenly spaced
    within :data:`BURST_REGULARITY`; the period is the shortest spacing. Anything else is
    continuous.

    >>> fs = 256.0
    >>> t = np.arange(8192) / fs
    >>> shaker_signal(np.sin(2 * np.pi * (t % 2) ** 2 * 20), fs).kind
    'periodic'
    >>> shaker_signal(np.random.default_rng(0).normal(size=8192), fs).kind
    'continuous'
    """
    x = np.asarray(force, dtype=float).ravel()
    x = x - np.median(x)
    n = x.size
    X = np.fft.rfft(x, 2 * n)
    r = np.fft.irfft(np.abs(X) ** 2, 2 * n)[:n] / (n - np.arange(n))
    lo, hi = max(1, round(MIN_PERIOD * fs)), n // 2
    if not r[0] > 0 or hi <= lo + 2:
        return ShakerSignal("continuous", None, 0.0, 1.0)
    rho = r[lo:hi] / r[0]
    best = float(rho.max())
    b, loud = _blocks(x, fs)
    duty = float(np.mean(loud)) if loud.size else 1.0
    if best >= PERIODIC_CORRELATION:
        peak = (rho[1:-1] >= rho[:-2]) & (rho[1:-1] >= rho[2:]) & (rho[1:-1] >= 0.98 * best)
        k = int(np.flatnonzero(peak)[0]) + 1 if peak.any() else int(np.argmax(rho))
        return ShakerSignal("periodic", lo + k, float(rho[k]), duty)
    on = burst_onsets(x, fs)
    if on.size >= 3 and duty < 0.95:
        gaps = np.diff(on)
        med = float(np.median(gaps))
        if np.all(np.abs(gaps - med) <= BURST_REGULARITY * med + b):
            return ShakerSignal("burst", int(gaps.min()), best, duty)
    return ShakerSignal("continuous", None, best, duty)


def steady_periods(responses: NDArray[np.float64], period: int) -> int:
    """Periods to skip at the start of a periodic test before the responses repeat: the
    first period ``k`` (at least 1: the start from rest) whose difference from the next,
    relative to it (RMS, worst channel), is within twice the median of the later half's."""
    y = np.atleast_2d(np.asarray(responses, dtype=float))
    m = y.shape[1] // period
    if m < 3:
        return min(1, max(m - 1, 0))
    p = y[:, : m * period].reshape(y.shape[0], m, period)
    d = np.sqrt(np.mean(np.diff(p, axis=1) ** 2, axis=-1))
    d = np.max(d / np.maximum(np.sqrt(np.mean(p[:, 1:] ** 2, axis=-1)), 1e-300), axis=0)
    floor = float(np.median(d[d.size // 2:]))
    steady = np.flatnonzero(d <= 2 * floor)
    return int(max(1, steady[0] if steady.size else 1))


#: a record's mean deviating from the others' by more than this many times their typical
#: deviation holds a transient (the sensors settling)
SETTLING_FACTOR = 3.0


def settled_records(records: NDArray[np.float64]) -> int:
    """Records to skip at the start of a burst test while the responses settle (an IEPE
    sensor's decaying offset after power-up, a slow transient): zero-mean in steady state
    (the body is at rest at each record's ends, so its mean acceleration is nil), a record's
    mean is off when it holds such a transient.

    ``records`` (n_rec, n_ch, n): the response channels of each record, in time order. Each
    record's mean, per channel, less the median over the records, relative to the channel's
    median record RMS; worst channel. The answer is the first record whose deviation is
    within :data:`SETTLING_FACTOR` times the median of the later half's, at most half of the
    records (0 under three records).
    """
    rec = np.asarray(records, dtype=float)
    n_rec = rec.shape[0]
    if rec.ndim != 3 or n_rec < 3:
        return 0
    mean = np.mean(rec, axis=-1)  # (n_rec, n_ch)
    rms = np.median(np.sqrt(np.mean(rec**2, axis=-1)), axis=0)  # (n_ch,)
    d = np.max(np.abs(mean - np.median(mean, axis=0)) / np.maximum(rms, 1e-300), axis=1)
    floor = float(np.median(d[n_rec // 2:]))
    steady = np.flatnonzero(d <= SETTLING_FACTOR * floor)
    return int(min(steady[0] if steady.size else 0, n_rec // 2))
