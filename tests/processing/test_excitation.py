"""Shaker signal generators."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from processing.excitation import burst_random, continuous_random, periodic_chirp


def test_continuous_random_is_seeded_and_scaled():
    a = continuous_random(5000, 1000.0, rms=2.0, n_channels=2, seed=7)
    assert a.shape == (2, 5000)
    assert_allclose(np.sqrt(np.mean(a**2, axis=-1)), 2.0)
    assert_array_equal(a, continuous_random(5000, 1000.0, rms=2.0, n_channels=2, seed=7))
    assert abs(np.corrcoef(a)[0, 1]) < 0.05
    band = continuous_random(2**15, 1000.0, band=(100.0, 200.0), seed=1)[0]
    spec = np.abs(np.fft.rfft(band)) ** 2
    f = np.fft.rfftfreq(band.size, 1e-3)
    assert spec[(f > 110) & (f < 190)].mean() > 1e3 * spec[f > 300].mean()
    with pytest.raises(ValueError, match="band"):
        continuous_random(10, 1000.0, band=(100.0, 600.0))


def test_burst_random_is_silent_after_the_burst():
    x = burst_random(3, 1000, 1000.0, burst_fraction=0.3, seed=2)
    rec = x.reshape(3, 1000)
    assert np.all(rec[:, 300:] == 0) and np.all(np.abs(rec[:, 10:290]).max(axis=1) > 0)


def test_periodic_chirp_is_periodic_and_in_band():
    x = periodic_chirp(3, 1024, 1024.0, band=(50.0, 200.0))
    assert_array_equal(x[:1024], x[1024:2048])
    spec = np.abs(np.fft.rfft(x[:1024])) ** 2
    inside = spec[50:201].sum() / spec.sum()
    assert inside > 0.95
    # continuing the sweep one sample past the period gives the period's first sample
    assert abs(x[1023] - x[1022]) < 2 * np.pi * 200 / 1024 * 1.01
