"""``FRFSet.select_lines``: the usable band, cut once for every view."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_array_equal

from processing.data import FRFSet, Geometry


def _frf(coherence: bool = True) -> FRFSet:
    freq = np.arange(0.0, 129.0)  # 0 .. 128 Hz: a spectrum of fs = 256 Hz
    H = (np.arange(2 * 3 * freq.size) + 1j).reshape(2, 3, freq.size)
    coh = np.full(H.shape, 0.9)
    coh[0, 1, 50] = np.nan
    geo = Geometry(np.array([1, 2, 3, 4, 5]), np.arange(15.0).reshape(5, 3))
    return FRFSet(freq, H, [1, 2], np.eye(3)[:2], [3, 4, 5], np.eye(3),
                  geo, coh if coherence else None)


def test_cut_to_fmax_and_nan_coherence_is_zero() -> None:
    frf = _frf()
    assert frf.anti_alias_fmax() == 100.0  # 256 / 2.56
    cut = frf.select_lines(frf.anti_alias_fmax())
    assert_array_equal(cut.freq, np.arange(1.0, 101.0))
    assert_array_equal(cut.H, frf.H[..., 1:101])
    assert cut.coherence is not None
    assert cut.coherence[0, 1, 49] == 0.0 and np.all(np.isfinite(cut.coherence))


def test_all_positive_lines_without_fmax() -> None:
    cut = _frf(coherence=False).select_lines()
    assert_array_equal(cut.freq, np.arange(1.0, 129.0)) and cut.coherence is None


def test_nothing_to_change_returns_the_same_set() -> None:
    once = _frf(coherence=False).select_lines()
    assert once.select_lines() is once
    assert once.select_lines(1e9) is once
