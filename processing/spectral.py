"""Cross- and auto-spectral densities and the FRF estimators H1, H2 and Hv.

Convention (``PITFALLS.md``): ``S_xy = conj(X) Y``, so ``S_fx`` equals
``scipy.signal.csd(force, response)`` and ``H1 = S_fx / S_ff``. Spectra are
one-sided densities scaled exactly as :func:`scipy.signal.csd` (``'density'``:
unit**2/Hz, or ``'spectrum'``: unit**2), with Welch averaging over segments of
``nperseg`` samples overlapping by ``noverlap``, each detrended (constant) and
windowed (periodic Hann by default). Time is the last axis of every input.

:class:`SpectralAccumulator` takes samples block by block and keeps only the
samples not yet consumed, so a live display, a long recording and a replay all
go through the same code. Every complete segment is used as soon as it is in,
each value summed over the segments in order, so the result is bit for bit the
same whatever the block sizes and the number of threads.

Several references (shakers) give ``H = G_xf G_ff^-1`` per line and the
multiple coherence of each response.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from processing import _welch_kernel as _kernel
from processing.data import ESTIMATORS
from processing.windows import window_samples

__all__ = ["ESTIMATORS", "CrossSpectra", "SpectralAccumulator", "SpectralError", "coherence",
           "combine", "free_cores", "frf", "h1", "h2", "hv", "ordinary_coherence",
           "record_spectra", "welch_spectra"]

Scaling = Literal["density", "spectrum"]


class SpectralError(ValueError):
    """Bad spectral-analysis parameters or data; the message names the value and what is allowed."""


@dataclass(frozen=True)
class CrossSpectra:
    """Averaged one-sided spectra between reference (force) and response channels.

    Attributes
    ----------
    freq : (n_f,) Hz
    Sff : (n_ref, n_ref, n_f) complex
        ``Sff[a, b] = <conj(F_a) F_b>``, force unit**2/Hz (or unit**2).
    Sfx : (n_ref, n_resp, n_f) complex
        ``Sfx[a, i] = <conj(F_a) X_i>`` (``scipy.signal.csd(f_a, x_i)``).
    Sxx : (n_resp, n_f) float
        Auto-spectra of the responses.
    n_averages : int
        Number of segments (or records) averaged.
    ref_channels, resp_channels : channel indices in the input data.
    """

    freq: NDArray[np.float64]
    Sff: NDArray[np.complex128]
    Sfx: NDArray[np.complex128]
    Sxx: NDArray[np.float64]
    n_averages: int
    ref_channels: tuple[int, ...]
    resp_channels: tuple[int, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "freq", np.asarray(self.freq, dtype=float).ravel())
        n_f, n_ref, n_resp = self.freq.size, len(self.ref_channels), len(self.resp_channels)
        for name, dtype, shape in (("Sff", np.complex128, (n_ref, n_ref, n_f)),
                                   ("Sfx", np.complex128, (n_ref, n_resp, n_f)),
                                   ("Sxx", np.float64, (n_resp, n_f))):
            arr = np.asarray(getattr(self, name), dtype=dtype)
            if arr.shape != shape:
                raise SpectralError(f"{name} has shape {arr.shape}, expected {shape}")
            object.__setattr__(self, name, arr)
        if n_ref < 1:
            raise SpectralError("at least one reference channel is needed")
        if self.n_averages < 0:
            raise SpectralError(f"n_averages must be >= 0, got {self.n_averages}")
        object.__setattr__(self, "ref_channels", tuple(int(c) for c in self.ref_channels))
        object.__setattr__(self, "resp_channels", tuple(int(c) for c in self.resp_channels))

    @property
    def n_ref(self) -> int:
        return len(self.ref_channels)

    @property
    def n_resp(self) -> int:
        return len(self.resp_channels)


def combine(a: CrossSpectra, b: CrossSpectra) -> CrossSpectra:
    """Average of two sets of spectra weighted by their numbers of averages.

    Both must share frequencies and channel roles (e.g. two runs at one excitation point).
    """
    if a.freq.shape != b.freq.shape or not np.array_equal(a.freq, b.freq):
        raise SpectralError("cannot combine spectra with different frequency lines")
    if a.ref_channels != b.ref_channels or a.resp_channels != b.resp_channels:
        raise SpectralError("cannot combine spectra with different reference/response channels")
    n = a.n_averages + b.n_averages
    if n == 0:
        return a
    wa, wb = a.n_averages / n, b.n_averages / n
    return CrossSpectra(a.freq, wa * a.Sff + wb * b.Sff, wa * a.Sfx + wb * b.Sfx,
                        wa * a.Sxx + wb * b.Sxx, n, a.ref_channels, a.resp_channels)


def _solve_refs(sp: CrossSpectra, rhs: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """``Sff^-1 rhs`` per line, (n_ref, k, n_f) -> (n_ref, k, n_f); NaN where Sff is singular."""
    if sp.n_ref == 1:
        with np.errstate(divide="ignore", invalid="ignore"):
            return rhs / sp.Sff[0, 0]
    A = np.moveaxis(sp.Sff, -1, 0)  # (n_f, n_ref, n_ref)
    B = np.moveaxis(np.asarray(rhs, dtype=np.complex128), -1, 0)
    # Sff is Hermitian positive semi-definite: a relative eigenvalue floor marks singular lines
    ev = np.linalg.eigvalsh(A)
    bad = ev[:, 0] <= ev[:, -1] * 1e-12
    A = np.where(bad[:, None, None], np.eye(sp.n_ref), A)
    X = np.asarray(np.linalg.solve(A, B), dtype=np.complex128)
    X[bad] = np.nan
    return np.moveaxis(X, 0, -1)


def h1(sp: CrossSpectra) -> NDArray[np.complex128]:
    """H1 estimate (n_resp, n_ref, n_f): ``S_fx / S_ff``; ``G_xf G_ff^-1`` for several references.

    Unbiased by noise on the responses. Units: response unit per force unit.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> f = rng.standard_normal(4096)
    >>> x = 2.0 * f
    >>> sp = welch_spectra(np.stack([f, x]), fs=1000.0, nperseg=256)
    >>> bool(np.allclose(h1(sp)[0, 0, 1:], 2.0))
    True
    """
    # Sfx = Sff H^T  ->  H = (Sff^-1 Sfx)^T
    return np.swapaxes(_solve_refs(sp, sp.Sfx), 0, 1)


def h2(sp: CrossSpectra) -> NDArray[np.complex128]:
    """H2 estimate (n_resp, 1, n_f): ``S_xx / S_xf``, unbiased by noise on the force.

    Defined for one reference only; use H1 or Hv with several references.
    """
    if sp.n_ref != 1:
        raise SpectralError(f"H2 needs exactly one reference, got {sp.n_ref}: "
                            "use estimator 'H1' or 'Hv'")
    with np.errstate(divide="ignore", invalid="ignore"):
        return (sp.Sxx / np.conj(sp.Sfx[0]))[:, None, :]


def hv(sp: CrossSpectra) -> NDArray[np.complex128]:
    """Hv (total least squares) estimate (n_resp, n_ref, n_f).

    For each response and line, the eigenvector of the smallest eigenvalue of the
    Hermitian matrix ``<z z^H>``, ``z = [F_1 .. F_n, X_i]``, normalised to ``-1`` on
    the response. With one reference this is ``S_fx / (S_ff - lambda_min)``, between
    H1 and H2.
    """
    n_ref, n_resp, n_f = sp.n_ref, sp.n_resp, sp.freq.size
    C = np.empty((n_resp, n_f, n_ref + 1, n_ref + 1), dtype=np.complex128)
    # C[a, b] = <F_a conj(F_b)> = Sff[b, a]; C[a, n] = conj(Sfx[a]); C[n, n] = Sxx
    C[:, :, :n_ref, :n_ref] = np.moveaxis(sp.Sff, -1, 0).swapaxes(-1, -2)[None]
    C[:, :, :n_ref, n_ref] = np.moveaxis(np.conj(sp.Sfx), 0, -1)
    C[:, :, n_ref, :n_ref] = np.moveaxis(sp.Sfx, 0, -1)
    C[:, :, n_ref, n_ref] = sp.Sxx
    _, V = np.linalg.eigh(C)
    u = V[..., 0]  # (n_resp, n_f, n_ref + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        H = -np.conj(u[..., :n_ref] / u[..., n_ref:])
    return np.moveaxis(H, 1, -1)


def ordinary_coherence(sp: CrossSpectra) -> NDArray[np.float64]:
    """Ordinary coherence of each response with each reference, (n_resp, n_ref, n_f), in [0, 1]."""
    Sff = np.real(np.diagonal(sp.Sff, axis1=0, axis2=1)).T  # (n_ref, n_f)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.abs(sp.Sfx) ** 2 / (Sff[:, None, :] * sp.Sxx[None])
    return np.clip(np.swapaxes(g, 0, 1), 0.0, 1.0)


def coherence(sp: CrossSpectra) -> NDArray[np.float64]:
    """Coherence of each response with all references together, (n_resp, n_f), in [0, 1].

    Ordinary coherence ``|S_fx|^2 / (S_ff S_xx)`` with one reference; with several,
    the multiple coherence ``S_xf S_ff^-1 S_fx / S_xx``: the part of each response's
    power explained linearly by the references.
    """
    Y = _solve_refs(sp, sp.Sfx)  # (n_ref, n_resp, n_f)
    num = np.real(np.sum(np.conj(sp.Sfx) * Y, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        g = num / sp.Sxx
    return np.clip(g, 0.0, 1.0)


def frf(
    sp: CrossSpectra, estimator: str = "H1"
) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """FRFs (n_resp, n_ref, n_f) by ``estimator`` and coherence of the same shape.

    The coherence is the ordinary one with one reference and the multiple
    coherence of each response (repeated over the references) with several,
    ready for :class:`processing.data.FRFSet`.
    """
    funcs: dict[str, Callable[[CrossSpectra], NDArray[np.complex128]]] = {
        "h1": h1, "h2": h2, "hv": hv,
    }
    try:
        fn = funcs[estimator.lower()]
    except KeyError:
        raise SpectralError(f"unknown estimator {estimator!r}: choose one of "
                            f"{', '.join(ESTIMATORS)}") from None
    H = fn(sp)
    coh = np.broadcast_to(coherence(sp)[:, None, :], H.shape).copy()
    return H, coh


def _channel_roles(n_ch: int, references: Sequence[int], responses: Sequence[int] | None
                   ) -> tuple[tuple[int, ...], tuple[int, ...]]:
    refs = tuple(int(r) for r in references)
    resps = tuple(c for c in range(n_ch) if c not in refs) if responses is None else tuple(
        int(r) for r in responses)
    every = refs + resps
    if not refs:
        raise SpectralError("give at least one reference (force) channel")
    if any(c < 0 or c >= n_ch for c in every):
        raise SpectralError(f"channel indices {every} out of range for {n_ch} channels")
    if len(set(every)) != len(every):
        raise SpectralError(f"reference {refs} and response {resps} channels must be distinct")
    return refs, resps


def _averaged_spectra(freq: NDArray[np.float64], nfft: int, norm: float, n_avg: int,
                      P: NDArray[np.float64], Q: NDArray[np.float64], refs: tuple[int, ...],
                      resps: tuple[int, ...]) -> CrossSpectra:
    """One-sided spectra, divided by ``norm`` and averaged over ``n_avg`` segments (or records)
    of ``nfft`` samples, from the sums of :func:`processing._welch_kernel.accumulate`:
    P (2 n_ref, n_ch, n_f), Q (n_ch, n_f)."""
    scale = np.full(freq.size, 2.0 / norm)
    scale[0] = 1.0 / norm
    if nfft % 2 == 0:
        scale[-1] = 1.0 / norm
    scale /= n_avg
    cross = np.empty((P.shape[0] // 2, *P.shape[1:]), np.complex128)
    cross.real, cross.imag = P[0::2], P[1::2]
    return CrossSpectra(freq, cross[:, list(refs)] * scale, cross[:, list(resps)] * scale,
                        Q[list(resps)] * scale, n_avg, refs, resps)


#: the window of spectra already windowed in time
_NO_TAPS = np.ones(1)
#: one compiled parallel call at a time: numba's fallback thread pool (without OpenMP or
#: TBB) aborts the process when two threads launch parallel work at once
_LAUNCH = threading.Lock()
#: the most lines a window may spread over to be applied in frequency
_MAX_TAPS = 8


def free_cores() -> int:
    """Cores free for this process's threads now: the cores it may run on less the runnable
    threads but the caller (``/proc/loadavg``'s fourth field; below 1 when more threads than
    cores want to run); every core where that is not known (not Linux)."""
    try:
        with open("/proc/loadavg") as fh:
            runnable = int(fh.read().split()[3].partition("/")[0])
        return len(os.sched_getaffinity(0)) - (runnable - 1)
    except (AttributeError, OSError, IndexError, ValueError):
        return os.cpu_count() or 1


def _cosine_taps(win: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """The window as a short convolution in frequency, ``rfft(win)[:M + 1] / n``, when it is
    a periodic cosine sum of at most ``_MAX_TAPS`` terms to 1e-13 of its peak (Hann, Hamming,
    Blackman, flat top, rectangular, as :func:`scipy.signal.get_window` gives them); else None
    (the window is then applied to the samples)."""
    n = win.size
    W = np.fft.rfft(win) / n
    M = int(np.flatnonzero(np.abs(W) > 1e-13 * np.abs(W).max())[-1])
    if M > _MAX_TAPS or 2 * M + 1 > n or np.abs(W[: M + 1].imag).max() > 1e-13 * abs(W[0]):
        return None
    taps = np.ascontiguousarray(W[: M + 1].real)
    m = np.arange(1, M + 1)[:, None]
    rebuilt = taps[0] + 2 * np.sum(taps[1:, None] * np.cos(2 * np.pi * m * np.arange(n) / n),
                                   axis=0)
    if np.abs(rebuilt - win).max() > 1e-13 * np.abs(win).max():
        return None
    return taps


class SpectralAccumulator:
    """Welch cross-spectral accumulation over blocks of samples, memory bounded by the block size.

    Parameters
    ----------
    fs : float
        Sample rate, Hz.
    nperseg : int
        Segment length, samples; the line spacing is ``fs / nperseg`` Hz.
    noverlap : int, optional
        Overlap of consecutive segments, samples (default ``nperseg // 2``).
    window : str, tuple or array, optional
        Window for :func:`scipy.signal.get_window` (periodic), or the samples themselves.
    detrend : {'constant', False}
        Remove each segment's mean (as :func:`scipy.signal.csd`), or not.
    references : sequence of int
        Channel indices of the force(s) (default channel 0).
    responses : sequence of int, optional
        Channel indices of the responses (default: every other channel).
    scaling : {'density', 'spectrum'}
        Unit**2/Hz or unit**2, as in scipy.
    group : int, optional
        Most segments of a channel per FFT call (default 16 for float32 samples, 4 else).
    workers : int, optional
        Most threads sharing the channels, at most (and by default) numba's
        ``NUMBA_NUM_THREADS`` (the number of cores unless set). Each block takes as many
        as :func:`free_cores` finds free when it arrives, at least one: a thread sharing
        its core with another process holds up every other at the end of the block.

    Notes
    -----
    Float32 samples are transformed in single precision, anything else in double; the
    products are formed and summed in float64 (:mod:`processing._welch_kernel`). Segments
    are taken as :func:`scipy.signal.csd` takes them: from the first sample on, every
    ``nperseg - noverlap`` samples; trailing samples that do not fill a segment wait for
    the next block. A window that is a short cosine sum (Hann, Hamming, Blackman, flat
    top, rectangular) is applied in frequency, as a convolution over ``2 M + 1`` lines,
    and the mean removal by zeroing the un-windowed spectrum's line 0; any other window
    is applied to the samples. Each value is summed over the segments in order: the same
    bits whatever the block boundaries, ``group`` and ``workers`` (tested).

    Memory: two buffers of ``2 nperseg`` samples per channel holding the samples not yet
    consumed, the sums (``3 n_ch nperseg`` values for one reference), the references'
    spectra of up to 65 segments, and each FFT call's spectra (``group nperseg`` values).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> data = rng.standard_normal((3, 20000))
    >>> acc = SpectralAccumulator(fs=1000.0, nperseg=512)
    >>> for block in np.array_split(data, 7, axis=-1):
    ...     acc.update(block)
    >>> sp = acc.spectra()
    >>> sp.Sfx.shape, acc.n_averages
    ((1, 2, 257), 77)
    """

    def __init__(
        self,
        fs: float,
        nperseg: int,
        noverlap: int | None = None,
        *,
        window: str | tuple[object, ...] | ArrayLike = "hann",
        detrend: Literal["constant", False] = "constant",
        references: Sequence[int] = (0,),
        responses: Sequence[int] | None = None,
        scaling: Scaling = "density",
        group: int | None = None,
        workers: int | None = None,
    ) -> None:
        if not np.isfinite(fs) or fs <= 0:
            raise SpectralError(f"sample rate must be positive, got {fs}")
        nperseg = int(nperseg)
        if nperseg < 2:
            raise SpectralError(f"nperseg must be >= 2, got {nperseg}")
        noverlap = nperseg // 2 if noverlap is None else int(noverlap)
        if not 0 <= noverlap < nperseg:
            raise SpectralError(f"noverlap must be in [0, nperseg), got {noverlap}")
        if detrend not in ("constant", False):
            raise SpectralError(f"detrend must be 'constant' or False, got {detrend!r}")
        if scaling not in ("density", "spectrum"):
            raise SpectralError(f"scaling must be 'density' or 'spectrum', got {scaling!r}")
        if (group is not None and group < 1) or (workers is not None and workers < 1):
            raise SpectralError(f"group and workers must be >= 1, got {group}, {workers}")
        win = window_samples(window, nperseg)
        if win.shape != (nperseg,):
            raise SpectralError(f"window has shape {win.shape}, expected ({nperseg},)")
        self.fs, self.nperseg, self.noverlap = float(fs), nperseg, noverlap
        self.step = nperseg - noverlap
        self.window, self.detrend, self.scaling = win, detrend, scaling
        self._group = None if group is None else int(group)
        most = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
        self.workers = most if workers is None else min(int(workers), most)
        self._references = tuple(int(r) for r in references)
        self._responses = None if responses is None else tuple(int(r) for r in responses)
        # the window in frequency (taps; the mean removed by zero_dc), or on the samples
        # (the mean removed on the lines dc_bins of its spectrum): see add_block
        self._taps = _cosine_taps(win)
        self._zero_dc = self._taps is not None and detrend == "constant"
        W = np.fft.rfft(win)
        time_dc = self._taps is None and detrend == "constant"
        bins = np.flatnonzero((np.abs(W) > 1e-12 * np.abs(W[0])) & time_dc)
        self._dc_bins, self._dc_values = bins, W[bins]
        self.freq = np.asarray(np.fft.rfftfreq(nperseg, 1.0 / fs), dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        """Forget every sample and average (keeps the parameters)."""
        self._tail: NDArray[np.floating] | None = None
        self._dtype: np.dtype[np.floating] | None = None
        self._n_ch = self._n_seg = self._n_samples = 0
        self._refs: tuple[int, ...] = ()
        self._resps: tuple[int, ...] = ()

    @property
    def n_averages(self) -> int:
        """Segments averaged so far (every complete segment received)."""
        return self._n_seg

    @property
    def group(self) -> int:
        """Most segments of a channel per FFT call."""
        if self._group is not None:
            return self._group
        return 16 if self._dtype == np.float32 else 4

    @property
    def n_samples(self) -> int:
        """Samples per channel received so far."""
        return self._n_samples

    def _first_block(self, block: NDArray[np.generic]) -> None:
        self._n_ch = n_ch = block.shape[0]
        refs, self._resps = _channel_roles(n_ch, self._references, self._responses)
        self._refs, n_ref, n_f = refs, len(refs), self.freq.size
        dtype = self._dtype = np.dtype(np.float32 if block.dtype == np.float32 else np.float64)
        # two buffers taking turns holding the tail (a prefix of the first): fewer than
        # nperseg samples, and fewer than nperseg appended to it (see update)
        self._stores = [np.empty((n_ch, 2 * self.nperseg), dtype) for _ in range(2)]
        self._tail = self._stores[0][:, :0]
        rest = [c for c in range(n_ch) if c not in refs]  # in runs of adjacent rows (add_block)
        cuts = [i for i in range(1, len(rest)) if rest[i] != rest[i - 1] + 1 or i % 4 == 0]
        self._runs = np.array([(r, r + 1) for r in refs] + [
            (rest[a], rest[b - 1] + 1) for a, b in itertools.pairwise([0, *cuts, len(rest)])])
        self._ref_of = np.full(n_ch, -1)  # each row's index among the references
        self._ref_of[list(refs)] = np.arange(n_ref)
        self._win = np.empty(0, dtype) if self._taps is not None else self.window.astype(dtype)
        self._P, self._Q = np.zeros((2 * n_ref, n_ch, n_f)), np.zeros((n_ch, n_f))
        self._zr = np.empty((n_ref, _kernel.BATCH + 1, 2 * n_f), dtype)  # scratch of add_block
        self._fg = np.empty((_kernel.BATCH + 1, 2 * n_ref, n_f))

    def _admit(self, block: ArrayLike) -> NDArray[np.floating]:
        """``block`` checked, as the kernel takes it (the accumulator's sample type, and
        writeable: copied if not, never written)."""
        arr = np.asarray(block)
        if arr.ndim != 2:
            raise SpectralError(f"a block must have shape (n_channels, n_samples), got {arr.shape}")
        if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
            raise SpectralError(f"samples must be real numbers, got dtype {arr.dtype}")
        if self._tail is None:
            self._first_block(arr)
        if arr.shape[0] != self._n_ch:
            raise SpectralError(f"block has {arr.shape[0]} channels, expected {self._n_ch}")
        arr = arr.astype(self._dtype, copy=False)
        return arr if arr.flags.writeable else arr.copy()

    def update(self, block: ArrayLike) -> None:
        """Add a block of samples (n_ch, n); any n, including 0. Float32 stays float32.

        Raises :class:`SpectralError` for a block of another shape or type, or with a NaN
        or infinite sample (nothing of it is added).
        """
        arr = self._admit(block)
        assert self._tail is not None
        n_tail, n_new = self._tail.shape[-1], arr.shape[-1]
        step, N = self.step, self.nperseg
        if n_new > _kernel.BATCH * step:  # in parts of at most BATCH + 1 segments, once checked
            if not _kernel.all_finite(arr):
                raise SpectralError("block contains NaN or infinite samples; nothing was added")
            for k in range(0, n_new, _kernel.BATCH * step):
                self.update(arr[:, k : k + _kernel.BATCH * step])
            return
        avail = n_tail + n_new
        n_seg = 0 if avail < N else (avail - N) // step + 1  # every complete segment
        # segments starting in the tail are read there once the block's first samples they
        # need are appended to it (all of it if no segment is complete); the others in place
        n_head = min(n_seg, -(-n_tail // step))
        need = n_new if n_seg == 0 else (max(0, (n_head - 1) * step + N - n_tail) if n_head else 0)
        with _LAUNCH:
            threads = numba.get_num_threads()
            numba.set_num_threads(max(1, min(self.workers, free_cores())))
            chunk = numba.set_parallel_chunksize(1)  # the runs handed out one at a time
            try:
                finite = _kernel.add_block(
                    arr, self._stores[0], self._stores[1], n_tail, need, n_seg, n_head, N, step,
                    self.group, self._runs, self._ref_of,
                    _NO_TAPS if self._taps is None else self._taps, self._zero_dc, self._win,
                    self._dc_bins, self._dc_values, self._P, self._Q, self._zr, self._fg)
            finally:
                numba.set_parallel_chunksize(chunk)
                numba.set_num_threads(threads)
        if not finite:
            raise SpectralError("block contains NaN or infinite samples; nothing was added")
        self._n_samples += n_new
        if n_seg:
            self._n_seg += n_seg
            self._stores.reverse()
        self._tail = self._stores[0][:, : avail - n_seg * step]

    def spectra(self) -> CrossSpectra:
        """The current averaged spectra (the accumulator goes on accepting blocks).

        Raises
        ------
        SpectralError
            If not one complete segment has been received yet.
        """
        if self._n_seg == 0 or self._tail is None:
            raise SpectralError(f"no complete segment yet: {self._n_samples} samples per "
                                f"channel received, {self.nperseg} needed")
        w = self.window
        norm = self.fs * np.sum(w**2) if self.scaling == "density" else np.sum(w) ** 2
        return _averaged_spectra(self.freq, self.nperseg, float(norm), self._n_seg, self._P,
                                 self._Q, self._refs, self._resps)


def welch_spectra(data: ArrayLike, fs: float, nperseg: int, noverlap: int | None = None,
                  **kwargs: object) -> CrossSpectra:
    """Spectra of ``data`` (n_ch, n) at ``fs`` Hz by a one-shot :class:`SpectralAccumulator`
    (keyword arguments: its own)."""
    acc = SpectralAccumulator(fs, nperseg, noverlap, **kwargs)  # type: ignore[arg-type]
    acc.update(data)
    return acc.spectra()


def record_spectra(
    records: ArrayLike,
    fs: float,
    windows: ArrayLike | None = None,
    *,
    references: Sequence[int] = (0,),
    responses: Sequence[int] | None = None,
) -> CrossSpectra:
    """Spectra averaged over separate records (hits, bursts, periods), no overlap, no detrend.

    ``records`` (n_rec, n_ch, n): one record per hit/burst/period, all channels, sampled at
    ``fs`` Hz; ``windows`` (broadcastable to the records: one for all, one per channel or
    one per record and channel; rectangular by default): the force and exponential
    windows; ``references``, ``responses``: as for :class:`SpectralAccumulator`. Scaled as
    energy densities ``2 conj(X) Y / (fs n)`` (one-sided): with transients only ratios
    (FRFs, coherence) are meaningful.
    """
    rec = np.asarray(records)
    if rec.ndim != 3:
        raise SpectralError(f"records must have shape (n_rec, n_ch, n), got {rec.shape}")
    if rec.shape[0] == 0:
        raise SpectralError("no record to average")
    if not np.all(np.isfinite(rec)):
        raise SpectralError("records contain NaN or infinite samples")
    dtype = np.float32 if rec.dtype == np.float32 else np.float64
    n_rec, n_ch, n = rec.shape
    refs, resps = _channel_roles(n_ch, references, responses)
    x: NDArray[np.floating] = rec.astype(dtype, copy=True)
    if windows is not None:
        w: NDArray[np.floating] = np.asarray(windows, dtype=dtype)
        try:
            x *= w
        except ValueError:
            raise SpectralError(
                f"windows of shape {w.shape} do not broadcast to the records {rec.shape}"
            ) from None
    Z = np.ascontiguousarray(scipy.fft.rfft(x, axis=-1, overwrite_x=True).swapaxes(0, 1))
    n_f = Z.shape[-1]
    P, Q = np.zeros((2 * len(refs), n_ch, n_f)), np.zeros((n_ch, n_f))
    fg, buf = np.empty((n_rec, 2 * len(refs), n_f)), np.empty(max(_kernel.CHUNK, 2 * n_f))
    for a, r in enumerate(refs):
        _kernel.window_ref(Z[r].view(x.dtype), n, _NO_TAPS, False, a, fg, buf)
    _kernel.accumulate(fg, Z.view(x.dtype), n, _NO_TAPS, False, 0, P, Q, buf)
    freq = np.asarray(np.fft.rfftfreq(n, 1.0 / fs), dtype=np.float64)
    return _averaged_spectra(freq, n, fs * n, n_rec, P, Q, refs, resps)
