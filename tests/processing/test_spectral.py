"""Spectral accumulation and FRF estimators: scipy equivalence, streaming, physical model."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from hardware_mocks.benches import get_bench
from hardware_mocks.signals import impulse_response, simulate
from processing import spectral
from processing.excitation import burst_random, continuous_random, periodic_chirp
from processing.spectral import (
    CrossSpectra,
    SpectralAccumulator,
    SpectralError,
    coherence,
    combine,
    free_cores,
    frf,
    h1,
    h2,
    hv,
    ordinary_coherence,
    record_spectra,
    welch_spectra,
)

FS = 256.0
#: sums of the accumulator before it was parallelised with numba.prange (commit 51bd8c7)
GOLDEN = Path(__file__).parents[1] / "data" / "spectral_crew_sums.npz"


def _signals(n: int = 20000, n_resp: int = 3, seed: int = 0) -> np.ndarray:
    """Force with a DC offset and filtered, noisy responses (n_resp + 1, n)."""
    rng = np.random.default_rng(seed)
    f = rng.standard_normal(n) + 0.7
    b, a = scipy.signal.butter(2, [0.05, 0.3], "bandpass")
    x = np.stack([
        (k + 1) * scipy.signal.lfilter(b, a, f) + 0.05 * rng.standard_normal(n) + 3.0 * k
        for k in range(n_resp)
    ])
    return np.vstack([f[None], x])


@pytest.mark.parametrize(
    ("nperseg", "noverlap", "window", "detrend", "scaling"),
    [
        (256, None, "hann", "constant", "density"),
        (500, 123, "hamming", "constant", "spectrum"),
        (257, 0, ("tukey", 0.3), False, "density"),
        (128, 96, "boxcar", "constant", "density"),
        (255, 100, "blackman", "constant", "density"),
        (64, 32, "flattop", "constant", "spectrum"),
        (5, 2, "hann", "constant", "density"),
        (300, 150, scipy.signal.get_window("hann", 300, fftbins=False), "constant", "density"),
    ],
)
def test_matches_scipy_csd_and_welch(nperseg, noverlap, window, detrend, scaling):
    data = _signals()
    sp = welch_spectra(data, FS, nperseg, noverlap, window=window, detrend=detrend,
                       scaling=scaling)
    kw = {"fs": FS, "nperseg": nperseg, "noverlap": noverlap, "window": window,
          "detrend": detrend, "scaling": scaling}
    _, Pfx = scipy.signal.csd(data[0], data[1:], **kw)
    _, Pff = scipy.signal.welch(data[0], **kw)
    _, Pxx = scipy.signal.welch(data[1:], **kw)
    assert_allclose(sp.freq, scipy.signal.welch(data[0], **kw)[0], rtol=1e-14)
    assert_allclose(sp.Sfx[0], Pfx, rtol=1e-10, atol=1e-10 * np.abs(Pfx).max())
    assert_allclose(sp.Sff[0, 0].real, Pff, rtol=1e-10, atol=1e-10 * Pff.max())
    assert_allclose(sp.Sxx, Pxx, rtol=1e-10, atol=1e-10 * Pxx.max())
    ov = nperseg // 2 if noverlap is None else noverlap
    assert sp.n_averages == (data.shape[1] - ov) // (nperseg - ov)


def test_short_cosine_windows_are_applied_in_frequency_others_in_time():
    # both paths are checked against scipy above; here, that each window takes its path
    cosine = ("hann", "hamming", "blackman", "flattop", "boxcar", ("general_cosine", [1, 0.3]))
    for window in cosine:
        assert SpectralAccumulator(FS, 256, window=window)._taps is not None, window
    for window in (("tukey", 0.3), ("kaiser", 8.0), scipy.signal.get_window("hann", 256, False)):
        assert SpectralAccumulator(FS, 256, window=window)._taps is None, window
    assert_allclose(SpectralAccumulator(FS, 256)._taps, [0.5, -0.25], rtol=1e-14)


def test_float32_input_matches_scipy_in_single_precision():
    data = _signals().astype(np.float32)
    sp = welch_spectra(data, FS, 256)
    _, Pfx = scipy.signal.csd(data[0], data[1:], fs=FS, nperseg=256)
    assert sp.Sfx.dtype == np.complex128
    assert_allclose(sp.Sfx[0], Pfx, rtol=1e-4, atol=1e-5 * np.abs(Pfx).max())


def test_channel_roles_and_h1_matches_scipy_ratio():
    data = _signals()
    sp = welch_spectra(data[[2, 0, 1]], FS, 256, references=(1,), responses=(2, 0))
    _, Pfx = scipy.signal.csd(data[0], data[[1, 2]], fs=FS, nperseg=256)
    _, Pff = scipy.signal.welch(data[0], fs=FS, nperseg=256)
    assert sp.ref_channels == (1,) and sp.resp_channels == (2, 0)
    assert_allclose(h1(sp)[:, 0], Pfx / Pff, rtol=1e-10)


@settings(max_examples=40, deadline=None)
@given(
    cuts=st.lists(st.integers(0, 6000), max_size=12),
    workers=st.sampled_from([1, 2, None]),
    group=st.sampled_from([1, 3, 4]),
    dtype=st.sampled_from([np.float64, np.float32]),
    refs=st.sampled_from([(0,), (3,), (1, 3)]),
)
def test_streaming_is_bitwise_identical_to_one_shot(cuts, workers, group, dtype, refs):
    # threads share the channels; the references' spectra are transformed once
    data = _signals(n=6000, n_resp=3).astype(dtype)
    ref = welch_spectra(data, FS, 200, 150, group=7, references=refs)  # the group: FFT calls
    acc = SpectralAccumulator(FS, 200, 150, group=group, workers=workers, references=refs)
    for block in np.split(data, sorted(cuts), axis=-1):
        acc.update(block)
    sp = acc.spectra()
    assert sp.n_averages == ref.n_averages == acc.n_averages
    assert_array_equal(sp.Sfx, ref.Sfx)
    assert_array_equal(sp.Sff, ref.Sff)
    assert_array_equal(sp.Sxx, ref.Sxx)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_rejected_block_changes_nothing(workers):
    data = _signals(n=8000)
    acc = SpectralAccumulator(FS, 256, workers=workers)
    acc.update(data[:, :3000])
    bad = data[:, 3000:5000].copy()
    bad[2, 1500] = np.nan  # in the second worker's channels
    with pytest.raises(SpectralError, match="NaN or infinite"):
        acc.update(bad)
    with pytest.raises(SpectralError, match="NaN or infinite"):
        acc.update(np.full((4, 10), np.inf))
    acc.update(data[:, 3000:])
    assert acc.n_samples == 8000
    assert_array_equal(acc.spectra().Sfx, welch_spectra(data, FS, 256).Sfx)


def test_reset_with_more_channels_starts_afresh():
    acc = SpectralAccumulator(FS, 256, workers=2)
    acc.update(_signals(n=3000, n_resp=1))
    acc.reset()
    data = _signals(n=3000, n_resp=9)
    acc.update(data)
    assert_array_equal(acc.spectra().Sfx, welch_spectra(data, FS, 256).Sfx)


@pytest.mark.parametrize("workers", [1, 2])
def test_sums_are_bit_identical_to_the_crew_code(workers):
    # golden sums written by the code that had a hand-made thread crew (commit 51bd8c7),
    # one-shot; here cut in blocks, with one or two threads
    golden = np.load(GOLDEN)
    data = golden["data"]
    for i, case in enumerate(json.loads(str(golden["cases"]))):
        window = case["window"]
        acc = SpectralAccumulator(100.0, case["nperseg"], case["noverlap"],
                                  window=tuple(window) if isinstance(window, list) else window,
                                  detrend=case["detrend"], scaling=case["scaling"],
                                  references=case["refs"], workers=workers)
        for block in np.split(data.astype(case["dtype"]), [700, 701, 1900], axis=-1):
            acc.update(block)
        sp = acc.spectra()
        for name in ("Sff", "Sfx", "Sxx"):
            assert_array_equal(getattr(sp, name), golden[f"welch{i}_{name}"], err_msg=f"{case}")
    # record spectra go through scipy.fft, whose SIMD path follows the CPU: on another
    # machine than the one that wrote them they differed in the last bits (at most 1.8e-18
    # absolute, 4e-16 of the largest value), so they are held to rounding of the largest
    for i, dtype in enumerate(("float64", "float32")):
        records = data.astype(dtype)[:, :2800].reshape(5, 7, 400).transpose(1, 0, 2)
        sp = record_spectra(records, 100.0, np.exp(-np.arange(400) / 120.0))
        for name in ("Sff", "Sfx", "Sxx"):
            want = golden[f"records{i}_{name}"]
            assert_allclose(getattr(sp, name), want, rtol=0,
                            atol=1e-14 * float(np.max(np.abs(want))), err_msg=dtype)


def test_a_long_block_is_taken_in_parts_and_refused_whole():
    # more than BATCH segments: added in parts (the same bits), checked whole first
    data = _signals(n=40000)
    acc = SpectralAccumulator(FS, 256, 128)
    acc.update(data[:, :30000])
    acc.update(data[:, 30000:])
    small = SpectralAccumulator(FS, 256, 128)
    for block in np.array_split(data, 80, axis=-1):
        small.update(block)
    assert acc.n_averages == small.n_averages == 311
    assert_array_equal(acc.spectra().Sfx, small.spectra().Sfx)
    assert_array_equal(acc.spectra().Sxx, small.spectra().Sxx)
    bad = data.copy()
    bad[1, -5] = np.inf
    fresh = SpectralAccumulator(FS, 256, 128)
    with pytest.raises(SpectralError, match="nothing was added"):
        fresh.update(bad)
    assert fresh.n_averages == 0 and fresh.n_samples == 0


def test_threads_default_to_every_numba_thread():
    # the live shaker analysis (app/acquire/blocks.py) takes the default
    most = numba.config.NUMBA_NUM_THREADS
    assert SpectralAccumulator(FS, 256).workers == most
    assert SpectralAccumulator(FS, 256, workers=1000).workers == most
    assert SpectralAccumulator(FS, 256, workers=1).workers == 1


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread")
@pytest.mark.parametrize(("free", "workers", "threads"),
                         [(-3, None, 1), (0, 2, 1), (1, None, 1), (2, None, 2), (9, 2, 2),
                          (2, 1, 1)])
def test_each_block_takes_the_threads_of_the_free_cores(monkeypatch, free, workers, threads):
    # a thread sharing its core with a busy process holds up the others at the end of a
    # block (2x slower than one thread): the free cores are read at each block, here given
    used = []

    def set_num_threads(n):
        used.append(n)
        real(n)

    real = numba.set_num_threads
    monkeypatch.setattr(spectral, "free_cores", lambda: free)
    monkeypatch.setattr(numba, "set_num_threads", set_num_threads)
    data = _signals(n=3000, n_resp=9)
    acc = SpectralAccumulator(FS, 256, workers=workers)
    for block in np.array_split(data, 3, axis=-1):
        acc.update(block)
    assert used[::2] == [threads] * 3  # each launch's, then numba's own count put back
    assert_array_equal(acc.spectra().Sfx, welch_spectra(data, FS, 256, workers=1).Sfx)


def test_free_cores_leave_out_a_busy_process():
    # the process is runnable from its first line on: never a free core for it
    cores = len(os.sched_getaffinity(0))
    with subprocess.Popen([sys.executable, "-c", "print(flush=True)\nwhile True: pass"],
                          stdout=subprocess.PIPE) as busy:
        try:
            assert busy.stdout is not None and busy.stdout.readline() == b"\n"
            assert free_cores() <= cores - 1
        finally:
            busy.kill()
    assert free_cores() <= cores


def test_spectra_can_be_read_while_streaming():
    data = _signals(n=8000)
    acc = SpectralAccumulator(FS, 256)
    acc.update(data[:, :4000])
    early = acc.spectra()
    ref_early = welch_spectra(data[:, :4000], FS, 256)
    assert_array_equal(early.Sfx, ref_early.Sfx)
    acc.update(data[:, 4000:])
    assert_array_equal(acc.spectra().Sxx, welch_spectra(data, FS, 256).Sxx)
    assert acc.n_samples == 8000


def test_memory_is_bounded_by_the_tail():
    # every complete segment is used at once: less than one segment is kept, whatever the
    # blocks, and the buffers holding it stop growing
    acc = SpectralAccumulator(FS, 256, group=4)
    rng = np.random.default_rng(3)
    for n in [1000] * 20 + [100] * 20 + [3000] * 5:
        acc.update(rng.standard_normal((3, n)))
        assert acc._tail is not None and acc._tail.shape[-1] < 256
    assert max(store.shape[-1] for store in acc._stores) <= 2 * 256 * 5 // 4  # grown by 1/4


def test_no_segment_yet_and_bad_input_are_clear_errors():
    acc = SpectralAccumulator(FS, 256)
    acc.update(np.zeros((2, 100)))
    with pytest.raises(SpectralError, match="no complete segment"):
        acc.spectra()
    with pytest.raises(SpectralError, match="3 channels, expected 2"):
        acc.update(np.zeros((3, 10)))
    with pytest.raises(SpectralError, match="NaN"):
        acc.update(np.full((2, 10), np.nan))
    with pytest.raises(SpectralError, match="noverlap"):
        SpectralAccumulator(FS, 256, 256)
    with pytest.raises(SpectralError, match="distinct"):
        welch_spectra(np.zeros((2, 600)), FS, 256, references=(0,), responses=(0, 1))
    with pytest.raises(SpectralError, match="choose one of H1, H2, Hv"):
        frf(welch_spectra(_signals(), FS, 256), "H3")


def test_estimators_bracket_the_truth_with_noise_on_both_channels():
    rng = np.random.default_rng(5)
    n = 400_000
    f = rng.standard_normal(n)
    x = 2.0 * f
    fm = f + 0.3 * rng.standard_normal(n)  # force noise: H1 low
    xm = x + 0.6 * rng.standard_normal(n)  # response noise: H2 high
    sp = welch_spectra(np.stack([fm, xm]), FS, 128)
    g1, g2, gv = (np.abs(est(sp)[0, 0, 1:-1]).mean() for est in (h1, h2, hv))
    assert g1 == pytest.approx(2.0 / 1.09, rel=0.01)  # |H| Sff / (Sff + Snn)
    assert g2 == pytest.approx(2.0 * (1 + 0.36 / 4), rel=0.01)
    assert g1 < gv < g2
    # noise only on the response: H1 unbiased; only on the force: H2 unbiased
    assert np.abs(h1(welch_spectra(np.stack([f, xm]), FS, 128))[0, 0, 1:-1]).mean() == (
        pytest.approx(2.0, rel=0.01))
    assert np.abs(h2(welch_spectra(np.stack([fm, x]), FS, 128))[0, 0, 1:-1]).mean() == (
        pytest.approx(2.0, rel=0.01))


def test_hv_equals_h1_without_noise_and_h2_needs_one_reference():
    data = _signals()
    sp = welch_spectra(np.stack([data[0], 3 * data[0]]), FS, 256)
    assert_allclose(hv(sp)[..., 1:], h1(sp)[..., 1:], rtol=1e-9)
    assert_allclose(h2(sp)[..., 1:], h1(sp)[..., 1:], rtol=1e-9)
    two = welch_spectra(data, FS, 256, references=(0, 1))
    with pytest.raises(SpectralError, match="exactly one reference"):
        h2(two)


def test_combine_weights_by_averages():
    data = _signals(n=12000)
    a = welch_spectra(data[:, :4096], FS, 256, 0)
    b = welch_spectra(data[:, 4096:], FS, 256, 0)
    both = welch_spectra(np.concatenate([data[:, :4096], data[:, 4096:4096 + b.n_averages * 256]],
                                        axis=-1), FS, 256, 0)
    c = combine(a, b)
    assert c.n_averages == a.n_averages + b.n_averages == both.n_averages
    assert_allclose(c.Sfx, both.Sfx, rtol=1e-12)
    with pytest.raises(SpectralError, match="frequency lines"):
        combine(a, welch_spectra(data, FS, 128))


def test_cross_spectra_checks_shapes():
    with pytest.raises(SpectralError, match="Sfx has shape"):
        CrossSpectra(np.arange(3.0), np.ones((1, 1, 3)), np.ones((1, 2, 4)), np.ones((2, 3)), 1,
                     (0,), (1, 2))


# --------------------------------------------------------------------------------------------
# against the physical model
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def engine():
    b = get_bench("engine")
    g = b.geometry
    rx, ex = g.coordinates(b.resp_nodes)[:3], g.coordinates(b.exc_nodes)
    return b, rx, b.resp_dirs[:3], ex, b.exc_dirs


def _within(H, He, coh, freq, fs, limit=0.99, fmin=0.0):
    """Magnitude (relative) and phase (deg) errors where coherence > limit, below fs/2.56."""
    m = (coh > limit) & (freq > fmin) & (freq < fs / 2.56)
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = np.abs(np.abs(H) / np.abs(He) - 1)[m]
        ph = np.degrees(np.abs(np.angle(H / He)))[m]
    return m.mean(), mag.max(), ph.max()


def test_h1_continuous_random_matches_model(engine):
    bench, rx, rd, ex, ed = engine
    ir = impulse_response(bench.model, FS, rx, rd, ex[:1], ed[:1])
    nper, n_avg = 8192, 600
    f = continuous_random((n_avg + 1) * nper // 2, FS, rms=10.0, seed=1)
    x = simulate(ir, f)
    rng = np.random.default_rng(2)
    x += 0.01 * x.std(axis=-1, keepdims=True) * rng.standard_normal(x.shape)
    acc = SpectralAccumulator(FS, nper, workers=2)
    for block in np.array_split(np.vstack([f, x]), 9, axis=-1):
        acc.update(block)
    sp = acc.spectra()
    H, coh = frf(sp)
    He = bench.model.frf(sp.freq, rx, rd, ex[:1], ed[:1])
    frac, mag, ph = _within(H, He, coh, sp.freq, FS)
    assert frac > 0.6  # most lines are coherent
    assert mag < 0.01 and ph < 1.0


def test_h1_burst_random_matches_model_without_window(engine):
    bench, rx, rd, ex, ed = engine
    ir = impulse_response(bench.model, FS, rx, rd, ex[:1], ed[:1])
    L, n_b, lead = 2048, 12, 64
    f = burst_random(n_b, L, FS, burst_fraction=0.25, band=(0.0, 110.0), seed=3)
    f = np.concatenate([np.zeros((1, lead)), f[:, :-lead]], axis=-1)  # records start before bursts
    x = simulate(ir, f)
    # rectangular window, no overlap, no detrend: the accumulator as a burst analyser
    sp = welch_spectra(np.vstack([f, x]), FS, L, 0, window="boxcar", detrend=False)
    assert sp.n_averages == n_b
    H, coh = frf(sp)
    He = bench.model.frf(sp.freq, rx, rd, ex[:1], ed[:1])
    frac, mag, ph = _within(H, He, coh, sp.freq, FS)
    assert frac > 0.7
    assert mag < 0.01 and ph < 1.0
    # noise-free and leakage-free: exact but for the lowest lines (|H| ~ 1e-6 of the mass line)
    assert _within(H, He, coh, sp.freq, FS, fmin=0.5)[1] < 1e-3
    records = np.vstack([f, x]).reshape(4, n_b, L).transpose(1, 0, 2)
    assert_allclose(record_spectra(records, FS).Sfx, sp.Sfx, rtol=1e-9)


def test_h1_periodic_chirp_matches_model(engine):
    bench, rx, rd, ex, ed = engine
    ir = impulse_response(bench.model, FS, rx, rd, ex[:1], ed[:1])
    L = 1024
    f = periodic_chirp(5, L, FS, band=(1.0, 95.0), amplitude=5.0)[None]
    x = simulate(ir, f)
    # the first two periods let the transient settle; then each period is one record
    sp = welch_spectra(np.vstack([f, x])[:, 2 * L:], FS, L, 0, window="boxcar", detrend=False)
    H, coh = frf(sp)
    He = bench.model.frf(sp.freq, rx, rd, ex[:1], ed[:1])
    band = (sp.freq >= 2.0) & (sp.freq <= 94.0)
    assert_allclose(H[..., band], He[..., band], rtol=5e-3)
    assert coh[..., band].min() > 0.999


def test_two_shakers_multi_reference_h1_and_multiple_coherence(engine):
    bench, rx, rd, ex, ed = engine
    refs = [0, 7]
    ir = impulse_response(bench.model, FS, rx, rd, ex[refs], ed[refs])
    nper, n_avg = 8192, 1000
    f = continuous_random((n_avg + 1) * nper // 2, FS, rms=10.0, n_channels=2, seed=4)
    f[1] += 0.3 * f[0]  # partially correlated drives: still separable
    x_clean = simulate(ir, f)
    rng = np.random.default_rng(5)
    x = x_clean + 0.003 * x_clean.std(axis=-1, keepdims=True) * rng.standard_normal(x_clean.shape)
    sp = welch_spectra(np.vstack([f, x]), FS, nper, references=(0, 1), workers=2)
    H, coh = frf(sp)
    assert H.shape == (3, 2, nper // 2 + 1)
    He = bench.model.frf(sp.freq, rx, rd, ex[refs], ed[refs])
    m = (coh[:, 0] > 0.99) & (sp.freq > 0) & (sp.freq < FS / 2.56)
    assert m.mean() > 0.6
    # each response's row of FRFs within 1 % where the multiple coherence exceeds 0.99
    with np.errstate(divide="ignore", invalid="ignore"):
        row_err = np.linalg.norm(H - He, axis=1) / np.linalg.norm(He, axis=1)
    assert row_err[m].max() < 0.01
    # and each FRF within 1 % and 1 degree where it carries its share of the response
    # (at least half the largest of its row: a smaller one is less well separated)
    share = np.abs(He) >= 0.5 * np.abs(He).max(axis=1, keepdims=True)
    frac, mag, ph = _within(H, He, np.where(share, coh, 0.0), sp.freq, FS)
    assert frac > 0.4
    assert mag < 0.01 and ph < 1.0
    # multiple coherence: noise-free responses are explained by the two forces (but for
    # a little Hann leakage at the resonances)
    clean = welch_spectra(np.vstack([f, x_clean]), FS, nper, references=(0, 1))
    band = (clean.freq > 2) & (clean.freq < 90)
    assert coherence(clean)[:, band].min() > 0.99
    assert np.median(coherence(clean)[:, band]) > 0.9999
    # each force alone explains only part of each response
    assert ordinary_coherence(clean)[:, :, band].mean() < 0.95
