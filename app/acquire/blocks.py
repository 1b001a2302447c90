"""Shaker blocks: the verdict of each stored block and the FRFs averaged over accepted blocks.

One code path for the live shaker procedure and ``insitu replay`` (as
:mod:`app.acquire.analysis` is for hits): every block is judged by
:func:`block_verdict` on the record as stored, and a point's FRF column is the
:class:`~processing.spectral.SpectralAccumulator` of its accepted blocks fed one
block per update in acquisition order, so the live FRFs and the replay's are
identical bit for bit. Each block is one segment of ``nperseg`` samples (no
overlap between blocks: a rejected block or a pause never joins two pieces of
signal), windowed for its waveform (:data:`WINDOWS`): Hann for random, none for
burst random (each block starts at a burst) and periodic chirp (one period per
block), which are leakage-free.

With several shakers driven at once (``[shaker] shakers``), a block holds every force
(rows ``0 .. shakers - 1``) then the responses, and is stored under its drive (the
stop where those shakers were attached, :attr:`~app.acquire.plan.TestPlan.drives`);
the drive's spectra have every force as a reference and its multiple-reference H1
gives one FRF column per excitation driven.

The spectra are the offline path's: the parallel numba kernel of
:class:`~processing.spectral.SpectralAccumulator`, its channels shared by
:data:`WORKERS` threads (as :mod:`app.pipeline.time_uff` does for a time recording).
Live, each block is one call; a point rebuilt from its stored blocks (a verdict
changed, ``insitu replay``) is fed :data:`REBUILD_BLOCKS` blocks per call, the same
segments in the same order, so the sums are the same bits.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from app.acquire.plan import ShakerSettings, TestPlan
from processing.data import FRFSet, Geometry, InputError
from processing.measurement import Measurement, Provenance
from processing.spectral import CrossSpectra, SpectralAccumulator, frf
from processing.units import TimeUnits, UnitSpectra

__all__ = ["REBUILD_BLOCKS", "WINDOWS", "WORKERS", "BlockAnalysis", "BlockResult",
           "RecordLoader", "block_verdict", "shaker_measurement"]

#: window of each waveform's blocks (scipy window names)
WINDOWS = {"random": "hann", "burst-random": "boxcar", "chirp": "boxcar"}
#: threads of the spectral kernel: both cores of a bench PC, as the offline path
WORKERS = min(2, os.cpu_count() or 1)
#: stored blocks fed to the kernel per call when a point is rebuilt
REBUILD_BLOCKS = 16


def block_verdict(data: NDArray[np.float64], names: Sequence[str],
                  ranges: NDArray[np.float64] | None, n_forces: int = 1
                  ) -> tuple[bool, str, float]:
    """Automatic verdict of one block (force rows ``0 .. n_forces - 1``, N; responses m/s^2).

    Returns ``(accepted, reason, peak force N)`` (the largest of the forces): a block
    with lost samples or with a channel at or above 99 % of its range (``ranges`` in each
    row's unit) is rejected.

    Examples
    --------
    >>> block_verdict(np.array([[1.0, -3.0], [0.5, 9.95]]), ["F", "a1"], np.array([10, 10.]))
    (False, 'overload on a1 (peak at or above 99 % of its range)', 3.0)
    """
    force = data[:n_forces]
    finite = force[np.isfinite(force)]
    peak = float(np.abs(finite).max()) if finite.size else float("nan")
    lost = int(np.count_nonzero(np.isnan(data).any(axis=0)))
    if lost:
        return False, f"{lost} samples lost", peak
    if ranges is not None:
        over = np.abs(data).max(axis=-1) >= 0.99 * np.asarray(ranges)
        if over.any():
            ch = names[int(np.argmax(over))]
            return False, f"overload on {ch} (peak at or above 99 % of its range)", peak
    return True, "", peak


@dataclass(frozen=True)
class BlockResult:
    """The averaged FRF column of one excitation point.

    ``freq`` Hz; ``H`` (n_resp, 1, n_f) accelerance (m/s^2)/N; ``coherence`` (n_resp, 1,
    n_f); ``spectra`` the averaged cross-spectra; ``n_accepted`` blocks averaged.
    """

    freq: NDArray[np.float64]
    H: NDArray[np.complex128]
    coherence: NDArray[np.float64]
    spectra: CrossSpectra
    n_accepted: int


@dataclass
class _Point:
    acc: SpectralAccumulator
    ids: list[int] = field(default_factory=list)


#: reads stored records: given record numbers, yields ``(number, data)`` one at a time
RecordLoader = Callable[[Sequence[int]], Iterable[tuple[int, NDArray[np.float64]]]]


class BlockAnalysis:
    """FRFs of a shaker run, point by point, kept up to date as blocks and verdicts change.

    A "point" here is a drive of the plan (:attr:`~app.acquire.plan.TestPlan.drives`):
    the excitation point itself with one shaker, the excitations driven together with
    several; :meth:`point` then gives their columns, one per force.

    Same interface as :class:`app.acquire.analysis.RunAnalysis`: :meth:`add` a stored
    block, :meth:`set_used` its verdict in force, :meth:`point` the averaged column.
    Memory does not grow with the blocks: each point keeps its spectral accumulator, fed
    a used block as it comes; per block, only its point and verdict. A change that cannot
    be fed in order (a verdict changed on an older block) rebuilds the point's accumulator
    from the stored blocks, read one at a time with ``loader`` and fed
    :data:`REBUILD_BLOCKS` at a time, in acquisition order.

    Parameters
    ----------
    plan : TestPlan
        Its ``[shaker]`` section gives the waveform (window) and ``nperseg``.
    names : channel names of the record rows (force first)
    ranges : full-scale range of each row in its unit (for overload checks)
    loader : callable, optional
        ``loader(ids)`` yields ``(id, data)`` for the stored blocks ``ids``. Without it, a
        rebuild raises RuntimeError.
    workers : int, optional
        Threads of the spectral kernel (default :data:`WORKERS`); the sums are the same
        bits whatever their number.
    """

    def __init__(self, plan: TestPlan, names: Sequence[str],
                 ranges: NDArray[np.float64] | None, loader: RecordLoader | None = None,
                 workers: int | None = None) -> None:
        self.plan = plan
        self.workers = WORKERS if workers is None else workers
        self.names = tuple(names)
        self.ranges = ranges
        self.loader = loader
        self._point_of: dict[int, int] = {}
        self._finite: dict[int, bool] = {}
        self._accepted: dict[int, bool] = {}
        self._n_used: dict[int, int] = {}
        self._points: dict[int, _Point] = {}
        self._stale: set[int] = set()
        self._pending: tuple[int, NDArray[np.float64]] | None = None  # verdict to come

    def _accumulator(self) -> SpectralAccumulator:
        s: ShakerSettings = self.plan.shaker
        # no detrend: the sensors are AC-coupled, and a mean removed from the force of a
        # periodic block would leave 0/0 (NaN) on the 0 Hz line
        return SpectralAccumulator(self.plan.record.fs, s.nperseg, 0, detrend=False,
                                   window=WINDOWS[s.waveform],
                                   references=tuple(range(self.plan.n_references)),
                                   workers=self.workers)

    def warm_up(self) -> None:
        """Load the spectral kernels (numba's cache on disk, or compile them) and run one
        block of this run's layout through them, results thrown away.

        The first spectrum of a process takes about 0.4 s more than the next ones (more on
        a loaded machine): longer than a shaker's watchdog. The procedure calls this before
        any output goes on, so the first block is analysed as fast as the others.
        """
        acc = self._accumulator()
        acc.update(np.zeros((len(self.names), self.plan.shaker.nperseg)))
        frf(acc.spectra(), self.plan.record.estimator)

    def add(self, hit_id: int, point: int, data: NDArray[np.float64],
            override: str = "") -> tuple[bool, str, float] | None:
        """Judge a stored block; returns its verdict (None if it has lost samples)."""
        if hit_id in self._point_of and self._point_of[hit_id] != point:
            self._stale.add(self._point_of[hit_id])
        self._point_of[hit_id] = point
        verdict = block_verdict(data, self.names, self.ranges, self.plan.n_references)
        finite = bool(np.all(np.isfinite(data)))
        self._finite[hit_id] = finite
        self._pending = (hit_id, data) if finite else None
        return verdict if finite else None

    def point_of(self, hit_id: int) -> int:
        """The excitation point of stored block ``hit_id``."""
        return self._point_of[hit_id]

    def set_used(self, hit_id: int, used: bool) -> None:
        point = self._point_of[hit_id]
        used = used and self._finite[hit_id]
        was = self._accepted.get(hit_id, False)
        self._accepted[hit_id] = used
        self._n_used[point] = self._n_used.get(point, 0) + int(used) - int(was)
        pending, self._pending = self._pending, None
        if used == was:
            return
        st = self._points.get(point)
        if (used and pending is not None and pending[0] == hit_id and point not in self._stale
                and (st is None or hit_id > st.ids[-1])):
            if st is None:
                st = self._points[point] = _Point(self._accumulator())
            st.acc.update(pending[1])  # one block per update, in acquisition order
            st.ids.append(hit_id)
        else:
            self._stale.add(point)

    def n_used(self, point: int) -> int:
        return self._n_used.get(point, 0)

    def point(self, point: int, max_averages: int | None = None) -> BlockResult | None:
        """The averaged column of ``point`` from its accepted blocks (the first
        ``max_averages`` of them when given; None if none)."""
        st = self._points.get(point)
        if max_averages is not None or point in self._stale:
            ids = sorted(h for h, p in self._point_of.items()
                         if p == point and self._accepted.get(h))
            if max_averages is not None:
                ids = ids[:max_averages]
            st = self._rebuild(ids)
            if max_averages is None:
                self._stale.discard(point)
                if st is None:
                    self._points.pop(point, None)
                else:
                    self._points[point] = st
        if st is None:
            return None
        sp = st.acc.spectra()
        H, coh = frf(sp, self.plan.record.estimator)
        return BlockResult(sp.freq, H, coh, sp, len(st.ids))

    def used_ids(self, point: int, max_averages: int | None = None) -> list[int]:
        """The point's used blocks in acquisition order (the first ``max_averages``)."""
        ids = sorted(h for h, p in self._point_of.items() if p == point and self._accepted.get(h))
        return ids if max_averages is None else ids[:max_averages]

    def unit_spectra(self, point: int, max_averages: int | None = None) -> UnitSpectra | None:
        """The spectra of each of the point's used blocks (the units :meth:`point` averages),
        read back with ``loader``; None without a used block."""
        ids = self.used_ids(point, max_averages)
        if not ids or self.loader is None:
            return None
        spectra = []
        for _, data in self.loader(ids):
            acc = self._accumulator()
            acc.update(data)
            spectra.append(acc.spectra())
        return UnitSpectra.of(spectra)

    def _rebuild(self, ids: Sequence[int]) -> _Point | None:
        """An accumulator of blocks ``ids`` read back from the stored records, in order."""
        if not ids:
            return None
        if self.loader is None:
            raise RuntimeError("rebuilding a point's average needs the stored blocks: give "
                               "BlockAnalysis a loader")
        st = _Point(self._accumulator())
        batch: list[NDArray[np.float64]] = []
        for i, data in self.loader(ids):
            batch.append(data)
            st.ids.append(i)
            if len(batch) == REBUILD_BLOCKS:
                st.acc.update(np.concatenate(batch, axis=1))  # no overlap: the same segments
                batch.clear()
        if batch:
            st.acc.update(np.concatenate(batch, axis=1))
        return st


def shaker_measurement(plan: TestPlan, points: Sequence[BlockResult | None],
                       geometry: Geometry, resp_nodes: NDArray[np.int64],
                       resp_dirs: NDArray[np.float64], units: TimeUnits | None = None,
                       ) -> Measurement:
    """All drives' FRF columns as one measurement, one column per excitation in plan order
    (``points[d]``: drive ``d``'s result; raises InputError naming a drive without blocks),
    estimated here from blocks, with their spectra ``units`` when given."""
    cols, cohs, n_avg = [], [], []
    for d, r in enumerate(points):
        if r is None:
            labels = " and ".join(plan.excitations[j].label for j in plan.drives[d])
            raise InputError(f"excitation {labels} has no accepted block: "
                             "resume the run (insitu acquire --resume)")
        cols.append(r.H)
        cohs.append(r.coherence)
        n_avg += [r.n_accepted] * r.H.shape[1]
    first = next(r for r in points if r is not None)
    frfs = FRFSet(first.freq, np.concatenate(cols, axis=1), resp_nodes, resp_dirs,
                  plan.exc_nodes, plan.exc_dirs, geometry, np.concatenate(cohs, axis=1))
    return Measurement(frfs, Provenance(
        origin="estimated", excitation=f"shaker {plan.shaker.waveform}",
        estimator=plan.record.estimator, units=units, n_averages=tuple(n_avg),
        window=WINDOWS[plan.shaker.waveform], references=plan.n_references))
