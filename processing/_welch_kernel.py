"""Compiled (numba) kernel of the Welch accumulation: window in frequency, products, sums;
and :func:`work_block`, a worker thread's whole share of a block (check, tail, FFT, sums).

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

import ctypes
import sys
from typing import Any

import numpy as np
import rocket_fft  # noqa: F401  (teaches numba scipy.fft: pocketfft, called without the GIL)
import scipy.fft
from llvmlite import binding as llvm
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic
from numpy.lib.stride_tricks import as_strided
from numpy.typing import NDArray

__all__ = ["CHUNK", "accumulate", "all_finite", "compile_ahead", "scratch", "work_block"]

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


# ----------------------------------------------------------------------------------------------
# one worker's share of a block, from its check to its copy of the samples kept, without the GIL
# ----------------------------------------------------------------------------------------------
#: a worker's report on its channels of a block, in ``flags[worker]`` (0: not yet)
FINITE, NOT_FINITE = 1, 2
#: what :func:`work_block` returns
DONE, STOPPED, TIMED_OUT = 0, 1, 2
#: spins before a worker gives up waiting for another, the last element of ``flags`` (each
#: yields the CPU, about 1 us on an idle machine: tens of seconds; a worker never waits that
#: long unless another is gone)
PATIENCE = 20_000_000
_TIGHT_SPINS = 2000


def _load_acquire_ir(typingctx, arr, i):
    """``arr[i]`` (int64) read atomically with acquire order: what another thread wrote
    before its :func:`_store_release` of ``arr[i]`` is visible after it; never hoisted out
    of a loop."""
    sig = types.int64(arr, i)

    def codegen(context, builder, signature, args):
        aty = signature.args[0]
        ary = context.make_array(aty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aty, ary, [args[1]], wraparound=False)
        return builder.load_atomic(ptr, "acquire", 8)

    return sig, codegen


_load_acquire: Any = intrinsic(_load_acquire_ir)


def _store_release_ir(typingctx, arr, i, v):
    """``arr[i] = v`` (int64) atomically with release order (see :func:`_load_acquire`)."""
    sig = types.void(arr, i, types.int64)

    def codegen(context, builder, signature, args):
        aty = signature.args[0]
        ary = context.make_array(aty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aty, ary, [args[1]], wraparound=False)
        builder.store_atomic(args[2], ptr, "release", 8)
        return context.get_dummy_value()

    return sig, codegen


_store_release: Any = intrinsic(_store_release_ir)


#: the system call that lets another thread have this CPU, registered for the compiled code
#: under a name of our own (numba's cache keeps the name, resolved again at each start)
_YIELD = "insitu_yield_cpu"
_yield_fn = (ctypes.windll.kernel32.SwitchToThread if sys.platform == "win32"  # type: ignore[attr-defined]
             else ctypes.CDLL(None).sched_yield)
llvm.add_symbol(_YIELD, ctypes.cast(_yield_fn, ctypes.c_void_p).value)


def _yield_cpu_ir(typingctx):
    """``sched_yield()`` (``SwitchToThread()`` on Windows): let another thread have this
    CPU while waiting."""
    sig = types.int32()

    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(32), []),
                                            _YIELD)
        return builder.call(fn, [])

    return sig, codegen


_yield_cpu: Any = intrinsic(_yield_cpu_ir)


@_jit
def _wait(flags: NDArray[np.int64], i: int, abort: int) -> bool:
    """Wait until ``flags[i]`` is set; False if ``flags[abort]`` is set first (a worker
    failed) or after ``flags[-1]`` spins (then ``flags[abort]`` is set for the others)."""
    n = 0
    patience = flags[flags.shape[0] - 1]
    while _load_acquire(flags, i) == 0:
        if _load_acquire(flags, abort) != 0:
            return False
        n += 1
        if n > _TIGHT_SPINS:
            _yield_cpu()
            if n > patience:
                _store_release(flags, abort, TIMED_OUT)
                return False
    return _load_acquire(flags, abort) == 0


@_jit
def _stopped(flags: NDArray[np.int64], abort: int) -> int:
    """What a worker that stopped returns: TIMED_OUT if one gave up waiting, else STOPPED."""
    return TIMED_OUT if _load_acquire(flags, abort) == TIMED_OUT else STOPPED


@_jit
def _verdict(flags: NDArray[np.int64], n_workers: int) -> bool:
    """True once every worker has reported its channels finite; False as soon as one has
    not (or a worker failed)."""
    ok = True
    for k in range(n_workers):
        if not _wait(flags, k, n_workers):
            return False
        ok = ok and _load_acquire(flags, k) == FINITE
    return ok


@_jit
def _transform(seg: NDArray[np.floating], buf: NDArray[np.floating], win: NDArray[np.floating],
               dc_bins: NDArray[np.int64], dc_values: NDArray[np.complex128]) -> Any:
    """Spectra ``(k, n_seg, n_f)`` of the segments ``seg`` ``(k, n_seg, n)``: the FFT of the
    samples where they lie, or (``win`` not empty: a window applied in time) of the samples
    times ``win`` in ``buf``, each segment's mean then removed on the lines ``dc_bins`` of
    the window's spectrum (``dc_values``; none if no detrend)."""
    if win.shape[0] == 0:
        return scipy.fft.rfft(seg, axis=-1, workers=1)
    k, n_seg, n = seg.shape
    x = buf[: k * n_seg * n].reshape((k, n_seg, n))
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
def _group(src: Any, start: int, n_seg: int, gi: int, worker: int, n_workers: int, n: int,
           step: int, runs: Any, lead: Any, refs: Any, taps: Any, zero_dc: bool, win: Any,
           dc_bins: Any, dc_values: Any, P: Any, Q: Any, fg: Any, x: Any, buf: Any, zref: Any,
           flags: Any) -> bool:
    """One group: ``n_seg`` segments of ``src`` from sample ``start`` on, transformed and
    summed for the worker's rows. The first worker transforms the references and hands
    their spectra to the others in ``zref`` (``flags[2 n_workers + 1 + gi]`` set once they
    are in); nobody adds anything before every worker has reported its channels finite."""
    if start < 0 or start + (n_seg - 1) * step + n > src.shape[1]:
        raise ValueError("segments beyond the samples")
    s0, s1 = src.strides
    seg = as_strided(src[:, start:], shape=(src.shape[0], n_seg, n), strides=(s0, step * s1, s1))
    n_ref, n_f = refs.shape[0], n // 2 + 1
    zr = zref[gi, : n_ref * n_seg * n_f].reshape((n_ref, n_seg, n_f))
    real = src.dtype
    if worker == 0:
        if lead[0] >= 0:  # the references and the rows after them, one call
            z = _transform(seg[lead[0] : lead[1]], buf, win, dc_bins, dc_values)
            zr[:] = z[:n_ref]
            _store_release(flags, 2 * n_workers + 1 + gi, 1)
            if not _verdict(flags, n_workers):
                return False
            zv = z.view(real)
            accumulate(zv[:n_ref], zv, n, taps, zero_dc, lead[0], P, Q, fg, x)
        else:  # references apart: a call each
            for a in range(n_ref):
                zr[a] = _transform(seg[refs[a] : refs[a] + 1], buf, win, dc_bins, dc_values)[0]
            _store_release(flags, 2 * n_workers + 1 + gi, 1)
            if not _verdict(flags, n_workers):
                return False
            zrv = zr.view(real)
            for a in range(n_ref):
                accumulate(zrv, zrv[a : a + 1], n, taps, zero_dc, refs[a], P, Q, fg, x)
    for i in range(runs.shape[0]):
        lo, hi = runs[i, 0], runs[i, 1]
        z = _transform(seg[lo:hi], buf, win, dc_bins, dc_values)
        if not _verdict(flags, n_workers) or not _wait(flags, 2 * n_workers + 1 + gi, n_workers):
            return False
        accumulate(zr.view(real), z.view(real), n, taps, zero_dc, lo, P, Q, fg, x)
    return True


@_jit
def work_block(arr: Any, store: Any, dst: Any, n_tail: int, need: int, n_seg: int, n_head: int,
               n: int, step: int, G: int, own: Any, runs: Any, lead: Any, refs: Any, taps: Any,
               zero_dc: bool, win: Any, dc_bins: Any, dc_values: Any, P: Any, Q: Any, fg: Any,
               x: Any, buf: Any, zref: Any, flags: Any, worker: int, n_workers: int) -> int:
    """One worker's share of a block (see :func:`_share`), then its code + 1 in
    ``flags[n_workers + 1 + worker]``; the first worker (the calling thread) returns only
    once every worker has (or one failed): it waits here, without a wake-up through the
    system, rather than in Python for the others to return. It returns the block's code:
    DONE if every worker's is, else the highest (STOPPED, TIMED_OUT).

    ``flags``: each worker's report on its channels (FINITE, NOT_FINITE), the abort flag,
    each worker's code + 1, each group's "references ready", then the spins a worker waits
    for another before it gives up (PATIENCE).
    """
    code = _share(arr, store, dst, n_tail, need, n_seg, n_head, n, step, G, own, runs, lead,
                  refs, taps, zero_dc, win, dc_bins, dc_values, P, Q, fg, x, buf, zref, flags,
                  worker, n_workers)
    _store_release(flags, n_workers + 1 + worker, code + 1)
    if worker == 0:
        for k in range(1, n_workers):
            if not _wait(flags, n_workers + 1 + k, n_workers):
                return _stopped(flags, n_workers)
        for k in range(n_workers):  # the block's outcome: DONE only if every worker's is
            code = max(code, _load_acquire(flags, n_workers + 1 + k) - 1)
    return code


@_jit
def _share(arr: Any, store: Any, dst: Any, n_tail: int, need: int, n_seg: int, n_head: int,
           n: int, step: int, G: int, own: Any, runs: Any, lead: Any, refs: Any, taps: Any,
           zero_dc: bool, win: Any, dc_bins: Any, dc_values: Any, P: Any, Q: Any, fg: Any,
           x: Any, buf: Any, zref: Any, flags: Any, worker: int, n_workers: int) -> int:
    """One worker's share of a block ``arr`` (n_ch, n_new), start to end without the GIL.

    Its rows ``own`` (runs ``(lo, hi)``) of the block are checked (``flags[worker]``: FINITE
    or NOT_FINITE) and, if finite, their first ``need`` samples appended to the tail
    ``store[:, :n_tail]``. Then the block's ``n_seg`` complete segments, the first
    ``n_head`` starting in the tail, in groups of up to ``G`` per FFT call (group ``gi``
    uses ``zref[gi]``): the first worker transforms the references (``lead``: the rows of
    its call with them, ``(-1, -1)`` when they are not adjacent) and every worker its
    ``runs``, adding their products with the references to ``P``, ``Q``. Last, its rows of
    the samples not consumed go to ``dst``. ``flags[n_workers]`` set (by a failed
    worker's caller, or a worker that waited too long) stops every worker.

    Returns DONE, STOPPED (a block with a non-finite sample, or a worker failed: this
    worker added nothing, or only before the failure) or TIMED_OUT.
    """
    abort = n_workers
    tail = store[:, : n_tail + need]
    finite = True
    for i in range(own.shape[0]):
        if not all_finite(arr[own[i, 0] : own[i, 1]]):
            finite = False
            break
    if finite:
        for i in range(own.shape[0]):
            tail[own[i, 0] : own[i, 1], n_tail:] = arr[own[i, 0] : own[i, 1], :need]
    _store_release(flags, worker, FINITE if finite else NOT_FINITE)
    gi = 0
    for i in range(0, n_head, G):
        if not _group(tail, i * step, min(G, n_head - i), gi, worker, n_workers, n, step, runs,
                      lead, refs, taps, zero_dc, win, dc_bins, dc_values, P, Q, fg, x, buf,
                      zref, flags):
            return _stopped(flags, abort)
        gi += 1
    for i in range(n_head, n_seg, G):
        if not _group(arr, i * step - n_tail, min(G, n_seg - i), gi, worker, n_workers, n, step,
                      runs, lead, refs, taps, zero_dc, win, dc_bins, dc_values, P, Q, fg, x,
                      buf, zref, flags):
            return _stopped(flags, abort)
        gi += 1
    if not _verdict(flags, n_workers):
        return _stopped(flags, abort)
    if n_seg:  # the samples from the first unconsumed one on, for the next block
        start = n_seg * step
        n_new = arr.shape[1]
        for i in range(own.shape[0]):
            for r in range(own[i, 0], own[i, 1]):
                if start < n_tail + need:
                    k = n_tail + need - start
                    dst[r, :k] = tail[r, start:]
                    dst[r, k : k + n_new - need] = arr[r, need:]
                else:
                    dst[r, : n_tail + n_new - start] = arr[r, start - n_tail :]
    return DONE


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
        n, n_f = 8, 5
        cplx = np.result_type(real, np.complex64)
        for block in (np.ones((3, 24), real), np.ones((3, 48), real)[:, ::2]):  # any layout
            for win in (np.empty(0, real), np.ones(n, real)):  # window in frequency, in time
                store = np.zeros((3, 2 * n), real)
                work_block(block, store, store.copy(), 0, 0, 5, 0, n, 4, 4,
                           np.array([[0, 3]], np.int64), np.array([[1, 3]], np.int64),
                           np.array([0, 1], np.int64), np.array([0], np.int64), np.ones(1),
                           False, win, np.array([0], np.int64), np.ones(1, np.complex128),
                           np.zeros((2, 3, n_f)), np.zeros((3, n_f)), *scratch(4, 1, n_f),
                           np.empty(3 * 4 * n, real), np.empty((2, 4 * n_f), cplx),
                           # flags of one worker, two groups (see work_block)
                           np.array([0, 0, 0, 0, 0, PATIENCE], np.int64), 0, 1)
