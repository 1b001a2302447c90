"""Non-wrapping time responses of the bench model."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from hardware_mocks.benches import get_bench
from hardware_mocks.signals import frf_laplace, half_sine, impulse_response, simulate


def _block():
    b = get_bench("block")
    g = b.geometry
    return b, g.coordinates(b.resp_nodes)[:3], b.resp_dirs[:3], g.coordinates(b.exc_nodes[:1]), \
        b.exc_dirs[:1]


def test_short_record_does_not_wrap_unlike_time_response():
    b, rx, rd, ex, ed = _block()
    fs, n = 2048.0, 2048
    ir = impulse_response(b.model, fs, rx, rd, ex, ed, passband=0.5)
    f = half_sine(n, fs, 0.01, 0.002, 100.0)[None]
    y = simulate(ir, f)
    # the same hit inside a record 8x longer: the first second must not change
    long = np.zeros((1, 8 * n))
    long[:, :n] = f
    assert_allclose(simulate(ir, long)[:, :n], y, atol=1e-12 * np.abs(y).max())
    # the circular time_response folds the 6 Hz mode's tail back into a 1 s record
    y_circ = b.model.time_response(f, fs, rx, rd, ex, ed)
    assert np.abs(y_circ - y).max() > 0.005 * np.abs(y).max()
    # and agrees once the record is long enough for the tail to die out
    long_circ = b.model.time_response(long, fs, rx, rd, ex, ed)
    assert_allclose(long_circ[:, :n], y, atol=1e-5 * np.abs(y).max())


def test_frf_laplace_on_the_axis_is_the_frf():
    b, rx, rd, ex, ed = _block()
    freq = np.linspace(1, 300, 50)
    assert_allclose(frf_laplace(b.model, 2j * np.pi * freq, rx, rd, ex, ed),
                    b.model.frf(freq, rx, rd, ex, ed), rtol=1e-10)
