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
"""

from __future__ import annotations

import numpy as np
import scipy.signal
from numpy.typing import NDArray

__all__ = ["burst_random", "continuous_random", "periodic_chirp"]


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
