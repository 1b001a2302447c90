"""Run files (``.h5`` written by ``insitu acquire``) -> FRFs.

Every stored hit or block is processed again with the plan's settings and the operator's
overrides by the live acquisition's own code (:mod:`app.acquire.analysis`), so the FRFs are
the live run's. ``Settings.run_points`` says what a point without a used record does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.acquire.analysis import analyse_records, check_identifiable, run_frfs, run_units
from app.io.runfile import RunData, read_run
from app.pipeline.assemble import assemble, check_reports
from app.pipeline.settings import OpenError, RunReport, Settings
from processing.data import FRFSet
from processing.identify import FROM_TIME_RECORDS
from processing.impact import ImpactResult, impact_frfset

__all__ = ["open_run_file"]


def open_run_file(path: Path, s: Settings) -> tuple[FRFSet, list[RunReport]]:
    """The FRFs of a run file.

    With ``s.run_points == "all"``: every point's FRF column (InputError naming a point
    without a used record; a run whose force is aligned by host timing only is refused),
    or the FRFs stored when the run finished if ``s.stored``; on the lines up to fs / 2.56,
    with ``meta["file"]`` and ``meta["run_state"]`` set; no report.
    With ``"usable"``: the points with a used record (the others reported and left out,
    the first ``s.averages`` used records of each point averaged), on the lines up to
    ``s.fmax`` (default fs / 2.56), with the checks reported.
    """
    run = read_run(path)
    if s.run_points == "usable":
        return _usable_points(run, path, s)
    if s.stored and run.frf is not None:
        whole = run.frf
    elif len(run.records) == 0:
        raise OpenError(f"{path}: the run holds no hit yet")
    else:
        check_identifiable(run)
        whole, ana = run_frfs(run)
        whole.meta["time_units"] = run_units(ana)  # per hit or block: the bootstrap
    out = whole.select_lines(whole.anti_alias_fmax())
    out.meta.update({"file": Path(path).name, "run_state": run.state,
                     FROM_TIME_RECORDS: True})
    if run.mounts is not None:
        out.meta["mounts"] = run.mounts
    return out, []


def _usable_points(run: RunData, path: Path, s: Settings) -> tuple[FRFSet, list[RunReport]]:
    """The FRFs of the points with a used record, each other point reported and left out."""
    if len(run.records) == 0:
        raise OpenError(f"{path}: the run holds no hit yet: record hits (insitu acquire)")
    fmax = s.fmax if s.fmax is not None else run.records.fs / 2.56
    reports: list[RunReport] = []
    if run.method != "hammer":  # shaker runs: the run's own FRFs (every point needed)
        frfs, blocks = run_frfs(run, s.averages)
        assert frfs.coherence is not None
        frfs.meta["time_units"] = run_units(blocks, s.averages)
        out = assemble(frfs.freq, [frfs.H], [frfs.coherence], frfs.resp_nodes, frfs.resp_dirs,
                       frfs.exc_nodes, frfs.exc_dirs, frfs.geometry, dict(frfs.meta), fmax,
                       reports)
        return out, reports + check_reports(out, s.coherence)
    plan, ana = analyse_records(run)
    rec = run.records
    good: list[int] = []
    results: list[ImpactResult] = []
    for j, point in enumerate(plan.excitations):
        mine = np.flatnonzero(rec.point == j)
        res = ana.point(j, s.averages)
        if res is None or res.H is None or res.coherence is None:
            why = ("no hit recorded" if mine.size == 0 else
                   f"every hit rejected ({'; '.join(rec.reason[i] or 'rejected' for i in mine)})")
            reports.append(RunReport(f"{point.label}: {why}: hit it again (insitu acquire "
                                     "--resume)", skipped=True))
            continue
        n_used = ana.n_used(j) if s.averages is None else min(ana.n_used(j), s.averages)
        reports.append(RunReport(f"{point.label}: {n_used} of {mine.size} hits used"))
        good.append(j)
        results.append(res)
    if not results:
        raise OpenError(f"{path}: no point has an accepted hit ({len(reports)} points, see "
                        "above)", reports)
    rows = run.channels[1:]
    col = impact_frfset(results, run.geometry, np.array([c.node for c in rows]),
                        np.array([c.direction for c in rows]), plan.exc_nodes[good],
                        plan.exc_dirs[good])
    col.meta["time_units"] = run_units(ana, s.averages)  # per hit: the bootstrap
    assert col.coherence is not None
    out = assemble(col.freq, [col.H], [col.coherence], col.resp_nodes, col.resp_dirs,
                   col.exc_nodes, col.exc_dirs, col.geometry, col.meta, fmax, reports)
    return out, reports + check_reports(out, s.coherence)

