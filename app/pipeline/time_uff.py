"""UFF time records -> FRFs: runs grouped by excitation DOF, averaged, checked.

Each run (its records sharing a load case: one force, the accelerations) gives the FRF
column of its excitation DOF; runs at the same DOF are averaged together. ``random``
(shaker: Welch, segments of ``nperseg`` samples) or ``impact`` (hammer: trigger,
per-hit checks, force and exponential windows). A bad run is reported and left out.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from app.io.uff import read_time_uff
from app.io.uff_geometry import read_geometry_uff
from app.io.uff_time import TimeRun
from app.pipeline.assemble import assemble, check_reports
from app.pipeline.settings import OpenError, RunReport, Settings, n_skipped
from processing.data import FRFSet, InputError
from processing.impact import ImpactResult, ImpactSettings, merge_results, process_impacts
from processing.spectral import CrossSpectra, SpectralAccumulator, combine, frf

__all__ = ["open_time_uff"]

#: one FRF column: H (n_resp, 1, n_f), coherence, frequency lines (Hz)
Column = tuple[NDArray[np.complex128], NDArray[np.float64], NDArray[np.float64]]
DofKey = tuple[int, tuple[float, ...]]


def _random_spectra(r: TimeRun, s: Settings) -> CrossSpectra:
    nperseg = s.nperseg
    if r.n_samples < nperseg:
        raise InputError(f"load case {r.load_case}: {r.n_samples} samples, fewer than "
                         f"--nperseg {nperseg}: lower --nperseg or record longer")
    noverlap = round(s.overlap * nperseg)
    # a whole recording in one block: both cores of a bench PC (more gain little)
    acc = SpectralAccumulator(r.fs, nperseg, noverlap, window=s.window,
                              workers=min(2, os.cpu_count() or 1))
    n = r.n_samples
    if s.averages is not None:  # the samples of the first N segments
        n = min(n, (s.averages - 1) * (nperseg - noverlap) + nperseg)
    acc.update(np.vstack([r.force[None, :n], r.responses[:, :n]]))
    return acc.spectra()


def _impact(r: TimeRun, s: Settings, max_averages: int | None = None) -> ImpactResult:
    """Hits of one run, the first ``max_averages`` accepted ones averaged; InputError (naming
    the load case) when none can be used."""
    lc = f"load case {r.load_case}"
    peak = float(np.max(np.abs(r.force)))
    if s.level is None and peak == 0:
        raise InputError(f"{lc}: the force channel is zero throughout: check the hammer channel")
    level = s.level if s.level is not None else 0.1 * peak
    settings = ImpactSettings(
        level=level, record_length=round(s.record * r.fs),
        pretrigger=round(s.pretrigger * r.fs),
        slope="rising" if level > 0 else "falling", exp_tau=s.exp_tau,
    )
    names = ["force", *(f"response {i + 1}" for i in range(r.responses.shape[0]))]
    res = process_impacts(np.vstack([r.force[None], r.responses]), r.fs, settings,
                          channel_names=names, estimator=s.estimator,
                          max_averages=max_averages)
    if not res.verdicts:
        raise InputError(f"{lc}: no hit found (the force never crosses {level:g} N): lower "
                         "--level or check the force channel")
    if res.H is None:
        why = "; ".join(f"hit {v.index + 1}: {v.reason}" for v in res.verdicts)
        raise InputError(f"{lc}: every hit rejected ({why}): measure the point again")
    return res


def _consistent(runs: list[TimeRun], reports: list[RunReport]) -> list[TimeRun]:
    """The runs with the first run's sample rate and response DOFs; the others reported."""
    first = runs[0]
    good: list[TimeRun] = []
    for r in runs:
        if r.fs != first.fs or not (np.array_equal(r.resp_nodes, first.resp_nodes)
                                    and np.allclose(r.resp_dirs, first.resp_dirs)):
            what = (f"sample rate {r.fs:g} Hz differs from load case {first.load_case}'s "
                    f"{first.fs:g} Hz" if r.fs != first.fs else
                    f"response DOFs differ from load case {first.load_case}'s")
            reports.append(RunReport(f"load case {r.load_case}: {what}: process such runs in "
                                     "separate files", skipped=True))
        else:
            good.append(r)
    return good


def _impact_column(key: DofKey, members: list[TimeRun], s: Settings,
                   reports: list[RunReport]) -> Column | None:
    """The averaged hits of one excitation DOF's runs (None when none is usable)."""
    results: list[ImpactResult] = []
    for r in members:
        left = None
        if s.averages is not None:  # the first N accepted hits of the point
            left = s.averages - sum(one.n_accepted for one in results)
            if left == 0:
                reports.append(RunReport(f"load case {r.load_case} (node {key[0]}): not used, "
                                         f"the first {s.averages} accepted hits of the point "
                                         "are averaged"))
                continue
        try:
            one = _impact(r, s, left)
        except InputError as err:
            reports.append(RunReport(str(err), skipped=True))
            continue
        results.append(one)
        bad = [v for v in one.rejected if not v.reason.startswith("not used")]
        n_unused = len(one.rejected) - len(bad)
        reports.append(RunReport(
            f"load case {r.load_case} (node {key[0]}): {one.n_accepted} hits accepted"
            + (", rejected: " + "; ".join(f"hit {v.index + 1}: {v.reason}" for v in bad)
               if bad else "")
            + (f"; {n_unused} more not used (--averages {s.averages})" if n_unused else "")))
    if not results:
        return None
    res = merge_results(results)
    assert res.H is not None and res.coherence is not None
    return res.H, res.coherence, res.freq


def _random_column(key: DofKey, members: list[TimeRun], s: Settings,
                   reports: list[RunReport]) -> Column | None:
    """The Welch average over one excitation DOF's runs (None when none is usable)."""
    spectra = []
    for r in members:
        try:
            if not np.any(r.force):
                raise InputError(f"load case {r.load_case}: the force channel is zero "
                                 "throughout: check the shaker's force channel")
            spectra.append(_random_spectra(r, s))
        except InputError as err:
            reports.append(RunReport(str(err), skipped=True))
    if not spectra:
        return None
    sp = spectra[0]
    for other in spectra[1:]:
        sp = combine(sp, other)
    H, coh = frf(sp, s.estimator)
    reports.append(RunReport(f"excitation node {key[0]}: {sp.n_averages} averages"))
    return H, coh, sp.freq


def open_time_uff(path: Path, s: Settings) -> tuple[FRFSet, list[RunReport]]:
    """FRFs with coherence and geometry from the time runs of a UFF file.

    Returns the FRF set on the lines up to ``s.fmax`` (default fs / 2.56) and the reports:
    each run's verdicts, each bad run (skipped), the coherence gate and the rigidity check.
    Raises :class:`OpenError` (one line) when no run is usable or a setting fits no run.
    """
    runs, problems = read_time_uff(path, strict=False)
    reports = [RunReport(msg, skipped=True) for _, msg in problems]
    if runs:  # options that depend on the data: once for the file, not once per run
        try:
            s.check_rate(runs[0].fs, max(r.n_samples / r.fs for r in runs))
        except InputError as err:
            raise OpenError(str(err), reports) from err
    if runs and s.excitation == "random" and max(r.n_samples for r in runs) < s.nperseg:
        raise OpenError(f"the longest run has {max(r.n_samples for r in runs)} samples, fewer "
                        f"than --nperseg {s.nperseg}: lower --nperseg", reports)
    good = _consistent(runs, reports) if runs else []
    groups: dict[DofKey, list[TimeRun]] = {}  # one column per excitation DOF, in order
    for r in good:
        groups.setdefault((int(r.exc_node), tuple(np.round(r.exc_dir, 6))), []).append(r)
    column = _impact_column if s.excitation == "impact" else _random_column
    cols = {key: col for key, members in groups.items()
            if (col := column(key, members, s, reports)) is not None}
    if not cols:
        raise OpenError(f"{path}: no usable time run ({n_skipped(reports)} bad run(s), see "
                        "above)", reports)
    first = runs[0]
    geometry, _ = read_geometry_uff(path)
    keys = list(cols)
    meta: dict[str, object] = {"estimator": s.estimator, "excitation": s.excitation,
                               "exponential_tau": s.exp_tau if s.excitation == "impact"
                               else None}
    out = assemble(cols[keys[0]][2], [cols[k][0] for k in keys], [cols[k][1] for k in keys],
                   first.resp_nodes, first.resp_dirs, np.array([k[0] for k in keys]),
                   np.array([k[1] for k in keys]), geometry, meta,
                   s.fmax if s.fmax is not None else first.fs / 2.56, reports)
    return out, reports + check_reports(out, s.coherence)
