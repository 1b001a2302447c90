"""Impact FRFs of band-limited hits against an exact single-DOF accelerance: the force's offset
and the anti-alias filter's ringing around a pulse a few samples long."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_less

from processing.data import InputError
from processing.impact import (
    ImpactSettings,
    impact_defaults,
    pretrigger_for,
    process_impacts,
    ringing,
)

FS = 256.0
M, FN, ZETA = 100.0, 6.0, 0.1  # kg, Hz: one mount mode, decayed to 1e-4 in 2.5 s
HIT_TIMES = (1.0, 4.0, 7.0, 10.0)  # s
N = 13 * 256


def _accelerance(f: np.ndarray, a: float = 0.0, zeta: float = ZETA) -> np.ndarray:
    """Accelerance at ``s = j 2 pi f + a`` (``a``: an exponential window's decay rate, 1/s)."""
    s, wn = 2j * np.pi * f + a, 2 * np.pi * FN
    return s**2 / (M * (wn**2 + s**2 + 2 * zeta * wn * s))


def _recording(offset: float = 0.0, noise: float = 0.0, seed: int = 0,
               zeta: float = ZETA, times: tuple[float, ...] = HIT_TIMES) -> np.ndarray:
    """Force (N) and acceleration of half-sine hits 2.56 samples wide through a zero-phase
    anti-alias filter (flat to fs / 2.56, raised cosine to 0 at fs / 2), as an acquisition
    records them; the response is exact (long zero tail)."""
    n_pad = 16 * N
    t = np.arange(n_pad) / FS
    f = np.zeros(n_pad)
    width = 2.56 / FS
    for k, t0 in enumerate(times):
        u = (t - t0 - 0.3 * k / FS) / width
        f += np.where((u > 0) & (u < 1), 200.0 * np.sin(np.pi * np.clip(u, 0, 1)), 0.0)
    freq = np.fft.rfftfreq(n_pad, 1 / FS)
    lo, hi = FS / 2.56, FS / 2
    g = 0.5 * (1 + np.cos(np.pi * np.clip((freq - lo) / (hi - lo), 0, 1)))
    F = np.fft.rfft(f) * g
    x = np.fft.irfft(_accelerance(freq, zeta=zeta) * F, n_pad)[:N]
    force = np.fft.irfft(F, n_pad)[:N] + offset
    rng = np.random.default_rng(seed)
    return np.vstack([force + noise * rng.standard_normal(N),
                      x + noise * 1e-4 * rng.standard_normal(N)])


def _error(data: np.ndarray, settings: ImpactSettings, band: tuple[float, float]) -> float:
    """Largest relative error of H1 against the exact accelerance on the lines of ``band``."""
    res = process_impacts(data, FS, settings)
    assert res.H is not None
    sel = (res.freq >= band[0]) & (res.freq <= band[1])
    H = res.H[0, 0, sel]
    return float(np.max(np.abs(H - _accelerance(res.freq[sel])) / np.abs(_accelerance(
        res.freq[sel]))))


def test_force_offset_is_taken_off():
    """A 1 N offset under 200 N pulses 2.56 samples wide biases the force spectrum by about a
    percent when left in the force window; taken off (the record's median), the FRF is as
    without it."""
    s = ImpactSettings(level=20.0, record_length=round(2.5 * FS), pretrigger=32, ring=8)
    clean = _error(_recording(), s, (2.0, 90.0))
    offset = _error(_recording(offset=1.0), s, (2.0, 90.0))
    assert clean < 3e-3
    assert offset < clean + 5e-4


def test_ringing_read_from_the_force():
    """Samples the filtered pulse stands above 4 noise standard deviations before and after
    the pulse: a few, and more with less noise."""
    data = _recording(noise=0.05)
    d = impact_defaults(data[0], data[1:], FS)
    quiet = impact_defaults(*_recording(noise=0.005)[:1], _recording(noise=0.005)[1:], FS)
    assert 2 <= d.ring_before <= 16 and 2 <= d.ring_after <= 16
    assert quiet.ring_before > d.ring_before and quiet.ring_after > d.ring_after
    g = data[0] - np.median(data[0])
    assert ringing(g, np.array([int(HIT_TIMES[0] * FS)]), 0.05)[1] == pytest.approx(
        d.ring_after, abs=3)


def test_pretrigger_and_force_window_hold_the_ringing():
    """A pre-trigger of 3 samples and a force window ending one pulse width after the pulse cut
    the filter's ringing: the lowest lines (accelerance small) are off by about 2 %. Four
    times the ringing before the pulse and the ringing after it kept bring them under
    0.6 %."""
    data = _recording(noise=0.05)
    d = impact_defaults(data[0], data[1:], FS)
    L = round(2.5 * FS)
    cut = _error(data, ImpactSettings(level=20.0, record_length=L, pretrigger=3), (0.8, 3.0))
    kept = _error(data, ImpactSettings(level=20.0, record_length=L,
                                       pretrigger=4 * d.ring_before, ring=d.ring_after),
                  (0.8, 3.0))
    assert cut > 0.012
    assert_array_less(kept, 0.006)



def test_default_pretrigger_holds_the_ringing():
    """The default pre-trigger (:func:`pretrigger_for`: twice the samples the force rings above
    its noise before a pulse) holds the filter's ringing: the lowest lines within 0.5 %, where
    0.01 s (3 samples) leaves them 1.8 % off; with less force noise more ringing shows and the
    pre-trigger grows with it."""
    L = round(2.5 * FS)
    for noise, most in ((0.05, 0.005), (0.01, 0.006)):
        data = _recording(noise=noise)
        d = impact_defaults(data[0], data[1:], FS)
        pre = round(pretrigger_for(d.ring_before, FS) * FS)
        assert pre == 2 * d.ring_before
        err = _error(data, ImpactSettings(level=20.0, record_length=L, pretrigger=pre),
                     (0.8, 3.0))
        assert_array_less(err, most)
        cut = _error(data, ImpactSettings(level=20.0, record_length=L,
                                          pretrigger=round(0.01 * FS)), (0.8, 3.0))
        assert cut > 3 * err
    assert pretrigger_for(1, FS) == 0.01
    with pytest.raises(InputError, match="ring_before"):
        pretrigger_for(-1, FS)
