"""Compiled (numba) kernel of the Welch accumulation: window in frequency, products, sums.

After the FFT, every step of the cross-spectral sums is a pass over the spectra that
numpy cannot fuse: the window (a short convolution in frequency when the window is a
short cosine sum, such as Hann), the mean removal, the products with each reference and
the squares, then the additions into float64 sums. :func:`accumulate` does them all in
one pass, a cache-sized chunk of lines at a time, reading each spectrum once.

Layout (the one :func:`processing.spectral._spectra_sums` reads): spectra arrive as
interleaved real views ``(re, im, re, im, ...)`` of ``2 n_f`` values; the sums are kept
per line, ``P[2a] += Re(conj(F_a) X)``, ``P[2a + 1] += Im(conj(F_a) X)`` and
``Q += |X|^2``, in float64 (``3 n_f`` values per channel and reference, read and written
once per group of segments: the larger the group, the less memory traffic). Every value
is summed over the segments in order, whatever the chunking and the grouping: the same
bits whatever the block boundaries and the number of workers.

The hot loops index from zero upwards only: numba's wrap-around of negative indices
stops LLVM vectorising a loop (measured: 1.1 ns against 0.17 ns per value).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["CHUNK", "accumulate", "all_finite", "compile_ahead", "scratch"]

#: interleaved values per chunk (4 kB of float64): a chunk of a channel's windowed
#: spectrum and of its sums stays in the first-level cache over the segments of a group
CHUNK = 512

#: compiled once per sample precision, cached on disk; releases the GIL (worker threads)
_jit = njit(nogil=True, cache=True, boundscheck=False, error_model="numpy")


@_jit
def _edge(zr: NDArray[np.floating], n: int, taps: NDArray[np.float64], zero_dc: bool,
          k: int) -> tuple[float, float]:
    """Windowed value (re, im) of line ``k``, the convolution wrapping around the two-sided
    DFT of length ``n`` (negative lines are conjugates); line 0 taken as 0 if ``zero_dc``."""
    n_f = zr.shape[0] // 2
    M = taps.shape[0] - 1
    re = 0.0
    im = 0.0
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
    n2 = zr.shape[0]
    n_f = n2 // 2
    M = taps.shape[0] - 1
    k_lo = M + 1 if (M > 0 or zero_dc) else 0  # first line of the plain formula
    i0 = max(c0, 2 * k_lo)
    i1 = min(c1, n2 - 2 * M)
    if i1 > i0:
        a = zr[i0 - 2 * M : i1 + 2 * M]
        y = x[i0 - c0 : i1 - c0]
        w = i1 - i0
        t0 = taps[0]
        if M == 0:
            for j in range(w):
                y[j] = t0 * a[j]
        elif M == 1:
            t1 = taps[1]
            for j in range(w):
                y[j] = t0 * a[j + 2] + t1 * (a[j] + a[j + 4])
        else:
            for j in range(w):
                y[j] = t0 * a[j + 2 * M]
            for m in range(1, M + 1):
                t = taps[m]
                lo = a[2 * (M - m) :]
                hi = a[2 * (M + m) :]
                for j in range(w):
                    y[j] += t * (lo[j] + hi[j])
    for k in range(c0 // 2, min(k_lo, c1 // 2)):
        x[2 * k - c0], x[2 * k + 1 - c0] = _edge(zr, n, taps, zero_dc, k)
    for k in range(max(n_f - M, c0 // 2), c1 // 2):
        x[2 * k - c0], x[2 * k + 1 - c0] = _edge(zr, n, taps, zero_dc, k)


@_jit
def accumulate(zref: NDArray[np.floating], zown: NDArray[np.floating], n: int,
               taps: NDArray[np.float64], zero_dc: bool, row0: int, P: NDArray[np.float64],
               Q: NDArray[np.float64], fg: NDArray[np.float64],
               x: NDArray[np.float64]) -> None:
    """Add one group of segments to the sums.

    Parameters
    ----------
    zref, zown : (n_ref, n_seg, 2 n_f), (n_own, n_seg, 2 n_f) float32 or float64
        Interleaved spectra of the group's segments (DFT length ``n``) of the references
        and of the channels summed; not yet windowed if ``taps`` has more than one value.
    taps : (M + 1,) float64
        The window in frequency, ``rfft(window)[:M + 1] / n`` (real: a periodic, even
        window); ``[1.0]`` for spectra already windowed.
    zero_dc : bool
        Remove each segment's mean (line 0 of the un-windowed spectrum taken as 0).
    P, Q : (2 n_ref, n_ch, n_f), (n_ch, n_f) float64
        Sums; ``zown[b]`` adds to rows ``row0 + b``.
    fg : (>= n_seg, 2 n_ref, n_f) float64, x : (2 n_f,) float64
        Scratch: the windowed references (real, imaginary parts), a windowed spectrum.
    """
    n_seg, n2 = zown.shape[1], zown.shape[2]
    n_f = n2 // 2
    n_ref = zref.shape[0]
    M = taps.shape[0] - 1
    t0 = taps[0]
    t1 = taps[1] if M > 0 else 0.0
    for s in range(n_seg):  # windowed references, whole length, split in (re, im)
        for a in range(n_ref):
            _window_chunk(zref[a, s], n, taps, zero_dc, 0, n2, x)
            fr, fi = fg[s, 2 * a], fg[s, 2 * a + 1]
            for k in range(n_f):
                fr[k] = x[2 * k]
                fi[k] = x[2 * k + 1]
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
def all_finite(x: NDArray[np.floating]) -> bool:
    """Whether every sample of ``x`` (2-D) is finite: ``v - v`` is 0 for a finite value
    (however large: nothing can overflow) and NaN otherwise, and an or-reduction of
    comparisons vectorises (twice as fast as numpy's ``isfinite(sum)``, which can also
    overflow)."""
    for i in range(x.shape[0]):
        row = x[i]
        bad = False
        for j in range(row.shape[0]):
            v = row[j]
            bad |= (v - v) != 0.0
        if bad:
            return False
    return True


def scratch(n_seg: int, n_ref: int, n_f: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The scratch ``fg``, ``x`` of :func:`accumulate` for up to ``n_seg`` segments of
    ``n_ref`` references and ``n_f`` lines."""
    return np.empty((n_seg, 2 * n_ref, n_f)), np.empty(max(CHUNK, 2 * n_f))


def compile_ahead() -> None:
    """Compile (or load from numba's on-disk cache) the kernels for both sample precisions,
    so that the first live spectrum does not wait for it (``make`` calls this at set-up)."""
    for real in (np.float32, np.float64):
        z = np.zeros((1, 1, 8), real)
        accumulate(z, z, 6, np.ones(1), False, 0, np.zeros((2, 1, 4)), np.zeros((1, 4)),
                   *scratch(1, 1, 4))
        x = np.zeros((2, 4), real)
        for _ in range(2):  # contiguous blocks and any other layout, writeable or not
            all_finite(x)
            all_finite(x[:, ::2])
            x.setflags(write=False)
