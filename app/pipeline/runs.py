"""Run files (``.h5`` written by ``insitu acquire``) -> a measurement.

Every stored hit or block is processed again with the plan's settings and the operator's
overrides by the live acquisition's own code (:func:`app.acquire.analysis.run_measurement`,
which the live run's own result comes from too), so the FRFs, their provenance and the fit
are the live run's. ``Settings.run_points`` says what a point without a used record does.
The records are read from the file one at a time (:func:`app.io.runfile.iter_record_data`),
as the analysis reaches them: memory holds a record and the points' spectra, not the run.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from app.acquire.analysis import (
    RecordLoader,
    analyse_records,
    analysis_measurement,
    anti_aliased,
    check_identifiable,
    run_measurement,
)
from app.io.runfile import RunData, iter_record_data, read_run
from app.pipeline.assemble import assemble, check_reports
from app.pipeline.settings import OpenError, RunReport, Settings
from processing.data import InputError
from processing.measurement import Measurement

__all__ = ["open_run_file"]


def open_run_file(path: Path, s: Settings) -> Measurement:
    """The measurement of a run file.

    With ``s.run_points == "all"``: every point's FRF column (InputError naming a point
    without a used record; a run whose force is aligned by host timing only is refused), on
    the lines up to fs / 2.56, with the per-hit or per-block spectra and the run's state;
    no report.
    With ``"usable"``: the points with a used record (the others reported and left out,
    the first ``s.averages`` used records of each point averaged), on the lines up to
    ``s.fmax`` (default fs / 2.56), with the checks reported.
    """
    run = read_run(path, with_data=False)
    if len(run.records) == 0:
        raise OpenError(f"{path}: the run holds no hit yet: record hits (insitu acquire)")
    if s.run_points == "usable":
        return _usable_points(run, path, s)
    check_identifiable(run)
    m = anti_aliased(run_measurement(run, loader=_loader(path))[0])
    return dataclasses.replace(m, provenance=dataclasses.replace(m.provenance,
                                                                 run_state=run.state))


def _loader(path: Path) -> RecordLoader:
    """Reads the run file's records ``ids`` one at a time."""
    return lambda ids: iter_record_data(path, ids)


def _usable_points(run: RunData, path: Path, s: Settings) -> Measurement:
    """The measurement of the points with a used record, each other point reported and
    left out."""
    fmax = s.fmax if s.fmax is not None else run.records.fs / 2.56
    reports: list[RunReport] = []
    if run.method != "hammer":  # shaker runs: the run's own FRFs (every point needed)
        m = run_measurement(run, s.averages, _loader(path))[0]
    else:
        plan, ana = analyse_records(run, _loader(path))
        rec = run.records
        good: list[int] = []
        for j, point in enumerate(plan.excitations):
            mine = np.flatnonzero(rec.point == j)
            res = ana.point(j, s.averages)
            if res is None or res.H is None or res.coherence is None:
                why = ("no hit recorded" if mine.size == 0 else "every hit rejected ("
                       + "; ".join(rec.reason[i] or "rejected" for i in mine) + ")")
                reports.append(RunReport(f"{point.label}: {why}: hit it again (insitu acquire "
                                         "--resume)", skipped=True))
                continue
            n_used = ana.n_used(j) if s.averages is None else min(ana.n_used(j), s.averages)
            reports.append(RunReport(f"{point.label}: {n_used} of {mine.size} hits used"))
            good.append(j)
        if not good:
            raise OpenError(f"{path}: no point has an accepted hit ({len(reports)} points, "
                            "see above)", reports)
        rows = run.channels[1:]
        try:
            m = analysis_measurement(ana, run.geometry, np.array([c.node for c in rows]),
                                     np.array([c.direction for c in rows]), path.name, good,
                                     s.averages)
        except InputError as err:
            raise OpenError(str(err), reports) from err
    col = m.frf
    assert col.coherence is not None
    out, kept = assemble(col.freq, [col.H], [col.coherence], col.resp_nodes, col.resp_dirs,
                         col.exc_nodes, col.exc_dirs, col.geometry, fmax, reports)
    reports += check_reports(out, s.coherence)
    n_avg = m.provenance.n_averages
    return dataclasses.replace(m, frf=out, provenance=dataclasses.replace(
        m.provenance, anti_alias_fmax=fmax, run_state=run.state, reports=tuple(reports),
        n_averages=tuple(n for n, k in zip(n_avg, kept, strict=True) if k) if n_avg else ()))
