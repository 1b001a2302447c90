"""Impact processing against the physical model: hits, verdicts, windows, averaged H1."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from hardware_mocks.benches import get_bench
from hardware_mocks.signals import frf_laplace, half_sine, impulse_response, simulate
from processing.data import FRFSet, InputError
from processing.impact import (
    ImpactSettings,
    find_triggers,
    impact_measurement,
    merge_results,
    process_impacts,
)

FS = 2048.0
L = 2048  # 1 s records, 1 Hz lines
PRE = 64
TAU = 0.1  # s: the engine's slowest mode (0.46 s) has died out (6e-6) by the record end
SPACING = 5.0  # s between hits: the previous hit has died out too
PULSE = 0.003  # s, half-sine


@pytest.fixture(scope="module")
def engine():
    b = get_bench("engine")
    g = b.geometry
    rx, rd = g.coordinates(b.resp_nodes), b.resp_dirs
    ex, ed = g.coordinates(b.exc_nodes[:1]), b.exc_dirs[:1]
    return b, rx, rd, ex, ed, impulse_response(b.model, FS, rx, rd, ex, ed)


def _hammer(ir, peaks, *, double_at=None, clip_at=None, seed=1, force_noise=0.05,
            resp_noise=2e-5):
    """Recording (1 + n_resp, n): hits every SPACING s from 1 s, optional double and clipped hit."""
    rng = np.random.default_rng(seed)
    n = int((len(peaks) * SPACING + 1.0) * FS)
    t_hits = 1.0 + SPACING * np.arange(len(peaks))
    f = sum(half_sine(n, FS, t, PULSE, p) for t, p in zip(t_hits, peaks, strict=True))
    if double_at is not None:
        f = f + half_sine(n, FS, t_hits[double_at] + 0.03, PULSE, 0.4 * peaks[double_at])
    x = simulate(ir, f[None])
    f_m = f + force_noise * rng.standard_normal(n)
    x_m = x + resp_noise * np.abs(x).max() * rng.standard_normal(x.shape)
    if clip_at is not None:
        i0 = int(t_hits[clip_at] * FS) - 5
        f_m[i0:i0 + 20] = np.minimum(f_m[i0:i0 + 20], 0.7 * peaks[clip_at])
    return np.vstack([f_m, x_m])


@pytest.fixture(scope="module")
def recording(engine):
    *_, ir = engine
    peaks = np.random.default_rng(0).uniform(150, 250, 11)
    return _hammer(ir, peaks, double_at=4, clip_at=5)


def test_triggers_one_per_hit_with_holdoff():
    f = np.zeros(10000)
    for t0 in (1000, 1010, 4000, 9000):  # 1010: the same hit's ringing re-crossing the level
        f[t0:t0 + 5] = 100.0
    s = ImpactSettings(level=50.0, record_length=2000, pretrigger=10)
    assert find_triggers(f, s).tolist() == [1000, 4000, 9000]
    falling = ImpactSettings(level=-50.0, record_length=2000, slope="falling")
    assert find_triggers(-f, falling).tolist() == [1000, 4000, 9000]


def test_verdicts_double_hit_clipping_incomplete(recording):
    data = recording[:, : -int(4.5 * FS)]  # cut inside the last record
    res = process_impacts(data, FS, ImpactSettings(20.0, L, PRE, exp_tau=TAU),
                          channel_names=["hammer", *(f"acc{i}" for i in range(12))])
    reasons = {v.index: v.reason for v in res.verdicts if not v.accepted}
    assert set(reasons) == {4, 5, 10}
    assert reasons[4].startswith("double hit (second impact 29.8 ms after")
    assert "overload on hammer" in reasons[5] and "clipped" in reasons[5]
    assert "incomplete" in reasons[10]
    assert res.n_accepted == 8
    assert res.meta["n_averages"] == 8


def test_clean_noisy_hits_are_not_double_hits(engine):
    *_, ir = engine
    data = _hammer(ir, [200.0, 180.0, 220.0], force_noise=1.0)  # 0.5 % force noise
    res = process_impacts(data, FS, ImpactSettings(20.0, L, PRE, exp_tau=TAU))
    assert [v.accepted for v in res.verdicts] == [True, True, True]


def test_response_overload_names_the_channel(recording):
    ranges = np.full(recording.shape[0], 1e9)
    ranges[3] = 0.5 * np.abs(recording[3, : int(6 * FS)]).max()  # first hit overloads acc 3
    res = process_impacts(recording, FS, ImpactSettings(20.0, L, PRE, exp_tau=TAU),
                          ranges=ranges)
    assert not res.verdicts[0].accepted
    assert res.verdicts[0].reason.startswith("overload on channel 3")


def test_h1_matches_the_exponentially_windowed_model(engine, recording):
    bench, rx, rd, ex, ed, _ = engine
    res = process_impacts(recording, FS, ImpactSettings(20.0, L, PRE, exp_tau=TAU))
    assert res.H is not None and res.coherence is not None and res.spectra is not None
    # the window turns the FRF into the model's at s = j omega + 1/tau (processing.windows)
    He = frf_laplace(bench.model, 2j * np.pi * res.freq + 1 / TAU, rx, rd, ex, ed)
    Sff = res.spectra.Sff[0, 0].real
    # where the hammer excites (force spectrum within 20 dB of its top), above the lowest
    # lines (accelerance 60 dB below the mass line) and in the front end's band
    band = (Sff > 0.01 * Sff.max()) & (res.freq >= 5.0) & (res.freq < FS / 2.56)
    m = (res.coherence > 0.99) & band
    assert m.mean() > 0.3
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = np.abs(np.abs(res.H) / np.abs(He) - 1)[m]
        ph = np.degrees(np.abs(np.angle(res.H / He)))[m]
    assert mag.max() < 0.01 and ph.max() < 1.0


def test_noise_free_hit_is_exact_and_float32_accepted(engine):
    bench, rx, rd, ex, ed, ir = engine
    data = _hammer(ir, [200.0, 150.0], force_noise=0.0, resp_noise=0.0)
    res = process_impacts(data.astype(np.float32), FS,
                          ImpactSettings(20.0, L, PRE, exp_tau=TAU, force_window=0.02))
    He = frf_laplace(bench.model, 2j * np.pi * res.freq + 1 / TAU, rx, rd, ex, ed)
    band = (res.freq >= 5.0) & (res.freq < 400.0)
    assert res.H is not None
    assert_allclose(res.H[..., band], He[..., band], rtol=1e-3, atol=1e-5 * np.abs(He).max())


def test_merge_and_frfset(engine, recording):
    bench, *_ = engine
    settings = ImpactSettings(20.0, L, PRE, exp_tau=TAU)
    cut = int(13.5 * FS)
    a = process_impacts(recording[:, :cut], FS, settings)
    b = process_impacts(recording[:, cut:], FS, settings)
    whole = process_impacts(recording, FS, settings)
    merged = merge_results([a, b])
    assert merged.n_accepted == whole.n_accepted
    assert merged.H is not None and whole.H is not None
    assert_allclose(merged.H, whole.H, rtol=1e-10)
    m = impact_measurement([merged, merged], bench.geometry, bench.resp_nodes,
                           bench.resp_dirs, bench.exc_nodes[:2], bench.exc_dirs[:2])
    fs_set = m.frf
    assert isinstance(fs_set, FRFSet)
    assert fs_set.H.shape == (12, 2, L // 2 + 1)
    assert m.provenance.exponential_tau == TAU
    assert m.provenance.estimated
    assert fs_set.coherence is not None


def test_max_averages_uses_the_first_accepted_hits(recording):
    settings = ImpactSettings(20.0, L, PRE, exp_tau=TAU)
    res = process_impacts(recording, FS, settings, max_averages=5)
    # hits 0-3 and 6 are the first five accepted (4: double hit, 5: clipped)
    assert [v.index for v in res.verdicts if v.accepted] == [0, 1, 2, 3, 6]
    unused = [v for v in res.verdicts if v.reason.startswith("not used")]
    assert [v.index for v in unused] == [7, 8, 9, 10]
    assert unused[0].reason == "not used: the first 5 accepted hits are averaged"
    assert res.meta["n_averages"] == 5 and res.spectra is not None
    assert res.spectra.n_averages == 5
    first = process_impacts(recording[:, : int(34 * FS)], FS, settings)  # hits 0-6 only
    assert first.n_accepted == 5 and first.H is not None and res.H is not None
    assert_array_equal(res.H, first.H)
    assert process_impacts(recording, FS, settings, max_averages=50).n_accepted == 9
    with pytest.raises(InputError, match="max_averages must be at least 1"):
        process_impacts(recording, FS, settings, max_averages=0)


def test_no_accepted_hit_is_reported_not_raised(recording):
    res = process_impacts(recording[:, : int(1.2 * FS)], FS, ImpactSettings(20.0, L, PRE))
    assert res.H is None and res.n_accepted == 0
    with pytest.raises(InputError, match="no accepted hit: record incomplete"):
        impact_measurement([res], get_bench("engine").geometry, [1], [[1, 0, 0]], [11],
                           [[1, 0, 0]])


def test_settings_are_checked():
    with pytest.raises(InputError, match="pretrigger"):
        ImpactSettings(10.0, 100, pretrigger=100)
    with pytest.raises(InputError, match="slope"):
        ImpactSettings(10.0, 100, slope="up")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="NaN"):
        process_impacts(np.full((2, 100), np.nan), FS, ImpactSettings(10.0, 50))


def test_a_channel_clipped_at_the_same_level_rejects_every_hit_reaching_it(engine):
    """Every hit clips one response for one or two samples at the digitiser's last code
    (no flat top to see in one hit): the common extreme gives it away, every hit reaching
    it names the channel, which is left out of the point's FRFs (the point is kept for the
    other responses); the same run unclipped, identical noise-free hits and a quiet channel
    a few codes above its noise are accepted."""
    *_, ir = engine
    peaks = np.random.default_rng(41).uniform(196, 204, 5)  # an even hand
    clean = _hammer(ir, peaks, seed=42)
    s = ImpactSettings(20.0, L, PRE, exp_tau=TAU)
    names = ["hammer", *(f"acc{i}" for i in range(12))]
    assert all(v.accepted for v in process_impacts(clean, FS, s, channel_names=names).verdicts)

    hit_peaks = np.array([np.abs(clean[7, int((1.0 + SPACING * k) * FS):
                                       int((1.0 + SPACING * (k + 1)) * FS)]).max()
                          for k in range(5)])
    level = 0.995 * hit_peaks.min()  # below every hit's peak: a sample or two clipped each
    clipped = clean.copy()
    clipped[7] = np.clip(clipped[7], -level, level)
    at_level = np.abs(clipped[7]) >= level
    assert 5 <= at_level.sum() <= 10 and not (at_level[2:] & at_level[1:-1] & at_level[:-2]).any()
    res = process_impacts(clipped, FS, s, channel_names=names)
    # every hit of the point clips acc6 alone: the hits are kept for the other responses,
    # acc6 left out of the point's FRFs (coherence 0, weighed out of the fit)
    assert all(v.accepted for v in res.verdicts)
    assert all(v.reason.startswith("accepted without acc6: every hit of the point overloads "
                                   "it (overload on acc6 (clipped: it reaches the extreme")
               for v in res.verdicts)
    assert res.left_out == (6,) and res.coherence is not None
    assert np.all(res.coherence[6] == 0) and np.all(res.coherence[5] > 0)
    # the station's input ranges decide when given: this level is far below them
    ranges = np.full(clipped.shape[0], 1e6)
    assert all(v.accepted for v in process_impacts(clipped, FS, s, channel_names=names,
                                                   ranges=ranges).verdicts)

    # identical noise-free hits reach the same extremes: not clipping
    same = _hammer(ir, [200.0] * 4, force_noise=0.0, resp_noise=0.0)
    assert all(v.accepted for v in process_impacts(same, FS, s).verdicts)
    # a quiet channel quantised to a few codes reaches its largest code on several hits
    quiet = clean.copy()
    quiet[5] = np.round(quiet[5] / np.abs(quiet[5]).max() * 4)
    assert all(v.accepted for v in process_impacts(quiet, FS, s).verdicts)


def test_a_single_sample_at_the_converters_last_code_rejects_its_hit(engine):
    """Every channel digitised by a 24-bit converter (each response's range 1.5x its largest
    hit, the force's 2x); one response's range then set under one hit's peak so that one
    sample of that hit alone clips: no flat top, no level another hit reaches, yet the
    sample sits at the converter's last code: that hit is rejected naming the channel, the
    others accepted. The same records unquantised (floats) or quantised without the clip
    reject none (the tops read from the samples: inf for floats, the full scale otherwise)."""
    from processing.impact import converter_tops

    *_, ir = engine
    peaks = np.random.default_rng(43).uniform(150, 250, 4)
    clean = _hammer(ir, peaks, seed=44)
    s = ImpactSettings(20.0, L, PRE, exp_tau=TAU)
    names = ["hammer", *(f"acc{i}" for i in range(12))]
    top = np.abs(clean).max(axis=-1) * np.r_[2.0, np.full(12, 1.5)]

    def digitised(x: np.ndarray, full: np.ndarray) -> np.ndarray:
        q = (2 * full / 2**24)[:, None]
        return np.clip(np.round(x / q) * q, -2**23 * q, 2**23 * q)

    assert_allclose(converter_tops(digitised(clean, top)), top * (1 - 1.001 / 2**23),
                    rtol=1e-9)
    assert np.all(np.isinf(converter_tops(clean)))
    assert all(v.accepted for v in process_impacts(digitised(clean, top), FS, s,
                                                   channel_names=names).verdicts)
    seg = [np.abs(clean[9, int((1.0 + SPACING * k) * FS):int((1.0 + SPACING * (k + 1)) * FS)])
           for k in range(4)]
    k = int(np.argmax([a.max() for a in seg]))
    second = np.sort(np.concatenate(seg))[-2]  # the level under the test's largest sample
    top[9] = 0.5 * (second + seg[k].max())
    x = digitised(clean, top)
    assert np.count_nonzero(np.abs(x[9]) >= top[9]) == 1
    res = process_impacts(x, FS, s, channel_names=names)
    reasons = {v.index: v.reason for v in res.verdicts if not v.accepted}
    assert list(reasons) == [k]
    assert reasons[k] == "overload on acc8 (clipped: a sample at its converter's last code)"


def test_a_level_two_hits_reach_far_under_the_converters_end_is_not_clipping(engine):
    """Two hits whose largest sample on a response is the same code, a quarter of its
    converter's full scale (two hits of one hand can): not clipping, both accepted; the same
    records as floats (the converter's end unknown) are taken for a clip at that level (the
    point then kept without that response)."""
    *_, ir = engine
    clean = _hammer(ir, [200.0, 200.0], seed=46)
    s = ImpactSettings(20.0, L, PRE, exp_tau=TAU)
    segs = [slice(int((1.0 + SPACING * k) * FS), int((1.0 + SPACING * k) * FS) + L - PRE)
            for k in range(2)]  # within each hit's record
    at = [int(np.argmax(clean[4, sg])) + sg.start for sg in segs]
    clean[4, at] = clean[4].max()  # both hits' largest sample on acc3 the same
    top = np.abs(clean).max(axis=-1) * 4.0
    q = (2 * top / 2**24)[:, None]
    x = np.round(clean / q) * q
    res = process_impacts(x, FS, s)
    assert all(v.accepted and not v.reason for v in res.verdicts) and res.left_out == ()
    res = process_impacts(clean, FS, s)  # both hits named: the point kept without acc3
    assert res.left_out == (3,)
    assert all(v.reason.startswith("accepted without channel 4: every hit of the point "
                                   "overloads it (overload on channel 4 (clipped: it reaches")
               for v in res.verdicts)
