"""The hammer's usable band (:func:`processing.impact.force_band_top`) against the half-sine
pulse's own spectrum, ``|F(f)| ~ |cos(pi f tau) / (1 - (2 f tau)^2)|`` (first zero at
``1.5 / tau``), and its use in the identification."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize

from processing.impact import force_band_top


def _half_sine_power(fs: float, width: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / fs
    pulse = np.where(t < width, np.sin(np.pi * t / width), 0.0)
    return np.fft.rfftfreq(n, 1 / fs), np.abs(np.fft.rfft(pulse)) ** 2


def _analytic_20db(width: float) -> float:
    """Where the continuous half-sine's power falls to 1 % of its value at 0 Hz."""
    def amp(f: float) -> float:
        x = f * width
        return float(np.cos(np.pi * x) / (1 - (2 * x) ** 2))  # 1 at 0 Hz
    return float(scipy.optimize.brentq(lambda f: amp(f) ** 2 - 0.01, 0.6 / width,
                                       1.45 / width))


@pytest.mark.parametrize("width", [0.004, 0.008, 0.016])
def test_top_where_the_half_sine_falls_20_db(width: float) -> None:
    fs, n = 8192.0, 16384  # 0.5 Hz lines
    freq, S = _half_sine_power(fs, width, n)
    band = freq <= 2.0 / width  # past the -20 dB point and the first zero
    top = force_band_top(freq[band], S[band])
    assert top is not None
    assert top == pytest.approx(_analytic_20db(width), abs=1.0)  # 0.5 Hz lines


def test_no_top_when_the_force_holds_up_and_the_least_column_counts() -> None:
    fs, n, band_top = 16384.0, 16384, 400.0  # 1 Hz lines
    freq, hard = _half_sine_power(fs, 1 / band_top, n)  # -9.5 dB at the band's top
    band = freq <= band_top
    assert force_band_top(freq[band], hard[band]) is None
    _, soft = _half_sine_power(fs, 2 / band_top, n)  # its first zero at 300 Hz
    top = force_band_top(freq[band], np.stack([hard[band], soft[band]]))
    assert top == pytest.approx(_analytic_20db(2 / band_top), abs=1.5)
