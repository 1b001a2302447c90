"""``drivers.sync.signal_delay``: sub-sample delay between two recordings of one hit."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.errors import SyncError
from drivers.sync import signal_delay

FS = 1024.0


def _pulse(delay: float, n: int = 1536, fs: float = FS) -> np.ndarray:
    """A 4 ms half-sine hit at 0.1 s + delay, each sample its mean over the sample interval."""
    t = np.arange(n) / fs
    dur = 0.004

    def integral(x: np.ndarray) -> np.ndarray:
        u = np.clip((x - 0.1 - delay) / dur, 0, 1)
        return dur / np.pi * (1 - np.cos(np.pi * u))

    return 200.0 * (integral(t + 0.5 / fs) - integral(t - 0.5 / fs)) * fs


@pytest.mark.parametrize("delay", [0.0, 0.37e-3, -1.23e-3, 2.9e-3, 11.05e-3])
def test_band_limited_delays_are_exact(delay: float) -> None:
    t = np.arange(1024) / FS
    a = np.exp(-(((t - 0.3) / 0.004) ** 2))  # 4 ms Gaussian: nothing above Nyquist
    b = 0.7 * np.exp(-(((t - 0.3 - delay) / 0.004) ** 2))
    d, corr = signal_delay(a, b, FS)
    assert d == pytest.approx(delay, abs=1e-5 / FS)
    assert corr > 0.9


@pytest.mark.parametrize("delay", [0.0, 0.37e-3, -1.23e-3, 2.9e-3, 11.05e-3])
def test_sampled_hits_to_a_hundredth_of_a_sample(delay: float) -> None:
    # a 4 ms hit sampled at 1024 Hz (4 samples) aliases: the shifted samples are not an
    # exact shift of the others, which bounds the accuracy (measured: 0.009 sample at most)
    d, corr = signal_delay(_pulse(0.0), _pulse(delay), FS)
    assert d == pytest.approx(delay, abs=0.02 / FS)
    assert corr > 0.5


def test_noise_and_gain_leave_the_delay() -> None:
    rng = np.random.default_rng(3)
    a = _pulse(0.0) + 0.2 * rng.standard_normal(1536)  # 0.1 % of the peak
    b = 0.8 * _pulse(0.6e-3) + 0.2 * rng.standard_normal(1536)
    d, corr = signal_delay(a, b, FS)
    assert d == pytest.approx(0.6e-3, abs=0.01 / FS) and corr > 0.95


def test_unusable_records_raise() -> None:
    with pytest.raises(SyncError, match="all zero"):
        signal_delay(np.zeros(64), _pulse(0.0, 64), FS)
    bad = _pulse(0.0)
    bad[5] = np.nan
    with pytest.raises(SyncError, match="lost"):
        signal_delay(bad, _pulse(0.0), FS)
    with pytest.raises(SyncError, match="one length"):
        signal_delay(np.ones(10), np.ones(12), FS)
