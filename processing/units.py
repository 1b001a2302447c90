"""Time data's averaging units: the spectra of each hit (hammer) or block (shaker) of a column.

A point's FRF column from time data is a ratio of averaged spectra: H1 is
``sum_u S_fx,u / sum_u S_ff,u`` over the point's units ``u`` (the accepted hits of a hammer
test, the blocks of a shaker test). Keeping them unit by unit lets the FRFs be formed again
from any resample of the units (:mod:`processing.bootstrap`). The pipeline attaches a test's
:class:`TimeUnits` to the measurement's provenance (``Provenance.units``). Continuous random
records (Welch, overlapping segments) are cut into contiguous blocks of segments
(:func:`welch_units`), so that neighbouring units share at most one overlapping segment (a
block bootstrap).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from processing.data import InputError

if TYPE_CHECKING:  # the spectra (numba kernels) load where spectra are computed
    from processing.spectral import CrossSpectra, SpectralAccumulator

__all__ = ["MIN_UNITS", "UNIT_DTYPE", "TimeUnits", "UnitKind", "UnitSpectra", "record_units",
           "welch_units"]

#: the bootstrap runs by default when every excitation column has at least this many units
MIN_UNITS = 3
#: continuous random records: at most this many blocks a run, of at least WELCH_MIN_SEGMENTS
WELCH_BLOCKS = 20
WELCH_MIN_SEGMENTS = 2

UnitKind = Literal["hit", "block"]

#: the precision units are kept in (:class:`UnitSpectra`)
UNIT_DTYPE, UNIT_CDTYPE = np.float32, np.complex64


@dataclass(frozen=True)
class UnitSpectra:
    """One excitation column's spectra, unit by unit (one reference: the column's force).

    Attributes
    ----------
    freq : (n_f,) Hz
    Sff : (n_u, n_f) force auto-spectrum of each unit
    Sfx : (n_u, n_resp, n_f) cross-spectra force -> responses (``conj(F) X``)
    Sxx : (n_u, n_resp, n_f) response auto-spectra
    weight : (n_u,) segments each unit averages (the weight of its spectra in the mean)

    All spectra of one column share one scaling; only their ratios matter. They are kept
    in single precision (:data:`UNIT_DTYPE`), on the FRFs' lines only (up to fs / 2.56 by
    default): a resample's FRFs need no more, and a long shaker test's units are then less
    than half the size (12 runs x 20 blocks x 13 channels x 800 lines: 27 MB, not 68 in
    double precision on all 1025 lines). The FRFs themselves come from the spectra in full
    precision.
    """

    freq: NDArray[np.float64]
    Sff: NDArray[np.floating[Any]]
    Sfx: NDArray[np.complexfloating[Any, Any]]
    Sxx: NDArray[np.floating[Any]]
    weight: NDArray[np.float64]

    def __post_init__(self) -> None:
        for name, dtype in (("Sff", UNIT_DTYPE), ("Sfx", UNIT_CDTYPE), ("Sxx", UNIT_DTYPE)):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=dtype))
        n_u, n_r, n_f = np.shape(self.Sfx)
        if np.shape(self.Sff) != (n_u, n_f) or np.shape(self.Sxx) != (n_u, n_r, n_f):
            raise InputError(f"unit spectra shapes differ: Sff {np.shape(self.Sff)}, Sfx "
                             f"{np.shape(self.Sfx)}, Sxx {np.shape(self.Sxx)}")
        if np.shape(self.weight) != (n_u,) or np.size(self.freq) != n_f:
            raise InputError("unit spectra: one weight per unit and one frequency per line")

    def __repr__(self) -> str:  # short: a provenance shown is one line
        return f"UnitSpectra({self.n_units} units, {self.Sfx.shape[1]} responses)"

    @property
    def n_units(self) -> int:
        return int(self.Sff.shape[0])

    def below(self, fmax: float | None) -> UnitSpectra:
        """The units on the lines up to ``fmax`` Hz (all when None), copied: the lines an
        FRF set cut there can use (:meth:`processing.data.FRFSet.select_lines`)."""
        k = _lines_upto(self.freq, fmax)
        if k == self.freq.size:
            return self
        return UnitSpectra(self.freq[:k].copy(), self.Sff[:, :k].copy(),
                           self.Sfx[..., :k].copy(), self.Sxx[..., :k].copy(), self.weight)

    @classmethod
    def of(cls, spectra: Sequence[CrossSpectra]) -> UnitSpectra:
        """Units from averaged spectra of one reference (each weighted by its averages)."""
        if not spectra:
            raise InputError("no unit spectra")
        for sp in spectra:
            if sp.n_ref != 1:
                raise InputError(f"unit spectra need one reference per column, got {sp.n_ref}")
        return cls(spectra[0].freq, np.stack([sp.Sff[0, 0].real for sp in spectra]),
                   np.stack([sp.Sfx[0] for sp in spectra]), np.stack([sp.Sxx for sp in spectra]),
                   np.array([float(sp.n_averages) for sp in spectra]))

    @classmethod
    def concat(cls, parts: Sequence[UnitSpectra]) -> UnitSpectra:
        """The units of several recordings of one column, in order."""
        if not parts:
            raise InputError("no unit spectra to join")
        for p in parts[1:]:
            if not np.array_equal(p.freq, parts[0].freq):
                raise InputError("unit spectra with different frequency lines")
        return cls(parts[0].freq, np.concatenate([p.Sff for p in parts]),
                   np.concatenate([p.Sfx for p in parts]),
                   np.concatenate([p.Sxx for p in parts]),
                   np.concatenate([p.weight for p in parts]))

    def mean(self) -> CrossSpectra:
        """The weighted mean of the units (the spectra the column's FRF is formed from)."""
        from processing.spectral import CrossSpectra

        w = self.weight / self.weight.sum()
        return CrossSpectra(self.freq, (w @ self.Sff)[None, None] + 0j,
                            np.einsum("u,urf->rf", w, self.Sfx)[None],
                            np.einsum("u,urf->rf", w, self.Sxx), int(self.weight.sum()),
                            (0,), tuple(range(1, self.Sfx.shape[1] + 1)))


@dataclass(frozen=True)
class TimeUnits:
    """The averaging units of every excitation column of a time-data test.

    ``columns`` in the order of ``exc_nodes`` / ``exc_dirs`` (n_exc, 3); ``kind`` "hit"
    (hammer) or "block" (shaker blocks, or blocks of segments of continuous records);
    ``estimator`` the FRF estimator ("H1", "H2", "Hv").
    """

    kind: UnitKind
    columns: tuple[UnitSpectra, ...]
    exc_nodes: NDArray[np.int64]
    exc_dirs: NDArray[np.float64]
    estimator: str = "H1"

    def __repr__(self) -> str:  # short: a provenance shown is one line
        n = [c.n_units for c in self.columns]
        return f"TimeUnits({len(n)} columns, {min(n, default=0)}-{max(n, default=0)} {self.kind}s)"

    def aligned(self, exc_nodes: NDArray[np.int64], exc_dirs: NDArray[np.float64],
                ) -> TimeUnits | None:
        """The units of the columns ``exc_nodes`` / ``exc_dirs`` in that order; None when a
        column has none."""
        idx = []
        for n, d in zip(np.asarray(exc_nodes), np.asarray(exc_dirs, float), strict=True):
            hit = np.flatnonzero((self.exc_nodes == n)
                                 & np.all(np.abs(self.exc_dirs - d) < 1e-6, axis=1))
            if hit.size == 0:
                return None
            idx.append(int(hit[0]))
        return TimeUnits(self.kind, tuple(self.columns[i] for i in idx),
                         self.exc_nodes[idx], self.exc_dirs[idx], self.estimator)

    def labels(self) -> tuple[str, ...]:
        """Contribution names of the columns: ``"hits of node 3:+z"``."""
        return tuple(f"{self.kind}s of node {n}{_axis(d)}"
                     for n, d in zip(self.exc_nodes, self.exc_dirs, strict=True))


def _axis(d: NDArray[np.float64]) -> str:
    k = int(np.argmax(np.abs(d)))
    return f":{'+' if d[k] >= 0 else '-'}{'xyz'[k]}"


def record_units(records: ArrayLike, fs: float, windows: ArrayLike | None = None,
                 force_channel: int = 0) -> UnitSpectra:
    """Per-record spectra of windowed records (n_rec, n_ch, n): one unit per record, scaled
    as :func:`processing.spectral.record_spectra` (whose average they are)."""
    rec = np.asarray(records, dtype=float)
    x = rec * (1.0 if windows is None else np.asarray(windows, dtype=float))
    n = x.shape[-1]
    Z = scipy.fft.rfft(x, axis=-1)
    scale = np.full(Z.shape[-1], 2.0 / (fs * n))
    scale[0] /= 2
    if n % 2 == 0:
        scale[-1] /= 2
    F = Z[:, force_channel]
    resp = [c for c in range(x.shape[1]) if c != force_channel]
    Xr = Z[:, resp]
    return UnitSpectra(np.asarray(np.fft.rfftfreq(n, 1.0 / fs), dtype=np.float64),
                       np.abs(F) ** 2 * scale,
                       np.conj(F)[:, None] * Xr * scale, np.abs(Xr) ** 2 * scale,
                       np.ones(rec.shape[0]))


def welch_units(acc: SpectralAccumulator,
                data: NDArray[np.floating] | Sequence[NDArray[np.floating]],
                n_blocks: int = WELCH_BLOCKS, fmax: float | None = None,
                ) -> tuple[CrossSpectra, UnitSpectra | None]:
    """Feed ``data`` (n_ch, n) to ``acc`` in pieces and return its spectra and the blocks of
    contiguous segments as units (None under ``MIN_UNITS`` blocks of
    ``WELCH_MIN_SEGMENTS``), on the lines up to ``fmax`` Hz (all when None).

    ``data`` may come as parts, each (k, n) or (n,), their rows in order: the pieces are
    joined as they are fed, so the whole recording is never copied. The accumulator's
    result is the same, bit for bit, as one update with all of ``data``
    (:class:`~processing.spectral.SpectralAccumulator`); a block's spectra are the
    difference of the running sums before and after its segments, kept in
    :data:`UNIT_DTYPE` as soon as formed. ``acc`` must be new.
    """
    parts = [data] if isinstance(data, np.ndarray) else [np.atleast_2d(p) for p in data]

    def piece(a: int, b: int) -> NDArray[np.floating]:
        return parts[0][:, a:b] if len(parts) == 1 else np.vstack([p[:, a:b] for p in parts])

    N, step = acc.nperseg, acc.step
    n = parts[0].shape[-1]
    n_seg = 0 if n < N else (n - N) // step + 1
    g = min(n_blocks, n_seg // WELCH_MIN_SEGMENTS)
    if g < MIN_UNITS:
        acc.update(piece(0, n))
        return acc.spectra(), None
    ends = [round(n_seg * (j + 1) / g) for j in range(g)]  # segments done after block j
    keep = slice(0, _lines_upto(acc.freq, fmax))
    Sff, Sfx, Sxx, weight = [], [], [], []
    fed, prev = 0, None
    for e in ends:
        stop = n if e == n_seg else (e - 1) * step + N
        acc.update(piece(fed, stop))
        fed = stop
        now = acc.spectra()
        if prev is None:
            ff, fx, xx = now.Sff[0, 0, keep], now.Sfx[0, :, keep], now.Sxx[:, keep]
            k = now.n_averages
        else:
            k0, k1 = prev.n_averages, now.n_averages
            ff = (now.Sff[0, 0, keep] * k1 - prev.Sff[0, 0, keep] * k0) / (k1 - k0)
            fx = (now.Sfx[0, :, keep] * k1 - prev.Sfx[0, :, keep] * k0) / (k1 - k0)
            xx = (now.Sxx[:, keep] * k1 - prev.Sxx[:, keep] * k0) / (k1 - k0)
            k = k1 - k0
        Sff.append(np.asarray(ff.real, dtype=UNIT_DTYPE))
        Sfx.append(np.asarray(fx, dtype=UNIT_CDTYPE))
        Sxx.append(np.asarray(xx, dtype=UNIT_DTYPE))
        weight.append(float(k))
        prev = now
    assert prev is not None
    return prev, UnitSpectra(prev.freq[keep], np.stack(Sff), np.stack(Sfx), np.stack(Sxx),
                             np.array(weight))


def _lines_upto(freq: NDArray[np.float64], fmax: float | None) -> int:
    """How many of the ascending lines ``freq`` lie at or below ``fmax`` Hz (all when None)."""
    return freq.size if fmax is None else int(np.searchsorted(freq, fmax, side="right"))
