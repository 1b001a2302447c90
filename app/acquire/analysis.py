"""From stored records to FRFs and the identification: one code path for live runs and replay.

The live procedure and ``insitu replay`` both call :func:`hit_result` on the
record exactly as it is stored in the run file and :func:`point_result` on the
results of a point's accepted hits, in acquisition order, so a replay gives the
same FRFs and the same identification, bit for bit.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from app.acquire.blocks import BlockAnalysis, RecordLoader, shaker_measurement
from app.acquire.plan import RecordSettings, TestPlan
from app.io.runfile import RunData
from processing.blas import one_blas_thread
from processing.data import Geometry, InputError
from processing.impact import (
    ImpactResult,
    ImpactSettings,
    impact_measurement,
    merge_results,
    process_impacts,
)
from processing.measurement import Measurement
from processing.units import TimeUnits, UnitSpectra

__all__ = ["PointColumn", "RecordAnalysis", "RecordLoader", "RunAnalysis", "analyse_blocks",
           "analyse_records", "analysis_measurement", "anti_aliased", "check_identifiable",
           "hit_result", "host_timed", "impact_settings", "margin_samples",
           "point_result", "run_measurement", "run_units"]


def margin_samples(fs: float) -> int:
    """Samples stored before and after each hit record (10 ms, at least 8)."""
    return max(8, round(0.01 * fs))


def impact_settings(record: RecordSettings) -> ImpactSettings:
    """The processing settings of a plan's record section. No record tails: a live run's
    FRFs must be the same bits in every process that replays it, and with the tails' fit
    of damped sinusoids (least squares through BLAS) the acquiring process and the replay
    did not always agree to the last bit."""
    return ImpactSettings(level=record.trigger_level, record_length=record.n_samples,
                          pretrigger=record.n_pretrigger, exp_tau=record.exp_tau)


@one_blas_thread
def hit_result(data: NDArray[np.float64], record: RecordSettings, names: Sequence[str],
               ranges: NDArray[np.float64] | None, override: str = "") -> ImpactResult:
    """Verdict, windows and spectra of one stored hit record (force row 0, N; responses m/s^2).

    ``override="accept"`` uses a hit the automatic checks rejected (the checks still
    run and their finding stays in the verdict's reason; a double hit's force window
    spans the rebound: :func:`processing.impact.process_impacts` ``force_accept``).
    Records with lost samples cannot be accepted, whatever the override.
    """
    if not np.all(np.isfinite(data)):
        raise InputError("the record has lost samples (corrupted or dropped frames)")
    return process_impacts(data, record.fs, impact_settings(record), channel_names=list(names),
                           ranges=ranges, estimator=record.estimator,
                           force_accept=override == "accept")


def point_result(results: Sequence[ImpactResult]) -> ImpactResult | None:
    """The averaged FRF column of a point from its accepted hits' results (None if none)."""
    used = [r for r in results if r.H is not None]
    return merge_results(used) if used else None


def anti_aliased(m: Measurement) -> Measurement:
    """A run's measurement on its lines above 0 Hz and up to fs / 2.56 (above it the front
    ends' anti-alias filters shape the data)."""
    fmax = m.frf.anti_alias_fmax()
    return dataclasses.replace(m, frf=m.frf.select_lines(fmax), provenance=dataclasses.replace(
        m.provenance, anti_alias_fmax=fmax))


class PointColumn(Protocol):
    """A point's averaged FRF column: :class:`~processing.impact.ImpactResult` (hits) or
    :class:`~app.acquire.blocks.BlockResult` (shaker blocks).

    ``freq`` Hz; ``H`` (n_resp, 1, n_f) accelerance, (m/s^2)/N, and ``coherence`` (n_resp,
    1, n_f), None when no record is accepted; ``n_accepted`` records averaged.
    """

    @property
    def freq(self) -> NDArray[np.float64]: ...
    @property
    def H(self) -> NDArray[np.complex128] | None: ...
    @property
    def coherence(self) -> NDArray[np.float64] | None: ...
    @property
    def n_accepted(self) -> int: ...


class RecordAnalysis(Protocol):
    """What a run's analysis offers, record by record: :class:`RunAnalysis` (hammer hits)
    and :class:`~app.acquire.blocks.BlockAnalysis` (shaker blocks).

    :meth:`add` a stored record to point ``point`` (its result, or None when it has lost
    samples), :meth:`set_used` its verdict in force, :meth:`n_used` the records a point
    averages, :meth:`point` its averaged column (the first ``max_averages`` used records).
    """

    plan: TestPlan
    names: tuple[str, ...]
    ranges: NDArray[np.float64] | None

    def add(self, hit_id: int, point: int, data: NDArray[np.float64],
            override: str = "") -> object: ...
    def set_used(self, hit_id: int, used: bool) -> None: ...
    def n_used(self, point: int) -> int: ...
    def point(self, point: int, max_averages: int | None = None) -> PointColumn | None: ...
    def unit_spectra(self, point: int, max_averages: int | None = None,
                     ) -> UnitSpectra | None: ...


class RunAnalysis:
    """FRFs of a run, point by point, kept up to date as hits come and verdicts change.

    Memory does not grow with the records: each point keeps the running average of its
    used hits' spectra (:func:`processing.spectral.combine`, the sums the H1/H2 FRFs and
    the coherence come from), folded in acquisition order as hits come; per hit, only its
    point, override and verdict in force. A change that cannot be folded in (a verdict
    changed on an older hit, an override) marks the point, whose average is then rebuilt
    from the stored records, read one at a time with ``loader``, in acquisition order: the
    result is the same, bit for bit, as averaging the point's used hits at once
    (:func:`point_result`).

    Parameters
    ----------
    plan : TestPlan
    names : channel names of the record rows (force first)
    ranges : full-scale range of each row in its unit (for overload checks)
    loader : callable, optional
        ``loader(ids)`` yields ``(id, data)`` for the stored records ``ids`` (e.g.
        :func:`app.io.runfile.iter_record_data` of the run file). Without it, a rebuild
        raises RuntimeError.
    """

    def __init__(self, plan: TestPlan, names: Sequence[str],
                 ranges: NDArray[np.float64] | None, loader: RecordLoader | None = None
                 ) -> None:
        self.plan = plan
        self.names = tuple(names)
        self.ranges = ranges
        self.loader = loader
        self._point_of: dict[int, int] = {}
        self._override: dict[int, str] = {}
        self._accepted: dict[int, bool] = {}
        self._n_used: dict[int, int] = {}
        self._sum: dict[int, ImpactResult] = {}  # point -> its used hits averaged so far
        self._last: dict[int, int] = {}  # point -> the last hit folded into its average
        self._stale: set[int] = set()  # points whose average must be rebuilt
        self._pending: tuple[int, ImpactResult | None] | None = None  # added, verdict to come

    def add(self, hit_id: int, point: int, data: NDArray[np.float64],
            override: str = "") -> ImpactResult | None:
        """Process a stored record; returns its result (None if it has lost samples).

        The result counts in its point's average once :meth:`set_used` says so."""
        try:
            res: ImpactResult | None = hit_result(data, self.plan.record, self.names,
                                                  self.ranges, override)
        except InputError:
            res = None
        if hit_id in self._point_of and (self._accepted.get(hit_id)
                                         or self._point_of[hit_id] != point):
            self._stale.add(self._point_of[hit_id])  # a used hit judged again
        self._point_of[hit_id] = point
        self._override[hit_id] = override
        self._pending = (hit_id, res)
        return res

    def point_of(self, hit_id: int) -> int:
        """The excitation point of stored hit ``hit_id``."""
        return self._point_of[hit_id]

    def set_used(self, hit_id: int, used: bool) -> None:
        """Whether hit ``hit_id`` (added before) counts in its point's average."""
        point = self._point_of[hit_id]
        was = self._accepted.get(hit_id, False)
        self._accepted[hit_id] = used
        self._n_used[point] = self._n_used.get(point, 0) + int(used) - int(was)
        pending, self._pending = self._pending, None
        if not used and not was:
            return
        res = pending[1] if pending is not None and pending[0] == hit_id else None
        if (used and not was and res is not None and res.H is not None
                and point not in self._stale and hit_id > self._last.get(point, -1)):
            old = self._sum.get(point)
            self._sum[point] = merge_results([res] if old is None else [old, res])
            self._last[point] = hit_id
        else:
            self._stale.add(point)

    def point(self, point: int, max_averages: int | None = None) -> ImpactResult | None:
        """The point's FRF column from its used hits (the first ``max_averages`` of them,
        in acquisition order, when given); None if it has none."""
        if max_averages is None and point not in self._stale:
            return self._sum.get(point)
        ids = sorted(h for h, p in self._point_of.items() if p == point and self._accepted[h])
        if max_averages is not None:
            ids = ids[:max_averages]
        total = self._rebuild(ids)
        if max_averages is None:
            self._stale.discard(point)
            self._last[point] = ids[-1] if ids else -1
            if total is None:
                self._sum.pop(point, None)
            else:
                self._sum[point] = total
        return total

    def _rebuild(self, ids: Sequence[int]) -> ImpactResult | None:
        """The average of hits ``ids`` read back from the stored records, in order."""
        if not ids:
            return None
        if self.loader is None:
            raise RuntimeError("rebuilding a point's average needs the stored records: give "
                               "RunAnalysis a loader")
        total: ImpactResult | None = None
        for i, data in self.loader(ids):
            try:
                res = hit_result(data, self.plan.record, self.names, self.ranges,
                                 self._override.get(i, ""))
            except InputError:
                continue
            if res.H is not None:
                total = merge_results([res] if total is None else [total, res])
        return total

    def n_used(self, point: int) -> int:
        return self._n_used.get(point, 0)

    def used_ids(self, point: int, max_averages: int | None = None) -> list[int]:
        """The point's used hits in acquisition order (the first ``max_averages``)."""
        ids = sorted(h for h, p in self._point_of.items() if p == point and self._accepted[h])
        return ids if max_averages is None else ids[:max_averages]

    def unit_spectra(self, point: int, max_averages: int | None = None) -> UnitSpectra | None:
        """The spectra of each of the point's used hits (the units :meth:`point` averages),
        read back with ``loader``; None without a used hit."""
        ids = self.used_ids(point, max_averages)
        if not ids or self.loader is None:
            return None
        spectra = []
        for i, data in self.loader(ids):
            res = hit_result(data, self.plan.record, self.names, self.ranges,
                             self._override.get(i, ""))
            if res.spectra is not None:
                spectra.append(res.spectra)
        return UnitSpectra.of(spectra) if spectra else None


def _run_setup(run: RunData) -> tuple[TestPlan, list[str], NDArray[np.float64]]:
    """A run file's plan, record row names and their full-scale ranges."""
    from app.acquire.plan import parse_plan

    rows = run.channels
    return (parse_plan(run.plan_data, f"{run.path}:/plan"), [c.name for c in rows],
            np.array([c.range_v * 1000.0 / c.sensitivity for c in rows]))


def _records(run: RunData, loader: RecordLoader | None) -> RecordLoader:
    """``loader``, or the run's records held in memory read as a loader reads them."""
    rec = run.records
    return loader or (lambda ids: ((i, rec.data[i]) for i in ids))


def analyse_records(run: RunData, loader: RecordLoader | None = None,
                    ) -> tuple[TestPlan, RunAnalysis]:
    """Recompute every stored record's verdict and spectra (no FRF set, no identification);
    ``RunAnalysis.point(j)`` is then point ``j``'s FRF column or None. ``loader`` reads the
    records (one at a time, e.g. :func:`app.io.runfile.iter_record_data`; default: the
    run's ``records.data``)."""
    plan, names, ranges = _run_setup(run)
    rec = run.records
    load = _records(run, loader)
    ana = RunAnalysis(plan, names, ranges, loader=load)
    for i, data in load(range(len(rec))):
        res = ana.add(i, int(rec.point[i]), data, rec.override[i])
        auto = res is not None and bool(res.verdicts) and res.verdicts[0].accepted
        used = auto if not rec.override[i] else rec.override[i] == "accept" and res is not None
        ana.set_used(i, bool(used))
    return plan, ana


def analyse_blocks(run: RunData, loader: RecordLoader | None = None,
                   ) -> tuple[TestPlan, BlockAnalysis]:
    """A shaker run's :func:`analyse_records`: every stored block judged again and averaged.

    A block rejected live for what its samples cannot show (the shaker's output went
    off) keeps that verdict: the stored automatic verdict can be confirmed, never upgraded.
    """
    plan, names, ranges = _run_setup(run)
    rec = run.records
    load = _records(run, loader)
    blocks = BlockAnalysis(plan, names, ranges, loader=load)
    for i, data in load(range(len(rec))):
        v = blocks.add(i, int(rec.point[i]), data, rec.override[i])
        auto = bool(rec.auto_accepted[i]) and v is not None and v[0]
        used = (rec.override[i] == "accept") if rec.override[i] else auto
        blocks.set_used(i, v is not None and used)
    return plan, blocks


def run_units(ana: RecordAnalysis, max_averages: int | None = None) -> TimeUnits | None:
    """The per-hit (hammer) or per-block (shaker) spectra of every point with a used record,
    for the bootstrap (:mod:`processing.bootstrap`); None when no point has one, or when the
    plan drives several shakers at once (the bootstrap resamples one reference per column)."""
    plan = ana.plan
    if plan.n_references > 1:
        return None
    cols, keep = [], []
    for j in range(len(plan.excitations)):
        u = ana.unit_spectra(j, max_averages)
        if u is not None:
            cols.append(u)
            keep.append(j)
    if not cols:
        return None
    return TimeUnits("hit" if isinstance(ana, RunAnalysis) else "block", tuple(cols),
                     plan.exc_nodes[keep], plan.exc_dirs[keep], plan.record.estimator)


def check_identifiable(run: RunData) -> None:
    """Refuse (InputError, one line) a run whose force was aligned by host timing only."""
    if run.records.force_alignment == "host-timed":
        dev = run.channels[0].device if run.channels else "?"
        ref = run.channels[1].device if len(run.channels) > 1 else "?"
        raise InputError(f"{run.path}: not identified: {host_timed(dev, ref)}")


@one_blas_thread
def analysis_measurement(ana: RecordAnalysis, geometry: Geometry,
                         resp_nodes: NDArray[np.int64], resp_dirs: NDArray[np.float64],
                         source: str, points: Sequence[int] | None = None,
                         max_averages: int | None = None) -> Measurement:
    """The measurement of a run's analysis, on all its lines: the FRF columns of ``points``
    (hammer; every point when None) or of every drive (shaker), each averaging its first
    ``max_averages`` used records (all when None), with the per-hit or per-block spectra
    (:func:`run_units`), and for hits the window's tau and the hammer's usable band. The
    live run and a run file's records (:func:`run_measurement`) both come here.

    Raises InputError naming a point (a drive) without a used record.
    """
    plan = ana.plan
    units = run_units(ana, max_averages)
    if isinstance(ana, RunAnalysis):
        idx = list(range(len(plan.excitations))) if points is None else list(points)
        cols = [ana.point(j, max_averages) for j in idx]
        for j, r in zip(idx, cols, strict=True):
            if r is None:
                raise InputError(f"excitation {plan.excitations[j].label} has no accepted "
                                 "hit: resume the run (insitu acquire --resume)")
        m = impact_measurement([r for r in cols if r is not None], geometry, resp_nodes,
                               resp_dirs, plan.exc_nodes[idx], plan.exc_dirs[idx], units)
    else:
        assert isinstance(ana, BlockAnalysis)
        drives = [ana.point(d, max_averages) for d in range(len(plan.drives))]
        m = shaker_measurement(plan, drives, geometry, resp_nodes, resp_dirs, units)
    return dataclasses.replace(m, source=source)


@one_blas_thread
def run_measurement(run: RunData, max_averages: int | None = None,
                    loader: RecordLoader | None = None,
                    ) -> tuple[Measurement, RecordAnalysis]:
    """The measurement of a run file's stored records, every record judged again
    (:func:`analysis_measurement` of :func:`analyse_records` or :func:`analyse_blocks`,
    the records read with ``loader`` when given), and the analysis it comes from (the
    identification refuses a run whose force was aligned by host timing only:
    :func:`check_identifiable`)."""
    if run.method == "shaker":
        _, blocks = analyse_blocks(run, loader)
        resp = run.channels[blocks.plan.n_references:]
        ana: RecordAnalysis = blocks
    else:
        _, ana = analyse_records(run, loader)
        resp = run.channels[1:]
    try:
        m = analysis_measurement(ana, run.geometry, np.array([c.node for c in resp]),
                                 np.array([c.direction for c in resp]), Path(run.path).name,
                                 max_averages=max_averages)
    except InputError as err:
        raise InputError(f"{run.path}: {err}") from err
    return m, ana


def host_timed(force_device: str, frontend: str) -> str:
    """Why a run whose force is aligned by host timing only is not identified (one line)."""
    return (f"the force comes from {force_device!r}, aligned to front end {frontend!r} by host "
            "timing only (about 1 ms: 20 degrees of phase at 55 Hz, the mass line comes out "
            "tens of percent off): record the same force on a front-end input too (a common "
            "channel) so every hit is aligned on it, or acquire FRFs only (no identification)")
