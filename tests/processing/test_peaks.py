"""Peak finding and running median: the same indices and values as SciPy's functions."""

from __future__ import annotations

import numpy as np
import scipy.ndimage
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from processing.peaks import find_prominent, local_maxima, prominences, running_median

# few distinct levels: plateaus, equal neighbours and equal peaks are common
levels = st.lists(st.integers(0, 6).map(float), min_size=0, max_size=60)


@settings(max_examples=300, deadline=None)
@given(levels, st.sampled_from([0.0, 0.5, 1.0, 2.0, 3.5]))
def test_prominent_peaks_are_scipy_s(x: list[float], p: float) -> None:
    a = np.array(x)
    want = scipy.signal.find_peaks(a, prominence=p)[0]
    assert np.array_equal(find_prominent(a, p), want)


@settings(max_examples=200, deadline=None)
@given(levels)
def test_maxima_and_prominences_are_scipy_s(x: list[float]) -> None:
    a = np.array(x)
    peaks = scipy.signal.find_peaks(a)[0]
    assert np.array_equal(local_maxima(a), peaks)
    assert np.array_equal(prominences(a, peaks), scipy.signal.peak_prominences(a, peaks)[0])


def test_log_spectrum_peaks() -> None:
    """A noisy log spectrum as the elastic-mode search sees it (511 lines)."""
    rng = np.random.default_rng(3251)
    f = np.linspace(0, 400, 511)
    x = np.log10(1e-3 + 1 / np.abs(1 - (f / 118.5) ** 2 + 0.02j * f / 118.5)
                 + 0.05 * rng.random(511))
    for p in (np.log10(3.0), 2 * np.log10(3.0)):
        assert np.array_equal(find_prominent(x, p), scipy.signal.find_peaks(x, prominence=p)[0])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=40),
       st.integers(0, 6).map(lambda k: 2 * k + 1))
def test_running_median_is_scipy_s(x: list[float], size: int) -> None:
    a = np.array(x)
    want = scipy.ndimage.median_filter(a, size=size, mode="nearest")
    assert np.array_equal(running_median(a, size), want)
