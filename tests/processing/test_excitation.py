"""Shaker signal generators."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from processing.excitation import (
    burst_onsets,
    burst_random,
    continuous_random,
    periodic_chirp,
    periodic_random,
    settled_records,
    shaker_signal,
    steady_periods,
)


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


def test_periodic_random_repeats_and_stays_in_band():
    x = periodic_random(4096, 1024.0, rms=0.5, band=(20.0, 100.0), seed=3)
    assert_array_equal(x, periodic_random(4096, 1024.0, rms=0.5, band=(20.0, 100.0), seed=3))
    assert np.sqrt(np.mean(x**2)) == pytest.approx(0.5, rel=1e-12)
    # played twice, one period analysed across the seam has the same lines as the first
    spec = np.abs(np.fft.rfft(np.tile(x, 2)[1000:5096]))
    assert_allclose(spec, np.abs(np.fft.rfft(x)), atol=1e-9)
    f = np.fft.rfftfreq(4096, 1 / 1024.0)
    assert spec[(f < 20.0) | (f > 100.0)].max() < 1e-9 * spec.max()
    with pytest.raises(ValueError, match="no frequency line"):
        periodic_random(8, 1000.0, band=(10.0, 20.0))


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


# ---- what a recorded shaker force is ----

FS = 256.0


def test_shaker_signal_tells_periodic_burst_and_continuous_apart():
    rng = np.random.default_rng(3)
    chirp = periodic_chirp(10, 1024, FS, band=(0.5, 100.0)) + 1e-3 * rng.normal(size=10240)
    s = shaker_signal(chirp, FS)
    assert (s.kind, s.period) == ("periodic", 1024) and s.correlation > 0.99
    burst = burst_random(10, 1024, FS, burst_fraction=0.6, band=(0.0, 100.0), seed=4)[0]
    s = shaker_signal(burst + 1e-3 * rng.normal(size=burst.size), FS)
    assert s.kind == "burst" and abs(s.duty - 0.6) < 0.05
    assert 1024 - 3 * round(0.01 * FS) <= s.period <= 1024  # onsets found to a block or two
    s = shaker_signal(continuous_random(10240, FS, seed=5)[0], FS)
    assert s.kind == "continuous" and s.period is None and s.correlation < 0.2


def test_burst_onsets_are_at_the_bursts():
    x = np.zeros(8 * 512)
    for k in range(8):
        x[k * 512 + 100: k * 512 + 400] = np.random.default_rng(k).normal(size=300)
    on = burst_onsets(x, FS)
    assert on.size == 8
    # never late; early by the blocks' fill and a margin of two blocks (10 ms blocks of 4
    # samples at 256 Hz): the anti-alias filter rings before a burst's sharp start
    assert np.all((on >= np.arange(8) * 512 + 100 - 5 * 4) & (on <= np.arange(8) * 512 + 100))


def test_steady_periods_skips_the_transient():
    t = np.arange(10 * 512) / FS
    y = np.sin(2 * np.pi * 4 * t)[None] + 1e-4 * np.random.default_rng(1).normal(size=(2, t.size))
    y_tr = y + 3 * np.exp(-t / 2.0) * np.cos(2 * np.pi * 3.1 * t)  # decays over ~5 periods
    assert steady_periods(y, 512) == 1  # at least the first: the start from rest
    k = steady_periods(y_tr, 512)
    assert 3 <= k <= 7
    d = np.abs(y_tr[:, k * 512:(k + 1) * 512] - y_tr[:, (k + 1) * 512:(k + 2) * 512]).max()
    assert d < 0.1


def test_settled_records_skips_the_records_with_the_sensors_settling() -> None:
    """Burst records (a burst, then the response dying out) of two channels; an IEPE-like
    decaying offset from the start of the recording (10 % of the response's peak, 0.4 s) is in the
    first record only: it is the one left out; without it none is."""
    rng = np.random.default_rng(4)
    n_rec, L = 10, 1024
    t = np.arange(L) / FS
    burst = rng.normal(size=(n_rec, 2, L)) * (t < 2.4)
    decay = np.diff(np.exp(-t / 0.3) * np.sin(2 * np.pi * 7 * t), prepend=0.0)  # no DC
    rec = np.array([[np.convolve(b, decay)[:L] for b in r] for r in burst])
    assert settled_records(rec) == 0
    peak = np.max(np.abs(rec))
    settling = 0.1 * peak * np.exp(-np.arange(n_rec * L) / FS / 0.4).reshape(n_rec, 1, L)
    assert settled_records(rec + settling) == 1
    assert settled_records(rec[:2] + settling[:2]) == 0  # too few records to tell
