"""Cross- and auto-spectral densities and the FRF estimators H1, H2 and Hv.

Convention (``PITFALLS.md``): ``S_xy = conj(X) Y``, so ``S_fx`` equals
``scipy.signal.csd(force, response)`` and ``H1 = S_fx / S_ff``. Spectra are
one-sided densities scaled exactly as :func:`scipy.signal.csd` (``'density'``:
unit**2/Hz, or ``'spectrum'``: unit**2), with Welch averaging over segments of
``nperseg`` samples overlapping by ``noverlap``, each detrended (constant) and
windowed (periodic Hann by default). Time is the last axis of every input.

:class:`SpectralAccumulator` takes samples block by block and keeps only the
samples not yet consumed, so a live display, a long recording and a replay all
go through the same code. Segments are summed in fixed groups of consecutive
segments, in order, so the result is bit for bit the same whatever the block
sizes and the number of worker threads.

Several references (shakers) give ``H = G_xf G_ff^-1`` per line and the
multiple coherence of each response.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Literal, TypeVar

import numpy as np
import scipy.fft
import scipy.signal
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ESTIMATORS",
    "CrossSpectra",
    "SpectralAccumulator",
    "SpectralError",
    "coherence",
    "combine",
    "frf",
    "h1",
    "h2",
    "hv",
    "ordinary_coherence",
    "record_spectra",
    "welch_spectra",
]

#: names accepted by :func:`frf`
ESTIMATORS = ("H1", "H2", "Hv")

Scaling = Literal["density", "spectrum"]
#: summed (Sff, Sfx, Sxx) of some segments
_Sums = tuple[NDArray[np.complex128], NDArray[np.complex128], NDArray[np.float64]]
_T = TypeVar("_T")
#: per-worker scratch arrays: windowed segments, their spectra (double precision), cross
#: products (single precision)
_Scratch = tuple[
    NDArray[np.floating], NDArray[np.complexfloating] | None, NDArray[np.complexfloating] | None
]
#: output arrays of one group's sums: cross (n_ref, n_ch, n_f) complex128, squares
#: (n_ch, 2 n_f) in the spectra's real precision, auto-spectra (n_ch, n_f) float64
_Outputs = tuple[NDArray[np.complex128], NDArray[np.floating], NDArray[np.float64]]


class SpectralError(ValueError):
    """Bad spectral-analysis parameters or data; the message names the value and what is allowed."""


# ----------------------------------------------------------------------------------------------
# result
# ----------------------------------------------------------------------------------------------
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
        freq = np.asarray(self.freq, dtype=float).ravel()
        Sff = np.asarray(self.Sff, dtype=np.complex128)
        Sfx = np.asarray(self.Sfx, dtype=np.complex128)
        Sxx = np.asarray(self.Sxx, dtype=np.float64)
        n_f = freq.size
        n_ref, n_resp = len(self.ref_channels), len(self.resp_channels)
        for name, arr, shape in (
            ("Sff", Sff, (n_ref, n_ref, n_f)),
            ("Sfx", Sfx, (n_ref, n_resp, n_f)),
            ("Sxx", Sxx, (n_resp, n_f)),
        ):
            if arr.shape != shape:
                raise SpectralError(f"{name} has shape {arr.shape}, expected {shape}")
        if n_ref < 1:
            raise SpectralError("at least one reference channel is needed")
        if self.n_averages < 0:
            raise SpectralError(f"n_averages must be >= 0, got {self.n_averages}")
        object.__setattr__(self, "freq", freq)
        object.__setattr__(self, "Sff", Sff)
        object.__setattr__(self, "Sfx", Sfx)
        object.__setattr__(self, "Sxx", Sxx)
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
    return CrossSpectra(
        a.freq, wa * a.Sff + wb * b.Sff, wa * a.Sfx + wb * b.Sfx, wa * a.Sxx + wb * b.Sxx,
        n, a.ref_channels, a.resp_channels,
    )


# ----------------------------------------------------------------------------------------------
# estimators
# ----------------------------------------------------------------------------------------------
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
        raise SpectralError(
            f"H2 needs exactly one reference, got {sp.n_ref}: use estimator 'H1' or 'Hv'"
        )
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
        raise SpectralError(
            f"unknown estimator {estimator!r}: choose one of {', '.join(ESTIMATORS)}"
        ) from None
    H = fn(sp)
    coh = np.broadcast_to(coherence(sp)[:, None, :], H.shape).copy()
    return H, coh


# ----------------------------------------------------------------------------------------------
# accumulation
# ----------------------------------------------------------------------------------------------
def _channel_roles(
    n_ch: int, references: Sequence[int], responses: Sequence[int] | None
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    refs = tuple(int(r) for r in references)
    if responses is None:
        resps = tuple(c for c in range(n_ch) if c not in refs)
    else:
        resps = tuple(int(r) for r in responses)
    every = refs + resps
    if not refs:
        raise SpectralError("give at least one reference (force) channel")
    if any(c < 0 or c >= n_ch for c in every):
        raise SpectralError(f"channel indices {every} out of range for {n_ch} channels")
    if len(set(every)) != len(every):
        raise SpectralError(f"reference {refs} and response {resps} channels must be distinct")
    return refs, resps


def _cross_sums(
    Z: NDArray[np.complexfloating],
    refs: tuple[int, ...],
    resps: tuple[int, ...],
    prod: NDArray[np.complexfloating] | None = None,
    out: _Outputs | None = None,
) -> _Sums:
    """Sums over the leading axis of ``conj(F) F``, ``conj(F) X`` and ``|X|^2``.

    ``Z`` (n_seg, n_ch, n_f) holds the spectra of all channels of n_seg segments.
    In single precision the cross products are formed in ``prod`` (scratch of shape
    (n_seg, n_ref, n_ch, n_f), allocated if not given) and summed in double precision,
    einsum being slow there; in double precision einsum does it in one pass over ``Z``.
    The sums go to ``out`` (see ``_Outputs``; allocated if not given) and the results
    are views of it: fresh megabyte-sized outputs for every group cost page faults
    that took as long as the products themselves (measured).
    """
    n_seg, n_ch, n_f = Z.shape
    if out is None:
        out = _outputs(len(refs), n_ch, n_f, Z.real.dtype)
    cross, auto2, Sxx = out
    Zr = np.conj(Z[:, list(refs)])  # (n_seg, n_ref, n_f), small copy
    if Z.dtype == np.complex64:
        shape = (n_seg, len(refs), n_ch, n_f)
        if prod is None or prod.shape != shape:
            prod = np.empty(shape, dtype=Z.dtype)
        np.multiply(Zr[:, :, None, :], Z[:, None, :, :], out=prod)
        np.add.reduce(prod, axis=0, dtype=np.complex128, out=cross)
    else:
        np.einsum("saf,sbf->abf", Zr, Z, out=cross)
    v = np.ascontiguousarray(Z).view(Z.real.dtype)  # interleaved re, im
    np.einsum("sbf,sbf->bf", v, v, out=auto2)
    np.add(auto2[:, 0::2], auto2[:, 1::2], out=Sxx, dtype=np.float64)
    r0 = resps[0] if resps else 0
    if resps == tuple(range(r0, r0 + len(resps))):  # the usual layout: a view, no copy
        return cross[:, list(refs)], cross[:, r0 : r0 + len(resps)], Sxx[r0 : r0 + len(resps)]
    return cross[:, list(refs)], cross[:, list(resps)], Sxx[list(resps)]


def _outputs(n_ref: int, n_ch: int, n_f: int, real: np.dtype[np.floating]) -> _Outputs:
    return (np.empty((n_ref, n_ch, n_f), np.complex128), np.empty((n_ch, 2 * n_f), real),
            np.empty((n_ch, n_f), np.float64))


def _shifted(fn: Callable[[int, int], _T], first: int, i: int, worker: int) -> _T:
    return fn(first + i, worker)


def _add(a: _Sums, b: _Sums) -> _Sums:
    return a[0] + b[0], a[1] + b[1], a[2] + b[2]


def _onesided_scale(n_f: int, nfft: int, norm: float) -> NDArray[np.float64]:
    scale = np.full(n_f, 2.0 / norm)
    scale[0] = 1.0 / norm
    if nfft % 2 == 0:
        scale[-1] = 1.0 / norm
    return scale


def _map_ordered(fn: Callable[[int, int], _T], n: int, workers: int = 1) -> list[_T]:
    """``[fn(i, k) for i in range(n)]``, by ``workers`` threads ``k`` on contiguous ranges of i.

    The only threads of ``processing``: numpy and pocketfft release the GIL, so two
    threads on disjoint segment groups use both cores. Results come back in order.
    """
    if workers <= 1 or n <= 1:
        return [fn(i, 0) for i in range(n)]
    workers = min(workers, n)
    bounds = np.linspace(0, n, workers + 1).astype(int)

    def run(k: int) -> list[_T]:
        return [fn(i, k) for i in range(bounds[k], bounds[k + 1])]

    with ThreadPoolExecutor(max_workers=workers - 1, thread_name_prefix="spectral") as pool:
        others = [pool.submit(run, k) for k in range(1, workers)]
        parts = [run(0)] + [f.result() for f in others]  # this thread takes the first range
    return [r for part in parts for r in part]


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
    group : int
        Segments transformed together (one FFT call for all channels of ``group``
        segments). Fixed per accumulator; results are independent of block sizes.
    workers : int
        Threads sharing the segment groups of one :meth:`update` (1 or 2 usually).

    Notes
    -----
    Float32 samples are transformed in single precision (complex64 FFT) and
    accumulated in float64; anything else is transformed in double precision.
    Segments are taken as :func:`scipy.signal.csd` takes them: from the first
    sample on, every ``nperseg - noverlap`` samples, trailing samples that do not
    fill a segment unused. With several workers, each :meth:`update` hands every
    thread the same number of groups and leaves the rest in the tail.

    Memory: the unconsumed tail (less than ``(workers + 1) * group * step + nperseg``
    samples per channel), a copy of at most that much joined to the next block, the
    accumulators (``n_ref * n_ch * (n_f + 1)`` complex values), per worker two arrays
    of ``group * n_ch * nperseg`` values, and ``2 * workers`` sets of one group's sums
    (``(n_ref + 2) * n_ch * n_f`` complex values each) reused from group to group.
    Measured with 25 channels, nperseg 8192, 1 s blocks at 51.2 kHz, two workers:
    under 100 MB (``benchmarks/frf.py``).

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
        group: int = 4,
        workers: int = 1,
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
        if group < 1 or workers < 1:
            raise SpectralError(f"group and workers must be >= 1, got {group}, {workers}")
        if isinstance(window, (str, tuple)):
            win = np.asarray(scipy.signal.get_window(window, nperseg), dtype=float)
        else:
            win = np.asarray(window, dtype=float)
        if win.shape != (nperseg,):
            raise SpectralError(f"window has shape {win.shape}, expected ({nperseg},)")
        self.fs = float(fs)
        self.nperseg = nperseg
        self.noverlap = noverlap
        self.step = nperseg - noverlap
        self.window = win
        self.detrend = detrend
        self.scaling: Scaling = scaling
        self.group = int(group)
        self.workers = int(workers)
        self._references = tuple(int(r) for r in references)
        self._responses = None if responses is None else tuple(int(r) for r in responses)
        W = np.fft.rfft(win)
        self._dc_bins = np.flatnonzero(np.abs(W) > 1e-12 * np.abs(W[0]))
        self._dc_values = W[self._dc_bins]
        self.freq = np.asarray(np.fft.rfftfreq(nperseg, 1.0 / fs), dtype=np.float64)
        self.reset()

    # -- state ---------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget every sample and average (keeps the parameters)."""
        self._tail: NDArray[np.floating] | None = None
        self._dtype: np.dtype[np.floating] | None = None
        self._n_ch = 0
        self._refs: tuple[int, ...] = ()
        self._resps: tuple[int, ...] = ()
        self._sums: _Sums | None = None
        self._n_seg = 0
        self._n_samples = 0
        self._scratch: list[_Scratch] = []
        self._outs: list[_Outputs] = []

    @property
    def n_averages(self) -> int:
        """Segments averaged so far (including those waiting for a full group)."""
        return self._n_seg + self._pending_segments()

    @property
    def n_samples(self) -> int:
        """Samples per channel received so far."""
        return self._n_samples

    def _pending_segments(self) -> int:
        n = 0 if self._tail is None else self._tail.shape[-1]
        return 0 if n < self.nperseg else (n - self.nperseg) // self.step + 1

    def _span(self, n_seg: int) -> int:
        return (n_seg - 1) * self.step + self.nperseg

    # -- work ----------------------------------------------------------------------------------
    def _first_block(self, block: NDArray[np.generic]) -> None:
        self._n_ch = block.shape[0]
        self._refs, self._resps = _channel_roles(self._n_ch, self._references, self._responses)
        self._dtype = np.dtype(np.float32 if block.dtype == np.float32 else np.float64)
        self._win = self.window.astype(self._dtype)
        self._tail = np.empty((self._n_ch, 0), dtype=self._dtype)

    def _group_sums(self, seg: NDArray[np.floating], worker: int | None = None,
                    slot: int | None = None) -> _Sums:
        """Sums of one group: ``seg`` (n_ch, n_seg, nperseg) strided view of the samples.

        A full group reuses the scratch arrays of ``worker`` and writes its sums to the
        output arrays of ``slot`` (its place in the groups awaiting commit; the result is
        a view of them): allocating them anew for every group costs page faults that
        serialise the threads.
        """
        n_seg = seg.shape[1]
        sums_out = None
        if worker is not None and n_seg == self.group:
            buf, spec, prod = self._workspace(worker)
            if slot is not None:
                assert self._dtype is not None
                while len(self._outs) <= slot:
                    self._outs.append(_outputs(len(self._refs), self._n_ch, self.freq.size,
                                               self._dtype))
                sums_out = self._outs[slot]
        else:
            buf, spec, prod = np.empty((n_seg, self._n_ch, self.nperseg), self._dtype), None, None
        np.multiply(seg.transpose(1, 0, 2), self._win, out=buf)
        # one FFT per precision whatever the buffers, so that results never depend on how
        # the samples were cut into blocks
        Z: NDArray[np.complexfloating]
        if self._dtype == np.float64:
            out = None if spec is None else spec.view(np.complex128)
            Z = np.fft.rfft(buf, axis=-1, out=out)  # numpy's pocketfft can write in place
        else:  # scipy's is twice as fast as numpy's in single precision
            Z = scipy.fft.rfft(buf, axis=-1, workers=1)
        if self.detrend == "constant":
            mean = seg.mean(axis=-1).T  # (n_seg, n_ch), in the samples' precision like scipy
            Z[..., self._dc_bins] -= (mean[..., None] * self._dc_values).astype(Z.dtype)
        return _cross_sums(Z, self._refs, self._resps, prod, sums_out)

    def _workspace(self, worker: int) -> _Scratch:
        while len(self._scratch) <= worker:
            n_f = self.freq.size
            single = self._dtype == np.float32
            self._scratch.append((
                np.empty((self.group, self._n_ch, self.nperseg), dtype=self._dtype),
                None if single else np.empty((self.group, self._n_ch, n_f), np.complex128),
                np.empty((self.group, len(self._refs), self._n_ch, n_f), np.complex64)
                if single else None,
            ))
        return self._scratch[worker]

    def _segments(self, data: NDArray[np.floating], start: int, n_seg: int) -> NDArray[np.floating]:
        view = data[:, start : start + self._span(n_seg)]
        return sliding_window_view(view, self.nperseg, axis=-1)[:, :: self.step]

    def update(self, block: ArrayLike) -> None:
        """Add a block of samples (n_ch, n); any n, including 0. Float32 stays float32."""
        arr = np.asarray(block)
        if arr.ndim != 2:
            raise SpectralError(f"a block must have shape (n_channels, n_samples), got {arr.shape}")
        if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
            raise SpectralError(f"samples must be real numbers, got dtype {arr.dtype}")
        if self._tail is None:
            self._first_block(arr)
        assert self._tail is not None
        if arr.shape[0] != self._n_ch:
            raise SpectralError(f"block has {arr.shape[0]} channels, expected {self._n_ch}")
        if not np.isfinite(np.add.reduce(arr, axis=None, dtype=np.float64)):  # one cheap pass
            raise SpectralError("block contains NaN or infinite samples; nothing was added")
        arr = arr.astype(self._dtype, copy=False)
        self._n_samples += arr.shape[-1]
        tail = self._tail
        n_tail, n_new = tail.shape[-1], arr.shape[-1]
        hop = self.group * self.step  # samples between group starts
        span = self._span(self.group)
        avail = n_tail + n_new
        n_groups = 0 if avail < span else (avail - span) // hop + 1
        # as many groups for each thread; the rest waits in the tail for the next block
        n_groups -= n_groups % self.workers
        if n_groups == 0:
            self._tail = np.concatenate([tail, arr], axis=-1)
            return
        # groups inside the tail or the block are views; only those straddling both are cut
        # from a joined copy
        n_inside = min(n_groups, max(0, (n_tail - span) // hop + 1))
        n_head = min(n_groups, -(-n_tail // hop))
        off = n_inside * hop
        head = tail
        if n_head > n_inside:
            need = (n_head - 1) * hop + span - n_tail
            head = np.concatenate([tail[:, off:], arr[:, :need]], axis=-1)

        chunk = 2 * self.workers  # groups whose sums wait for their turn to be committed

        def job(g: int, worker: int) -> _Sums:
            if g < n_inside:
                seg = self._segments(tail, g * hop, self.group)
            elif g < n_head:
                seg = self._segments(head, g * hop - off, self.group)
            else:
                seg = self._segments(arr, g * hop - n_tail, self.group)
            return self._group_sums(seg, worker, g % chunk)  # a slot per group of a chunk

        for first in range(0, n_groups, chunk):
            n_run = min(chunk, n_groups - first)
            self._commit(_map_ordered(functools.partial(_shifted, job, first), n_run,
                                      self.workers))
        self._n_seg += n_groups * self.group
        start = n_groups * hop  # first unconsumed sample, counted from the tail's start
        if start >= n_tail:
            self._tail = arr[:, start - n_tail :].copy()
        else:
            self._tail = np.concatenate([tail[:, start:], arr], axis=-1)

    def _commit(self, results: Sequence[_Sums]) -> None:
        for parts in results:  # in group order: the sums do not depend on block boundaries
            if self._sums is None:
                self._sums = (parts[0].copy(), parts[1].copy(), parts[2].copy())
            else:
                for total, part in zip(self._sums, parts, strict=True):
                    np.add(total, part, out=total)

    def spectra(self) -> CrossSpectra:
        """The current averaged spectra (the accumulator goes on accepting blocks).

        Raises
        ------
        SpectralError
            If not one complete segment has been received yet.
        """
        n_pending = self._pending_segments()
        if self._n_seg + n_pending == 0 or self._tail is None:
            raise SpectralError(
                f"no complete segment yet: {self._n_samples} samples per channel received, "
                f"{self.nperseg} needed"
            )
        sums = self._sums
        for start in range(0, n_pending, self.group):  # the same groups as update() forms
            k = min(self.group, n_pending - start)
            parts = self._group_sums(self._segments(self._tail, start * self.step, k))
            sums = parts if sums is None else _add(sums, parts)
        assert sums is not None
        n = self._n_seg + n_pending
        norm = self.fs * np.sum(self.window**2) if self.scaling == "density" else np.sum(
            self.window
        ) ** 2
        scale = _onesided_scale(self.freq.size, self.nperseg, float(norm)) / n
        Sff, Sfx, Sxx = sums
        return CrossSpectra(
            self.freq, Sff * scale, Sfx * scale, Sxx * scale, n, self._refs, self._resps
        )


def welch_spectra(
    data: ArrayLike,
    fs: float,
    nperseg: int,
    noverlap: int | None = None,
    **kwargs: object,
) -> CrossSpectra:
    """One-shot :class:`SpectralAccumulator`: spectra of ``data`` (n_ch, n) at ``fs`` Hz.

    Keyword arguments are those of :class:`SpectralAccumulator`.
    """
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

    Parameters
    ----------
    records : (n_rec, n_ch, n) array
        One record per hit/burst/period, all channels.
    fs : float
        Sample rate, Hz.
    windows : array broadcastable to (n_rec, n_ch, n), optional
        Windows (force and exponential windows): one for all, one per channel
        (n_ch, n) or one per record and channel; rectangular by default.
    references, responses : channel indices, as for :class:`SpectralAccumulator`.

    Returns
    -------
    CrossSpectra
        Scaled as energy densities ``2 conj(X) Y / (fs n)`` (one-sided); with
        transients only ratios (FRFs, coherence) are meaningful.
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
    Z = scipy.fft.rfft(x, axis=-1, overwrite_x=True)
    Sff, Sfx, Sxx = _cross_sums(Z, refs, resps)
    freq = np.asarray(np.fft.rfftfreq(n, 1.0 / fs), dtype=np.float64)
    scale = _onesided_scale(freq.size, n, fs * n) / n_rec
    return CrossSpectra(freq, Sff * scale, Sfx * scale, Sxx * scale, n_rec, refs, resps)
