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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from app.acquire.plan import ShakerSettings, TestPlan
from processing.data import FRFSet, Geometry, InputError
from processing.spectral import CrossSpectra, SpectralAccumulator, frf

__all__ = ["WINDOWS", "BlockAnalysis", "BlockResult", "block_verdict", "shaker_frfset"]

#: window of each waveform's blocks (scipy window names)
WINDOWS = {"random": "hann", "burst-random": "boxcar", "chirp": "boxcar"}


def block_verdict(data: NDArray[np.float64], names: Sequence[str],
                  ranges: NDArray[np.float64] | None) -> tuple[bool, str, float]:
    """Automatic verdict of one block (force row 0, N; responses m/s^2).

    Returns ``(accepted, reason, peak force N)``: a block with lost samples or with a
    channel at or above 99 % of its range (``ranges`` in each row's unit) is rejected.

    Examples
    --------
    >>> block_verdict(np.array([[1.0, -3.0], [0.5, 9.95]]), ["F", "a1"], np.array([10, 10.]))
    (False, 'overload on a1 (peak at or above 99 % of its range)', 3.0)
    """
    force = data[0]
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


class BlockAnalysis:
    """FRFs of a shaker run, point by point, kept up to date as blocks and verdicts change.

    Same interface as :class:`app.acquire.analysis.RunAnalysis`: :meth:`add` a stored
    block, :meth:`set_used` its verdict in force, :meth:`point` the averaged column.

    Parameters
    ----------
    plan : TestPlan
        Its ``[shaker]`` section gives the waveform (window) and ``nperseg``.
    names : channel names of the record rows (force first)
    ranges : full-scale range of each row in its unit (for overload checks)
    """

    def __init__(self, plan: TestPlan, names: Sequence[str],
                 ranges: NDArray[np.float64] | None) -> None:
        self.plan = plan
        self.names = tuple(names)
        self.ranges = ranges
        self._data: dict[int, NDArray[np.float64]] = {}
        self._point_of: dict[int, int] = {}
        self._accepted: dict[int, bool] = {}
        self._points: dict[int, _Point] = {}

    def _accumulator(self) -> SpectralAccumulator:
        s: ShakerSettings = self.plan.shaker
        # no detrend: the sensors are AC-coupled, and a mean removed from the force of a
        # periodic block would leave 0/0 (NaN) on the 0 Hz line
        return SpectralAccumulator(self.plan.record.fs, s.nperseg, 0, detrend=False,
                                   window=WINDOWS[s.waveform], references=(0,))

    def add(self, hit_id: int, point: int, data: NDArray[np.float64],
            override: str = "") -> tuple[bool, str, float] | None:
        """Judge a stored block; returns its verdict (None if it has lost samples)."""
        self._point_of[hit_id] = point
        verdict = block_verdict(data, self.names, self.ranges)
        if not np.all(np.isfinite(data)):
            self._data.pop(hit_id, None)
            return None
        self._data[hit_id] = data
        return verdict

    def point_of(self, hit_id: int) -> int:
        """The excitation point of stored block ``hit_id``."""
        return self._point_of[hit_id]

    def set_used(self, hit_id: int, used: bool) -> None:
        self._accepted[hit_id] = used and hit_id in self._data

    def n_used(self, point: int) -> int:
        return sum(1 for h, p in self._point_of.items() if p == point and self._accepted.get(h))

    def point(self, point: int, max_averages: int | None = None) -> BlockResult | None:
        """The averaged column of ``point`` from its accepted blocks (the first
        ``max_averages`` of them when given; None if none)."""
        ids = sorted(h for h, p in self._point_of.items() if p == point and self._accepted.get(h))
        if max_averages is not None:
            ids = ids[:max_averages]
        if not ids:
            return None
        st = self._points.get(point)
        if st is None or st.ids != ids[: len(st.ids)]:  # a block left: start again
            st = self._points[point] = _Point(self._accumulator())
        for h in ids[len(st.ids):]:  # one block per update, in acquisition order
            st.acc.update(self._data[h])
            st.ids.append(h)
        sp = st.acc.spectra()
        H, coh = frf(sp, self.plan.record.estimator)
        return BlockResult(sp.freq, H, coh, sp, len(ids))


def shaker_frfset(plan: TestPlan, points: Sequence[BlockResult | None], geometry: Geometry,
                  resp_nodes: NDArray[np.int64], resp_dirs: NDArray[np.float64]) -> FRFSet:
    """All points' FRF columns as one FRF set (raises InputError naming a point without blocks)."""
    cols, cohs = [], []
    for j, r in enumerate(points):
        if r is None:
            raise InputError(f"excitation {plan.excitations[j].label} has no accepted block: "
                             "resume the run (insitu acquire --resume)")
        cols.append(r.H)
        cohs.append(r.coherence)
    first = next(r for r in points if r is not None)
    return FRFSet(first.freq, np.concatenate(cols, axis=1), resp_nodes, resp_dirs,
                  plan.exc_nodes, plan.exc_dirs, geometry, np.concatenate(cohs, axis=1),
                  {"estimator": plan.record.estimator,
                   "excitation": f"shaker {plan.shaker.waveform}",
                   "window": WINDOWS[plan.shaker.waveform],
                   "n_averages": [0 if r is None else r.n_accepted for r in points]})
