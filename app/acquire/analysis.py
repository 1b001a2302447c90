"""From stored records to FRFs and the identification: one code path for live runs and replay.

The live procedure and ``insitu replay`` both call :func:`hit_result` on the
record exactly as it is stored in the run file and :func:`point_result` on the
results of a point's accepted hits, in acquisition order, so a replay gives the
same FRFs and the same identification, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.acquire.plan import RecordSettings, TestPlan
from app.io.runfile import RunData
from processing.data import FRFSet, Geometry, InputError
from processing.identify import IdentificationResult, IdentifyOptions, identify
from processing.impact import (
    ImpactResult,
    ImpactSettings,
    impact_frfset,
    merge_results,
    process_impacts,
)

__all__ = ["RunAnalysis", "analyse_run", "frfset", "hit_result", "impact_settings",
           "margin_samples", "point_result"]


def margin_samples(fs: float) -> int:
    """Samples stored before and after each hit record (10 ms, at least 8)."""
    return max(8, round(0.01 * fs))


def impact_settings(record: RecordSettings) -> ImpactSettings:
    """The processing settings of a plan's record section."""
    return ImpactSettings(level=record.trigger_level, record_length=record.n_samples,
                          pretrigger=record.n_pretrigger, exp_tau=record.exp_tau)


def hit_result(data: NDArray[np.float64], record: RecordSettings, names: Sequence[str],
               ranges: NDArray[np.float64] | None, override: str = "") -> ImpactResult:
    """Verdict, windows and spectra of one stored hit record (force row 0, N; responses m/s^2).

    ``override="accept"`` processes a hit the automatic checks rejected as if it had
    passed them (double-hit and overload checks relaxed; same trigger and record).
    Records with lost samples cannot be accepted, whatever the override.
    """
    if not np.all(np.isfinite(data)):
        raise InputError("the record has lost samples (corrupted or dropped frames)")
    settings = impact_settings(record)
    if override == "accept":
        settings = replace(settings, double_hit_ratio=0.999999,
                           clip_samples=settings.record_length)
        ranges = None
    return process_impacts(data, record.fs, settings, channel_names=list(names),
                           ranges=ranges, estimator=record.estimator)


def point_result(results: Sequence[ImpactResult]) -> ImpactResult | None:
    """The averaged FRF column of a point from its accepted hits' results (None if none)."""
    used = [r for r in results if r.H is not None]
    return merge_results(used) if used else None


def frfset(plan: TestPlan, points: Sequence[ImpactResult], geometry: Geometry,
           resp_nodes: NDArray[np.int64], resp_dirs: NDArray[np.float64]) -> FRFSet:
    """All points' FRF columns as one FRF set (raises InputError naming a point without hits)."""
    return impact_frfset(points, geometry, resp_nodes, resp_dirs, plan.exc_nodes, plan.exc_dirs)


def identify_frfs(frf: FRFSet, options: IdentifyOptions | None = None) -> IdentificationResult:
    """The identification of a run's FRFs, on the lines above 0 Hz and up to fs / 2.56
    (above it the front ends' anti-alias filters shape the data)."""
    keep = (frf.freq > 0) & (frf.freq <= frf.freq[-1] / 1.28)
    coh = None if frf.coherence is None else np.nan_to_num(frf.coherence[..., keep])
    cut = FRFSet(frf.freq[keep], frf.H[..., keep], frf.resp_nodes, frf.resp_dirs,
                 frf.exc_nodes, frf.exc_dirs, frf.geometry, coh, dict(frf.meta))
    return identify(cut, options or IdentifyOptions())


class RunAnalysis:
    """FRFs of a run, point by point, kept up to date as hits come and verdicts change.

    Parameters
    ----------
    plan : TestPlan
    names : channel names of the record rows (force first)
    ranges : full-scale range of each row in its unit (for overload checks)
    """

    def __init__(self, plan: TestPlan, names: Sequence[str],
                 ranges: NDArray[np.float64] | None) -> None:
        self.plan = plan
        self.names = tuple(names)
        self.ranges = ranges
        self._results: dict[int, ImpactResult | None] = {}
        self._point_of: dict[int, int] = {}
        self._accepted: dict[int, bool] = {}

    def add(self, hit_id: int, point: int, data: NDArray[np.float64],
            override: str = "") -> ImpactResult | None:
        """Process a stored record; returns its result (None if it has lost samples)."""
        try:
            res: ImpactResult | None = hit_result(data, self.plan.record, self.names,
                                                  self.ranges, override)
        except InputError:
            res = None
        self._results[hit_id] = res
        self._point_of[hit_id] = point
        return res

    def set_used(self, hit_id: int, used: bool) -> None:
        self._accepted[hit_id] = used

    def point(self, point: int) -> ImpactResult | None:
        ids = sorted(h for h, p in self._point_of.items() if p == point)
        return point_result([r for h in ids if self._accepted.get(h) and
                             (r := self._results[h]) is not None])

    def n_used(self, point: int) -> int:
        return sum(1 for h, p in self._point_of.items() if p == point and self._accepted.get(h))


def analyse_run(run: RunData, options: IdentifyOptions | None = None) -> (
    tuple[FRFSet, IdentificationResult, RunAnalysis]
):
    """Recompute every verdict, the FRFs and the identification from a run file's raw records."""
    from app.acquire.plan import parse_plan

    plan = parse_plan(run.plan_data, f"{run.path}:/plan")
    rows = run.channels
    ranges = np.array([c.range_v * 1000.0 / c.sensitivity for c in rows])
    ana = RunAnalysis(plan, [c.name for c in rows], ranges)
    rec = run.records
    for i in range(len(rec)):
        res = ana.add(i, int(rec.point[i]), rec.data[i], rec.override[i])
        auto = res is not None and bool(res.verdicts) and res.verdicts[0].accepted
        used = auto if not rec.override[i] else rec.override[i] == "accept" and res is not None
        ana.set_used(i, bool(used))
    points: list[Any] = [ana.point(j) for j in range(len(plan.excitations))]
    for j, r in enumerate(points):
        if r is None:
            raise InputError(f"{run.path}: excitation {plan.excitations[j].label} has no "
                             "accepted hit: resume the run (insitu acquire --resume)")
    resp = rows[1:]
    frf = frfset(plan, points, run.geometry, np.array([c.node for c in resp]),
                 np.array([c.direction for c in resp]))
    return frf, identify_frfs(frf, options), ana
