"""Compiled (numba) Welch accumulation of a block in one call parallel over channels
(:func:`add_block`): finite check, tail, FFT, window in frequency, products, float64 sums.

After the FFT, :func:`accumulate` does in one pass, a cache-sized chunk of lines at a time,
what numpy would do in several: the window (a short convolution in frequency when it is a
short cosine sum, such as Hann), the mean removal, the products with each reference and
the squares, added to float64 sums. Spectra arrive as interleaved real views ``(re, im,
...)`` of ``2 n_f`` values; the sums, per line (read by
:func:`processing.spectral._averaged_spectra`), are ``P[2a] += Re(conj(F_a) X)``,
``P[2a + 1] += Im(conj(F_a) X)`` and ``Q += |X|^2``. Each channel's sums are written by
one thread, every value summed over the segments in order, and the FFT of a segment does
not depend on the others in its call: the same bits whatever the block boundaries, the
grouping and the number of threads.

Threads: numba's OpenMP layer where the OpenMP runtime is present (else ``workqueue``),
unless ``NUMBA_THREADING_LAYER`` says otherwise, with ``OMP_WAIT_POLICY=PASSIVE`` unless
set: after a block its threads sleep at once (libgomp's spin count 0), so they neither hold
a core from other threads (the acquisition's readers, another process) nor count as
runnable when the next block looks for free cores (:func:`processing.spectral.free_cores`).
The hot loops index from zero upwards: numba's wrap-around of negative indices stops LLVM
vectorising a loop.
"""

from __future__ import annotations

import os
from typing import Any

import numba
import numpy as np
import rocket_fft  # noqa: F401  (teaches numba scipy.fft: pocketfft, called without the GIL)
import scipy.fft
from numba import njit, prange
from numpy.lib.stride_tricks import as_strided
from numpy.typing import NDArray

__all__ = ["CHUNK", "accumulate", "add_block", "all_finite", "compile_ahead", "window_ref"]

#: interleaved values per chunk (4 kB of float64, kept in the first-level cache)
CHUNK = 512
#: segments per FFT call of a reference, most rows of the others' (pocketfft's SIMD
#: lanes: 4 transforms at once in single precision)
LANES = 4
#: most segments of a compiled call (the references' windowed spectra are held): longer
#: blocks are cut
BATCH = 64

if "NUMBA_THREADING_LAYER" not in os.environ:
    # read by the OpenMP runtime when numba first loads it (the first parallel call)
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # no busy-wait after a block
    numba.config.THREADING_LAYER = "default"  # type: ignore[attr-defined]

#: compiled once per sample precision and layout, cached on disk; releases the GIL
_jit = njit(nogil=True, cache=True, boundscheck=False, error_model="numpy")
_parallel = njit(nogil=True, cache=True, boundscheck=False, error_model="numpy", parallel=True)


@_jit
def _edge(zr: NDArray[np.floating], n: int, taps: NDArray[np.float64], zero_dc: bool,
          k: int) -> tuple[float, float]:
    """Windowed value (re, im) of line ``k``, the convolution wrapping around the two-sided
    DFT of length ``n`` (negative lines are conjugates); line 0 taken as 0 if ``zero_dc``."""
    n_f, M = zr.shape[0] // 2, taps.shape[0] - 1
    re = im = 0.0
    for m in range(-M, M + 1):
        j = (k - m) % n
        if zero_dc and j == 0:
            continue
        t = taps[abs(m)]
        if j < n_f:
            re += t * zr[2 * j]
            im += t * zr[2 * j + 1]
        else:
            re += t * zr[2 * (n - j)]
            im -= t * zr[2 * (n - j) + 1]
    return re, im


@_jit
def _window_chunk(zr: NDArray[np.floating], n: int, taps: NDArray[np.float64], zero_dc: bool,
                  c0: int, c1: int, x: NDArray[np.float64]) -> None:
    """``x[:c1 - c0]``: values ``c0:c1`` of the interleaved windowed spectrum of ``zr``.

    ``X_w[k] = sum_{|m| <= M} taps[|m|] X[k - m]``; the lines near both ends, which wrap
    around, the slow way.
    """
    n2, M = zr.shape[0], taps.shape[0] - 1
    n_f = n2 // 2
    k_lo = M + 1 if (M > 0 or zero_dc) else 0  # first line of the plain formula
    i0 = max(c0, 2 * k_lo)
    i1 = min(c1, n2 - 2 * M)
    if i1 > i0:
        a = zr[i0 - 2 * M : i1 + 2 * M]
        y = x[i0 - c0 : i1 - c0]
        w = i1 - i0
        for j in range(w):
            y[j] = taps[0] * a[j + 2 * M]
        for m in range(1, M + 1):
            lo, hi = a[2 * (M - m) :], a[2 * (M + m) :]
            for j in range(w):
                y[j] += taps[m] * (lo[j] + hi[j])
    for k in range(c0 // 2, min(k_lo, c1 // 2)):
        x[2 * k - c0], x[2 * k + 1 - c0] = _edge(zr, n, taps, zero_dc, k)
    for k in range(max(n_f - M, c0 // 2), c1 // 2):
        x[2 * k - c0], x[2 * k + 1 - c0] = _edge(zr, n, taps, zero_dc, k)


@_jit
def accumulate(fg: NDArray[np.float64], zown: NDArray[np.floating], n: int,
               taps: NDArray[np.float64], zero_dc: bool, row0: int, P: NDArray[np.float64],
               Q: NDArray[np.float64], x: NDArray[np.float64]) -> None:
    """Add the segments ``zown`` (n_own, n_seg, 2 n_f) of some channels (interleaved
    spectra, DFT length ``n``, float32 or float64) to the sums ``P`` (2 n_ref, n_ch, n_f)
    and ``Q`` (n_ch, n_f), ``zown[b]`` to row ``row0 + b``. ``fg`` (>= n_seg, 2 n_ref,
    n_f): the references' windowed spectra of the same segments (:func:`window_ref`);
    ``taps`` (M + 1,): the window in frequency, ``rfft(window)[:M + 1] / n`` (``[1.0]``
    for spectra already windowed); ``zero_dc``: remove each segment's mean (line 0 of the
    un-windowed spectrum taken as 0); ``x`` (>= CHUNK,) float64 scratch."""
    n_seg, n_f, n_ref, M = zown.shape[1], zown.shape[2] // 2, fg.shape[1] // 2, taps.shape[0] - 1
    t0 = taps[0]
    t1 = taps[1] if M > 0 else 0.0
    L = CHUNK // 2  # lines per chunk
    for b in range(zown.shape[0]):
        row = row0 + b
        for k0 in range(0, n_f, L):
            k1 = min(k0 + L, n_f)
            w = k1 - k0
            q = Q[row, k0:k1]
            inner = M + 1 <= k0 and k1 <= n_f - M  # no line near either end
            paired = 0
            if n_ref == 1 and M == 1 and inner:  # Hann and the like, one reference: window,
                pr, pi = P[0, row, k0:k1], P[1, row, k0:k1]  # squares and products in one
                paired = n_seg - n_seg % 2  # pass, two segments at a time (the sums read
                for s in range(0, paired, 2):  # and written once, added to in order)
                    za = zown[b, s, 2 * k0 - 2 : 2 * k1 + 2]
                    ze = zown[b, s + 1, 2 * k0 - 2 : 2 * k1 + 2]
                    fr, fi = fg[s, 0, k0:k1], fg[s, 1, k0:k1]
                    ur, ui = fg[s + 1, 0, k0:k1], fg[s + 1, 1, k0:k1]
                    for j in range(w):
                        vr = t0 * za[2 * j + 2] + t1 * (za[2 * j] + za[2 * j + 4])
                        vi = t0 * za[2 * j + 3] + t1 * (za[2 * j + 1] + za[2 * j + 5])
                        yr = t0 * ze[2 * j + 2] + t1 * (ze[2 * j] + ze[2 * j + 4])
                        yi = t0 * ze[2 * j + 3] + t1 * (ze[2 * j + 1] + ze[2 * j + 5])
                        q[j] = (q[j] + (vr * vr + vi * vi)) + (yr * yr + yi * yi)
                        pr[j] = (pr[j] + (fr[j] * vr + fi[j] * vi)) + (ur[j] * yr + ui[j] * yi)
                        pi[j] = (pi[j] + (fr[j] * vi - fi[j] * vr)) + (ur[j] * yi - ui[j] * yr)
            for s in range(paired, n_seg):
                _window_chunk(zown[b, s], n, taps, zero_dc, 2 * k0, 2 * k1, x)
                for j in range(w):
                    vr, vi = x[2 * j], x[2 * j + 1]
                    q[j] += vr * vr + vi * vi
                for a in range(n_ref):
                    pr, pi = P[2 * a, row, k0:k1], P[2 * a + 1, row, k0:k1]
                    fr, fi = fg[s, 2 * a, k0:k1], fg[s, 2 * a + 1, k0:k1]
                    for j in range(w):
                        vr, vi = x[2 * j], x[2 * j + 1]
                        pr[j] += fr[j] * vr + fi[j] * vi
                        pi[j] += fr[j] * vi - fi[j] * vr


@_jit
def window_ref(z: NDArray[np.floating], n: int, taps: NDArray[np.float64], zero_dc: bool,
               a: int, fg: NDArray[np.float64], x: NDArray[np.float64]) -> None:
    """``fg[s, 2a]``, ``fg[s, 2a + 1]``: the real and imaginary parts of the windowed
    spectrum of segment ``s`` of reference ``a``, from its interleaved spectra ``z``
    ``(n_seg, 2 n_f)`` (see :func:`accumulate`); ``x`` ``(>= 2 n_f,)`` scratch."""
    n2 = z.shape[1]
    for s in range(z.shape[0]):
        _window_chunk(z[s], n, taps, zero_dc, 0, n2, x)
        fr, fi = fg[s, 2 * a], fg[s, 2 * a + 1]
        for k in range(n2 // 2):
            fr[k] = x[2 * k]
            fi[k] = x[2 * k + 1]


@_jit
def all_finite(x: NDArray[np.floating]) -> bool:
    """Whether every sample of ``x`` (2-D) is finite: ``v - v`` is 0 for a finite value
    (nothing can overflow) and NaN otherwise; an or-reduction of comparisons vectorises."""
    for i in range(x.shape[0]):
        bad = False
        for j in range(x.shape[1]):
            bad |= (x[i, j] - x[i, j]) != 0.0
        if bad:
            return False
    return True


@_jit
def _transform(seg: NDArray[np.floating], win: NDArray[np.floating], dc_bins: NDArray[np.int64],
               dc_values: NDArray[np.complex128]) -> Any:
    """Spectra ``(k, n_seg, n_f)`` of the segments ``seg`` ``(k, n_seg, n)``: the FFT of the
    samples where they lie, or (``win`` not empty: a window applied in time) of the samples
    times ``win``, each segment's mean then removed on the lines ``dc_bins`` of
    the window's spectrum (``dc_values``; none if no detrend)."""
    if win.shape[0] == 0:
        return scipy.fft.rfft(seg, axis=-1, workers=1)
    k, n_seg, n = seg.shape
    x = np.empty((k, n_seg, n), seg.dtype)
    for a in range(k):
        for s in range(n_seg):
            xs, ss = x[a, s], seg[a, s]
            for j in range(n):
                xs[j] = ss[j] * win[j]
    z = scipy.fft.rfft(x, axis=-1, workers=1)
    if dc_bins.shape[0]:
        for a in range(k):
            for s in range(n_seg):
                ss = seg[a, s]
                mean = 0.0
                for j in range(n):
                    mean += ss[j]
                mean /= n
                for b in range(dc_bins.shape[0]):
                    z[a, s, dc_bins[b]] -= mean * dc_values[b]
    return z


@_jit
def _segments(tail: Any, arr: Any, lo: int, hi: int, s: int, most: int, n: int, step: int,
              n_tail: int, n_head: int, n_seg: int) -> Any:
    """Rows ``lo:hi``'s segments (hi - lo, m, n) from segment ``s`` on, at most ``most``:
    the first ``n_head`` of the ``n_seg`` start in ``tail``, the others in ``arr``
    (``n_tail`` samples of the tail before it); none across."""
    m = min(most, (n_head if s < n_head else n_seg) - s)
    src, start = (tail, s * step) if s < n_head else (arr, s * step - n_tail)
    s0, s1 = src.strides
    return as_strided(src[lo:hi, start:], shape=(hi - lo, m, n), strides=(s0, step * s1, s1))


@_parallel
def add_block(arr: Any, store: Any, dst: Any, n_tail: int, need: int, n_seg: int,
              n_head: int, n: int, step: int, G: int, runs: Any, ref_of: Any, taps: Any,
              zero_dc: bool, win: Any, dc_bins: Any, dc_values: Any, P: Any, Q: Any,
              zr: Any, fg: Any) -> bool:
    """Add a block ``arr`` (n_ch, n_new) to the sums ``P``, ``Q``; False, and nothing added
    or kept, if a sample is not finite. Two loops over the channels, each channel on one
    of ``numba.get_num_threads()`` threads.

    The tail (samples not consumed by the blocks before) is ``store[:, :n_tail]``; the
    block's first ``need`` samples are appended to it. Its ``n_seg`` complete segments of
    ``n`` samples, every ``step``, the first ``n_head`` starting in the tail, are added
    (up to ``G`` per FFT call); then the samples not consumed go to ``dst``. ``runs`` (k, 2):
    the channels as rows ``lo:hi`` taken by one thread, the references first and alone, the
    others up to ``LANES`` adjacent rows; ``ref_of``: each channel's index among the
    references, or -1; ``zr`` (n_ref, >= n_seg, 2 n_f), ``fg`` (>= n_seg, 2 n_ref, n_f)
    float64: scratch, the references' spectra and windowed spectra. The window: in
    frequency (``taps``; ``zero_dc`` removes the mean; ``win`` empty) or on the samples
    (``win``; the mean removed on the lines ``dc_bins`` of its spectrum, ``dc_values``).
    """
    n_new = arr.shape[1]
    tail = store[:, : n_tail + need]
    bad = 0
    for i in prange(runs.shape[0]):  # check, append to the tail, the references' spectra
        r, hi = runs[i, 0], runs[i, 1]
        if not all_finite(arr[r:hi]):
            bad += 1
            continue
        tail[r:hi, n_tail:] = arr[r:hi, :need]
        if ref_of[r] < 0:
            continue
        x = np.empty(max(CHUNK, 2 * (n // 2 + 1)))
        s = 0
        while s < n_seg:
            seg = _segments(tail, arr, r, r + 1, s, LANES, n, step, n_tail, n_head, n_seg)
            m = seg.shape[1]
            zr[ref_of[r], s : s + m] = _transform(seg, win, dc_bins, dc_values)[0].view(arr.dtype)
            window_ref(zr[ref_of[r], s : s + m], n, taps, zero_dc, ref_of[r], fg[s : s + m], x)
            s += m
    if bad:
        return False
    start = n_seg * step
    for i in prange(runs.shape[0]):  # the sums, then the samples kept
        lo, hi = runs[i, 0], runs[i, 1]
        x = np.empty(CHUNK)
        if ref_of[lo] >= 0:
            accumulate(fg, zr[ref_of[lo] :][:1, :n_seg], n, taps, zero_dc, lo, P, Q, x)
        else:
            s = 0
            while s < n_seg:
                seg = _segments(tail, arr, lo, hi, s, G, n, step, n_tail, n_head, n_seg)
                m = seg.shape[1]
                z = _transform(seg, win, dc_bins, dc_values)
                accumulate(fg[s : s + m], z.view(arr.dtype), n, taps, zero_dc, lo, P, Q, x)
                s += m
        if n_seg == 0:
            continue
        if start < n_tail + need:
            k = n_tail + need - start
            dst[lo:hi, :k] = tail[lo:hi, start:]
            dst[lo:hi, k : k + n_new - need] = arr[lo:hi, need:]
        else:
            dst[lo:hi, : n_tail + n_new - start] = arr[lo:hi, start - n_tail :]
    return True


def compile_ahead() -> None:
    """Compile (or load from numba's cache on disk) the kernels for both sample precisions
    and any block layout, so that the first spectrum does not wait (``make`` calls it)."""
    n, n_f = 8, 5
    for real in (np.float32, np.float64):
        for block in (np.ones((3, 24), real), np.ones((3, 48), real)[:, ::2]):
            for win in (np.empty(0, real), np.ones(n, real)):  # window in frequency, in time
                store = np.zeros((3, 2 * n), real)
                add_block(block, store, store.copy(), 0, 0, 5, 0, n, 4, 4,
                          np.array([[0, 1], [1, 3]]), np.array([0, -1, -1]), np.ones(1),
                          False, win,
                          np.array([0]), np.ones(1, np.complex128), np.zeros((2, 3, n_f)),
                          np.zeros((3, n_f)), np.empty((1, 5, 2 * n_f), real),
                          np.empty((5, 2, n_f)))
        z, fg, P = np.zeros((1, 1, 2 * n_f), real), np.zeros((1, 2, n_f)), np.zeros((2, 1, n_f))
        window_ref(z[0], n, np.ones(1), False, 0, fg, np.empty(CHUNK))  # record_spectra's
        accumulate(fg, z, n, np.ones(1), False, 0, P, P[0] * 0, np.empty(CHUNK))
