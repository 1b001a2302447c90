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
from numpy.typing import NDArray

from processing.decay import CARRY_MIN, CARRY_STRETCH, free_decay, noise_sigma

__all__ = ["ShakerSignal", "burst_onsets", "burst_random", "burst_records", "burst_ringing",
           "continuous_random", "periodic_chirp", "periodic_random", "settled_records",
           "shaker_signal", "steady_periods"]


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
    import scipy.signal  # the generators' filters: 40 MB that reading records never needs

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


def periodic_random(
    n: int,
    fs: float,
    *,
    rms: float = 1.0,
    band: tuple[float, float] | None = None,
    seed: int | None = None,
) -> NDArray[np.float64]:
    """Gaussian random noise (n,) that repeats every ``n`` samples: a buffer played over and
    over (a generator's regenerated output) joins itself without a step.

    White noise with its discrete Fourier coefficients outside ``band`` (Hz; default up to
    ``fs / 2``) set to zero, scaled to ``rms``: flat over the band, zero outside it, no
    filter transient. The lines are ``fs / n`` Hz apart.

    >>> x = periodic_random(1000, 1000.0, band=(10.0, 100.0), seed=1)
    >>> round(float(np.sqrt(np.mean(x**2))), 12)
    1.0
    """
    _check(fs, band)
    spec = np.fft.rfft(np.random.default_rng(seed).standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / fs)
    lo, hi = (0.0, fs / 2) if band is None else band
    spec[(f < lo) | (f > hi)] = 0.0
    x = np.fft.irfft(spec, n)
    power = float(np.mean(x**2))
    if power == 0.0:
        raise ValueError(f"band {band} holds no frequency line at {fs / n:g} Hz spacing")
    return rms * x / np.sqrt(power)


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
    import scipy.signal

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
#: the loud blocks of a burst train repeat: their autocorrelation reaches this at the period
BURST_CORRELATION = 0.5


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


def _rises(x: NDArray[np.float64], fs: float) -> tuple[int, NDArray[np.bool_],
                                                    NDArray[np.int64]]:
    """Block length, loud blocks (:func:`_blocks`) and the first block of each loud stretch
    that follows a quiet one (block 0 when the recording starts loud)."""
    b, loud = _blocks(x, fs)
    rise = np.flatnonzero(loud[1:] & ~loud[:-1]) + 1
    if loud.size and loud[0]:
        rise = np.r_[0, rise]
    return b, loud, np.asarray(rise, dtype=np.int64)


def _longest_run(mask: NDArray[np.bool_]) -> tuple[int, int] | None:
    """First index and end (exclusive) of the longest run of True in ``mask`` (the first
    such run on a tie); None when there is none."""
    edges = np.diff(np.r_[0, mask.astype(int), 0])
    on, off = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if on.size == 0:
        return None
    k = int(np.argmax(off - on))
    return int(on[k]), int(off[k])


def _burst_period(loud: NDArray[np.bool_]) -> int | None:
    """Blocks from one burst to the next: the shortest lag within 20 % of the highest peak
    of the loud blocks' autocorrelation (about their mean, unbiased), from 2 blocks to a
    third of the recording (three bursts at least); None when it shows no repetition (a
    peak under :data:`BURST_CORRELATION`)."""
    m = loud.astype(float) - loud.mean()
    n = m.size
    hi = n // 3
    if hi < 4 or not np.any(m):
        return None
    r = np.fft.irfft(np.abs(np.fft.rfft(m, 2 * n)) ** 2, 2 * n)[:hi] / (n - np.arange(hi))
    rho = r / r[0]
    peak = np.flatnonzero((rho[2:-1] >= rho[1:-2]) & (rho[2:-1] >= rho[3:])) + 2
    if peak.size == 0 or rho[peak].max() < BURST_CORRELATION:
        return None
    # every multiple of the period peaks as high, give or take the estimate's scatter
    return int(peak[rho[peak] >= 0.8 * rho[peak].max()][0])


def _burst_train(b: int, loud: NDArray[np.bool_], rise: NDArray[np.int64], n: int
                 ) -> tuple[NDArray[np.int64], int, int] | None:
    """The bursts' onsets (samples) on one regular grid, how many loud stretches start on
    it and how many grid points lie within the recording; None when the loud blocks do not
    repeat (:func:`_burst_period`) or fewer than three stretches start on any grid.

    The bursts' phase is the start of the longest run of phases loud in most periods (the
    loud blocks folded on the period); the grid is fitted by least squares to the stretch
    starts within twice :data:`BURST_REGULARITY` of the period from that phase (the period
    need not be a whole number of blocks); a burst whose start the ringing before it hides
    is still on it. ``b``, ``loud``, ``rise``: :func:`_rises` of a recording of ``n``
    samples."""
    period = _burst_period(loud)
    if period is None or rise.size < 3:
        return None
    # the bursts' phase: the longest run of phases loud in most periods (the ringing after
    # a burst is loud in some periods, at some phases)
    n_per = loud.size // period
    folded = loud[:n_per * period].reshape(n_per, period).mean(axis=0) > 0.5
    if folded.all() or not folded.any():
        return None
    off = int(np.argmin(folded))  # a quiet phase: no run wraps past it
    run = _longest_run(np.roll(folded, -off))
    assert run is not None  # folded has a loud phase
    phase = (run[0] + off) % period
    r = rise * b
    P0 = float(period * b)
    u = (r - phase * b) / P0
    on_grid = np.abs(u - np.round(u)) <= 2 * BURST_REGULARITY
    if on_grid.sum() < 3:
        return None
    k = np.round(u[on_grid])
    period_s, first = np.polyfit(k, r[on_grid], 1)
    # two blocks earlier still: the anti-alias filter rings before a burst's sharp start
    first -= 2 * b + np.floor((first - 2 * b) / period_s) * period_s
    onsets = np.round(first + period_s * np.arange(int((n - first) // period_s) + 1))
    # (a burst starting with the recording has no onset in it: its record is not cut)
    onsets = onsets[(onsets >= 0) & (onsets < n)].astype(np.int64)
    # a burst is loud soon after its onset (none after the recording's last one)
    span = int(np.ceil(2 * BURST_REGULARITY * period_s / b)) + 3
    blk = onsets // b
    onsets = onsets[[bool(loud[i:i + span].any()) for i in blk.tolist()]]
    return onsets, int(on_grid.sum()), int(onsets.size)


def burst_onsets(force: NDArray[np.float64], fs: float) -> NDArray[np.int64]:
    """First sample of each burst of a burst-random force (N), in order.

    A burst starts a loud stretch (10 ms blocks) that follows a quiet one. The structure's
    ringing after a burst, felt through the shaker's armature at a lightly damped
    resonance, can rise above the quiet level for a while too, and hide the quiet before
    the next burst: the onsets are the regular grid through most stretch starts
    (:func:`_burst_train`), or every stretch start when the loud blocks do not repeat.

    >>> x = np.zeros(4096)
    >>> for k in range(8):
    ...     x[k * 512 + 100: k * 512 + 400] = np.random.default_rng(k).normal(size=300)
    >>> burst_onsets(x, 256.0)[:3]
    array([  84,  596, 1108])
    """
    x = np.asarray(force, dtype=float).ravel()
    b, loud, rise = _rises(x - np.median(x), fs)
    train = _burst_train(b, loud, rise, x.size)
    return np.asarray(rise * b, dtype=np.int64) if train is None else train[0]


def shaker_signal(force: NDArray[np.float64], fs: float) -> ShakerSignal:
    """Periodic, burst or continuous, from a recorded shaker force (N) at ``fs`` Hz.

    Periodic: the autocorrelation (about the median, unbiased, normalised) reaches
    :data:`PERIODIC_CORRELATION` at some lag from :data:`MIN_PERIOD` s to half the
    recording; the period is the shortest lag within 2 % of the highest peak. Burst: quiet
    stretches, and at least three loud stretches, most of the bursts, starting on one
    regular grid within :data:`BURST_REGULARITY` (:func:`burst_onsets`); the period is the
    grid's spacing (samples, rounded down). Anything else is continuous.

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
    b, loud, rise = _rises(x, fs)
    duty = float(np.mean(loud)) if loud.size else 1.0
    if best >= PERIODIC_CORRELATION:
        peak = (rho[1:-1] >= rho[:-2]) & (rho[1:-1] >= rho[2:]) & (rho[1:-1] >= 0.98 * best)
        k = int(np.flatnonzero(peak)[0]) + 1 if peak.any() else int(np.argmax(rho))
        return ShakerSignal("periodic", lo + k, float(rho[k]), duty)
    train = _burst_train(b, loud, rise, n) if duty < 0.95 else None
    if train is not None and 2 * train[1] >= train[2]:  # most bursts start on the grid
        return ShakerSignal("burst", int(np.diff(train[0]).min()), best, duty)
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


# ---- burst records: the structure still ringing when the record ends ----

#: the free decay after a burst is fitted from this long after its last loud block, s
BURST_GUARD = 0.05
#: the ringing at a record's end is read over its last this many seconds
RING_SPAN = 0.05


def _quiet_from(force: NDArray[np.float64], fs: float, starts: NDArray[np.int64],
                length: int) -> NDArray[np.int64]:
    """Per record, the first sample (from its start) after its burst: the end of its longest
    loud stretch (:func:`_blocks`; the ringing after a burst can be loud for a while too,
    never as long) plus :data:`BURST_GUARD`; ``length`` when the burst fills the record."""
    x = np.asarray(force, dtype=float).ravel()
    b, loud = _blocks(x - np.median(x), fs)
    guard = round(BURST_GUARD * fs)
    out = np.full(starts.size, length, dtype=np.int64)
    for k, s in enumerate(starts.tolist()):  # a few dozen records
        run = _longest_run(loud[s // b: (s + length) // b])
        if run is not None:
            out[k] = min(length, (s // b + run[1]) * b - s + guard)
    return out


def burst_ringing(data: NDArray[np.float64], fs: float, starts: NDArray[np.int64],
                  length: int, force_rows: int = 1) -> float:
    """How much the responses still ring when a burst record ends: per record, the largest
    over the response channels of the RMS of its last :data:`RING_SPAN` s (mean removed)
    over the channel's noise (:func:`processing.decay.noise_sigma` on the quiet stretches
    after the bursts); the median over the records. ``data`` (n_ch, n): the forces (the
    first ``force_rows`` rows, N) then the responses; ``starts`` the records' first samples.

    >>> fs, t = 256.0, np.arange(4096) / 256.0
    >>> drive = np.random.default_rng(1).normal(size=t.size) * (t % 4 < 2)
    >>> ring = np.convolve(drive, np.exp(-t / 2) * np.sin(2 * np.pi * 5 * t))
    >>> y = np.vstack([drive, ring[:t.size]]) + 1e-3 * np.random.default_rng(2).normal(
    ...     size=(2, t.size))
    >>> bool(burst_ringing(y, fs, np.array([0, 1024, 2048]), 1024) > 10)
    True
    """
    rec, _, sigma = _records(data, fs, starts, length, force_rows)
    n = max(2, round(RING_SPAN * fs))
    tail = rec[:, force_rows:, -n:]
    rms = np.std(tail, axis=-1) / np.maximum(sigma[force_rows:], 1e-300)
    return float(np.median(np.max(rms, axis=-1))) if rms.size else 0.0


def _records(data: NDArray[np.float64], fs: float, starts: NDArray[np.int64], length: int,
             force_rows: int) -> tuple[NDArray[np.float64], NDArray[np.int64],
                                       NDArray[np.float64]]:
    """The records (n_rec, n_ch, length), where each one's burst ends
    (:func:`_quiet_from`) and each channel's noise read on those quiet stretches."""
    x = np.asarray(data, dtype=float)
    rec = x[:, starts[:, None] + np.arange(length)].transpose(1, 0, 2)
    quiet = _quiet_from(np.sum(x[:force_rows], axis=0), fs, starts, length)
    still = [rec[k, :, q:] for k, q in enumerate(quiet.tolist()) if length - q >= 4]
    sigma = (noise_sigma(np.concatenate(still, axis=-1)) if still
             else noise_sigma(x))
    return rec, quiet, sigma


def burst_records(data: NDArray[np.float64], fs: float, starts: NDArray[np.int64],
                  length: int, force_rows: int = 1, complete: bool = True,
                  ) -> NDArray[np.float64]:
    """Burst records (n_rec, n_ch, length) from ``starts``; with ``complete``, each one as if
    the structure had been at rest when it began and the record had been long enough for it
    to come to rest again, i.e. leakage-free under the rectangular window.

    A burst record holds the end of the earlier bursts' ringing and cuts off the end of its
    own: both are free decays of the structure (forces, through the shaker's armature,
    included), fitted as damped sinusoids (:func:`processing.decay.free_decay`). The first
    is fitted on the quiet stretch before the record (after the previous burst, at most
    :data:`processing.decay.CARRY_STRETCH` s) and its continuation subtracted; the second on
    the record's own quiet stretch after its burst, continued past the record's end and
    folded onto the record (the record then holds the periodic response to its burst, whose
    spectrum is the FRF times the force's at every line). A stretch under
    :data:`processing.decay.CARRY_MIN` s leaves that side as it is.

    Parameters
    ----------
    data : (n_ch, n)
        The forces (the first ``force_rows`` rows, N) then the responses, one recording.
    fs : float
        Sample rate, Hz.
    starts : (n_rec,) int
        First sample of each record (each burst's onset, :func:`burst_onsets`); each record
        must lie within ``data``.
    length : int
        Samples a record.
    """
    x = np.asarray(data, dtype=float)
    rec, quiet, sigma = _records(x, fs, starts, length, force_rows)
    if not complete:
        return rec
    rec = rec.copy()
    shortest, longest = round(CARRY_MIN * fs), round(CARRY_STRETCH * fs)
    ends = np.r_[0, starts[:-1] + quiet[:-1]] if starts.size else starts
    for k, s in enumerate(starts.tolist()):  # a few dozen records, two fits each
        a = max(int(ends[k]), s - longest)
        if s - a >= shortest:  # the earlier bursts' ringing
            rec[k] -= free_decay(x[:, a:s], length, sigma)
        q = int(quiet[k])
        if length - q >= shortest:  # its own tail, past the record's end
            rec[k] += free_decay(rec[k, :, max(q, length - longest):], length, sigma, fold=True)
    return rec

