"""Time records -> FRFs: runs grouped by excitation DOF, averaged, checked.

The runs come from a time UFF or from a TDMS or MDF file through its channel map
(:class:`app.io.uff_time.TimeSource`): one code computes the FRFs of all three.

Each run (its records sharing a load case: one force, the accelerations) gives the FRF
column of its excitation DOF; runs at the same DOF are averaged together. ``random``
(shaker: Welch, segments of ``nperseg`` samples) or ``impact`` (hammer: trigger,
per-hit checks, force and exponential windows). A bad run is reported and left out.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from app.io.uff_time import TimeRun, TimeSource, read_time_file
from app.pipeline.assemble import assemble, check_reports
from app.pipeline.settings import OpenError, RunReport, Settings, n_skipped
from processing.data import FRFSet, Geometry, InputError
from processing.excitation import (
    ShakerSignal,
    burst_onsets,
    burst_records,
    burst_ringing,
    settled_records,
    shaker_signal,
    steady_periods,
)
from processing.geometry import excitation_rank
from processing.impact import (
    MIN_PRETRIGGER,
    ExcitationGuess,
    HitVerdict,
    ImpactDefaults,
    ImpactResult,
    ImpactSettings,
    excitation_type,
    exponential_for,
    force_band_top,
    impact_defaults,
    merge_results,
    pretrigger_for,
    process_impacts,
    wanted_record,
)
from processing.measurement import Measurement, Provenance
from processing.spectral import CrossSpectra, SpectralAccumulator, combine, frf, record_spectra
from processing.units import MIN_UNITS, TimeUnits, UnitSpectra, record_units, welch_units

__all__ = ["open_time_records", "open_time_uff"]

#: one FRF column: H (n_resp, 1, n_f), coherence, frequency lines (Hz), and the spectra of
#: its hits or blocks (for the bootstrap, :mod:`processing.bootstrap`; None when too few)
Column = tuple[NDArray[np.complex128], NDArray[np.float64], NDArray[np.float64],
               UnitSpectra | None]
DofKey = tuple[int, tuple[float, ...]]


def _apart(onsets: NDArray[np.int64], length: int) -> NDArray[np.int64]:
    """The onsets that start after the record of the previous one kept (a loud moment inside
    a burst, e.g. the armature's force while the structure rings, starts no record)."""
    kept: list[int] = []
    for o in onsets.tolist():  # a few dozen bursts
        if not kept or o >= kept[-1] + length:
            kept.append(o)
    return np.asarray(kept, dtype=np.int64)


def _burst_starts(r: TimeRun, length: int) -> NDArray[np.int64]:
    """First sample of each burst record of ``length`` samples that lies within the run."""
    starts = _apart(burst_onsets(r.force, r.fs), length)
    return starts[starts + length <= r.n_samples]


def _stacked(r: TimeRun) -> NDArray[np.float64]:
    """The run's force then its responses, (1 + n_resp, n)."""
    return np.vstack([r.force[None], r.responses])


def _record_spectra(r: TimeRun, s: Settings) -> tuple[CrossSpectra, UnitSpectra | None, str]:
    """Spectra of whole periods (``s.records == "periodic"``, the first ones skipped until
    the responses repeat) or of one record from each burst's onset (``"burst"``, completed
    when ``s.carryover``: :func:`processing.excitation.burst_records`; the first ones
    skipped while the responses settle: :func:`processing.excitation.settled_records`),
    ``s.nperseg`` samples each, rectangular window; each record's spectra (the bootstrap's
    units, None under :data:`processing.units.MIN_UNITS` records); and a note on the records
    skipped ("" when none)."""
    L = s.nperseg
    assert L is not None
    data = _stacked(r)
    note = ""
    if s.records == "periodic":
        skip = steady_periods(r.responses, L)
        starts = np.arange(skip * L, r.n_samples - L + 1, L)
        what = f"period of {L} samples after the first {skip}"
        records = data[:, starts[:, None] + np.arange(L)].transpose(1, 0, 2)
    else:
        starts = _burst_starts(r, L)
        what = f"burst of {L} samples"
        records = burst_records(data, r.fs, starts, L, complete=bool(s.carryover))
        skip = settled_records(records[:, 1:])  # the responses of each record
        records = records[skip:]
        if skip:
            note = (f"the first {skip} burst record{'s' if skip > 1 else ''} left out "
                    "(responses settling: record mean off the others')")
    if s.averages is not None:
        records = records[:s.averages]
    if records.shape[0] == 0:
        raise InputError(f"load case {r.load_case}: no whole {what}: record longer or give "
                         "--nperseg")
    units = (record_units(records, r.fs).below(_fmax(s, r.fs)) if records.shape[0] >= MIN_UNITS
             else None)
    return record_spectra(records, r.fs), units, note


def _random_spectra(r: TimeRun, s: Settings) -> tuple[CrossSpectra, UnitSpectra | None, str]:
    if s.records in ("periodic", "burst"):
        return _record_spectra(r, s)
    nperseg = s.nperseg
    assert nperseg is not None and s.overlap is not None and s.window is not None
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
    return (*welch_units(acc, (r.force[:n], r.responses[:, :n]), fmax=_fmax(s, r.fs)), "")


def _fmax(s: Settings, fs: float) -> float:
    """The highest line of the FRFs of runs sampled at ``fs`` Hz (``s.fmax``, default
    fs / 2.56): the units keep no line above it."""
    return s.fmax if s.fmax is not None else fs / 2.56


#: the earlier hits' (bursts') ringing is taken off each record by default when the
#: responses ring at least this many times their noise just before the next hit (at the end
#: of a burst record), median over the runs (:attr:`processing.impact.ImpactDefaults.carryover`,
#: :func:`processing.excitation.burst_ringing`)
CARRY_GATE = 3.0

#: shortest pre-trigger when none is given, s (:func:`processing.impact.pretrigger_for`)
PRETRIGGER = MIN_PRETRIGGER


def _impact(r: TimeRun, s: Settings, levels: dict[int, float],
            max_averages: int | None = None) -> ImpactResult:
    """Hits of one run, the first ``max_averages`` accepted ones averaged; InputError (naming
    the load case) when none can be used. ``s`` is resolved (:func:`_resolve`); ``levels``
    the runs' default trigger levels, N."""
    lc = f"load case {r.load_case}"
    peak = float(np.max(np.abs(r.force)))
    if s.level is None and (peak == 0 or r.load_case not in levels):
        raise InputError(f"{lc}: the force channel is zero throughout: check the hammer channel"
                         if peak == 0 else f"{lc}: no impact stands out of the force's noise: "
                         "check the hammer channel or give --level")
    level = s.level if s.level is not None else levels[r.load_case]
    assert s.record is not None and s.pretrigger is not None
    settings = ImpactSettings(
        level=level, record_length=round(s.record * r.fs),
        pretrigger=round(s.pretrigger * r.fs),
        slope="rising" if level > 0 else "falling", exp_tau=s.exp_tau or None,
        ring=s.ring or 0, carryover=bool(s.carryover), complete=bool(s.tail),
    )
    names = ["force", *(f"response {i + 1}" for i in range(r.responses.shape[0]))]
    res = process_impacts(np.vstack([r.force[None], r.responses]), r.fs, settings,
                          channel_names=names, estimator=s.estimator,
                          max_averages=max_averages, keep_units=True)
    if not res.verdicts:
        raise InputError(f"{lc}: no hit found (the force never crosses {level:g} N): lower "
                         "--level or check the force channel")
    if res.H is None:
        why = "; ".join(f"hit {v.index + 1}: {v.reason}" for v in res.verdicts)
        message = f"{lc}: every hit rejected ({why}): measure the point again"
        if _only_double_hits(res.verdicts):
            raise _DoubleHitsOnlyError(message, _double_hits_kept(process_impacts(
                np.vstack([r.force[None], r.responses]), r.fs, settings, channel_names=names,
                estimator=s.estimator, force_accept=True, max_averages=max_averages,
                keep_units=True)))
        raise InputError(message)
    return res


class _DoubleHitsOnlyError(InputError):
    """Every hit of a run rejected for a double hit and nothing else; ``result`` holds the
    run's hits accepted all the same (used when the point is needed: :func:`_columns`)."""

    def __init__(self, message: str, result: ImpactResult) -> None:
        super().__init__(message)
        self.result = result


def _only_double_hits(verdicts: Sequence[HitVerdict]) -> bool:
    """Whether every complete hit was rejected for a double hit and nothing else (a record
    cut by the data's ends stays rejected whatever its point's other hits)."""
    complete = [v for v in verdicts if not np.isnan(v.peak_force)]
    return bool(complete) and all(v.reason.startswith("double hit (") and ";" not in v.reason
                                  for v in complete)


def _double_hits_kept(res: ImpactResult) -> ImpactResult:
    """``res`` (its hits accepted by :func:`process_impacts`' ``force_accept``) with its
    verdicts saying why."""
    return dataclasses.replace(res, verdicts=tuple(
        dataclasses.replace(v, reason=(
            f"accepted: {v.reason.removeprefix('accepted by override: ')}, the point's only "
            "hits, needed for the excitation geometry (its force window spans the rebound)"))
        if v.accepted else v for v in res.verdicts))


@dataclass(frozen=True)
class _Layout:
    """The first good run's load case, sample rate (Hz) and response DOFs: every run used
    shares them."""

    load_case: int
    fs: float
    resp_nodes: NDArray[np.int64]
    resp_dirs: NDArray[np.float64]

    def mismatch(self, r: TimeRun) -> RunReport | None:
        """The report leaving ``r`` out when its rate or response DOFs differ, else None."""
        if r.fs == self.fs and (np.array_equal(r.resp_nodes, self.resp_nodes)
                                and np.allclose(r.resp_dirs, self.resp_dirs)):
            return None
        what = (f"sample rate {r.fs:g} Hz differs from load case {self.load_case}'s "
                f"{self.fs:g} Hz" if r.fs != self.fs else
                f"response DOFs differ from load case {self.load_case}'s")
        return RunReport(f"load case {r.load_case}: {what}: process such runs in separate "
                         "files", skipped=True)


@dataclass(frozen=True)
class _Force:
    """What the settings read from one run's force: its load case, sample rate (Hz),
    length (samples) and, when a setting is to be read from the data, the excitation it
    suggests and the shaker signal's kind (:func:`processing.excitation.shaker_signal`)."""

    load_case: int
    fs: float
    n_samples: int
    guess: ExcitationGuess | None
    signal: ShakerSignal | None


class _Passes:
    """The runs of a time-records file as the passes over it read them, one run at a time.

    ``bad`` maps the load case of each run found bad so far to its problem (kept from one
    attempt to the next); ``good`` holds the runs read whole without a problem. A run found
    bad by a whole read after its force counted in a setting (``late``) makes the caller
    start again without it, so the settings and FRFs come from the good runs alone, as if
    every run had been checked first.
    """

    def __init__(self, file: TimeSource, bad: dict[int, str], good: set[int]) -> None:
        self.file, self.bad, self.good = file, bad, good
        self.late = False

    def forces(self, s: Settings) -> list[_Force]:
        """Each run's force read alone (a bad one goes to ``bad``), what the settings need
        of it kept."""
        guess = s.excitation is None and not s.hammer_given
        signal = ((s.excitation == "random" or guess)
                  and not (s.records is not None and s.nperseg is not None)
                  and not (s.welch_given or s.records == "welch"))
        seen = []
        for lc in self.file.load_cases:
            if lc in self.bad:
                continue
            try:
                r = self.file.read_run(lc, force_only=True)
            except InputError as err:
                self.bad[lc] = str(err)
                continue
            seen.append(_Force(lc, r.fs, r.n_samples, excitation_type(r.force) if guess else None,
                               shaker_signal(r.force, r.fs) if signal else None))
            del r
        return seen

    def runs(self) -> Iterator[TimeRun]:
        """The runs not known bad, read whole one at a time, in the file's order."""
        for lc in self.file.load_cases:
            if lc in self.bad:
                continue
            try:
                run = self.file.read_run(lc)
            except InputError as err:
                self.bad[lc] = str(err)
                self.late = True
                continue
            self.good.add(lc)
            yield run
            del run  # before the next run is read

    def check_all(self) -> None:
        """Read whole every run not read whole yet (before a refusal: its reports name
        every bad run)."""
        for lc in self.file.load_cases:
            if lc not in self.bad and lc not in self.good:
                try:
                    self.file.read_run(lc)
                    self.good.add(lc)
                except InputError as err:
                    self.bad[lc] = str(err)
                    self.late = True

    def problems(self) -> list[RunReport]:
        """One skipped report per bad run, in the file's order."""
        return [RunReport(self.bad[lc], skipped=True) for lc in self.file.load_cases
                if lc in self.bad]


class _ImpactColumn:
    """One excitation DOF's hits, its runs added one at a time: the first ``s.averages``
    accepted hits of the point averaged."""

    def __init__(self, key: DofKey) -> None:
        self.key = key
        self.results: list[ImpactResult] = []
        self.reports: list[RunReport] = []
        #: a run whose every hit is a double hit: its hits accepted, its load case and the
        #: line that reports it skipped
        self.spare: tuple[ImpactResult, int, RunReport] | None = None

    def add(self, r: TimeRun, s: Settings, levels: dict[int, float]) -> None:
        left = None
        if s.averages is not None:  # the first N accepted hits of the point
            left = s.averages - sum(one.n_accepted for one in self.results)
            if left == 0:
                self.reports.append(RunReport(
                    f"load case {r.load_case} (node {self.key[0]}): not used, the first "
                    f"{s.averages} accepted hits of the point are averaged"))
                return
        try:
            one = _impact(r, s, levels, left)
        except _DoubleHitsOnlyError as err:
            self.spare = (err.result, r.load_case, RunReport(str(err), skipped=True))
            self.reports.append(self.spare[2])
            return
        except InputError as err:
            self.reports.append(RunReport(str(err), skipped=True))
            return
        self._add(one, r.load_case, s)

    def use_spare(self, s: Settings) -> None:
        """The point's double hits used after all (its only hits; the excitation geometry
        needs it): they replace the run's 'every hit rejected' line."""
        assert self.spare is not None and not self.results
        one, load_case, skipped = self.spare
        self.spare = None
        self.reports = [rep for rep in self.reports if rep is not skipped]
        self._add(one, load_case, s, " (double hits, the point's only hits: without them "
                  "the excitations do not span the six rigid-body motions)")

    def _add(self, one: ImpactResult, load_case: int, s: Settings, note: str = "") -> None:
        self.results.append(one)
        bad = [v for v in one.rejected if not v.reason.startswith("not used")]
        n_unused = len(one.rejected) - len(bad)
        without = ", ".join(f"response {i + 1}" for i in one.left_out)
        self.reports.append(RunReport(
            f"load case {load_case} (node {self.key[0]}): {one.n_accepted} hits accepted{note}"
            + (f" without {without} (every hit overloads it: left out of this point's FRFs)"
               if without else "")
            + (", rejected: " + "; ".join(f"hit {v.index + 1}: {v.reason}" for v in bad)
               if bad else "")
            + (f"; {n_unused} more not used (--averages {s.averages})" if n_unused else "")))

    def column(self, s: Settings) -> Column | None:
        """The averaged hits (None when no run is usable)."""
        results, self.results = self.results, []  # each run's spectra freed once merged
        if not results:
            return None
        res = merge_results(results)
        del results
        assert res.H is not None and res.coherence is not None
        return res.H, res.coherence, res.freq, res.units


class _RandomColumn:
    """One excitation DOF's Welch average, its runs added one at a time."""

    def __init__(self, key: DofKey) -> None:
        self.key = key
        self.spectra: list[CrossSpectra] = []
        self.units: list[UnitSpectra | None] = []
        self.notes: list[str] = []
        self.reports: list[RunReport] = []

    def add(self, r: TimeRun, s: Settings, levels: dict[int, float]) -> None:
        try:
            if not np.any(r.force):
                raise InputError(f"load case {r.load_case}: the force channel is zero "
                                 "throughout: check the shaker's force channel")
            sp_r, units_r, note = _random_spectra(r, s)
            self.spectra.append(sp_r)
            self.units.append(units_r)
            if note:
                self.notes.append(f"load case {r.load_case}: {note}")
        except InputError as err:
            self.reports.append(RunReport(str(err), skipped=True))

    def column(self, s: Settings) -> Column | None:
        """The Welch average over the runs (None when no run is usable)."""
        if not self.spectra:
            return None
        sp = self.spectra[0]
        for other in self.spectra[1:]:
            sp = combine(sp, other)
        H, coh = frf(sp, s.estimator)
        self.reports.append(RunReport(f"excitation node {self.key[0]}: {sp.n_averages} averages"
                                      + (f" ({'; '.join(self.notes)})" if self.notes else "")))
        units, self.units = self.units, []  # each run's units freed once joined
        parts = [u for u in units if u is not None]
        del units
        joined = (None if len(parts) < len(self.spectra) else parts[0] if len(parts) == 1
                  else UnitSpectra.concat(parts))
        return H, coh, sp.freq, joined


def _excitation(runs: list[_Force], s: Settings) -> tuple[Settings, list[RunReport]]:
    """``s`` with its excitation read from the data when not given, and the line saying so."""
    if s.excitation is not None:
        return s, []
    if s.hammer_given:
        return dataclasses.replace(s, excitation="impact"), [RunReport(
            "excitation impact (a hammer option is given; --excitation random to change)")]
    guesses = [r.guess for r in runs if r.guess is not None]
    n_imp = sum(g.kind == "impact" for g in guesses)
    kind: Literal["impact", "random"] = "impact" if 2 * n_imp > len(guesses) else "random"
    k = float(np.median([g.kurtosis for g in guesses]))
    crest = float(np.median([g.crest for g in guesses]))
    why = (f"force impulsive in {n_imp} of {len(runs)} runs: median kurtosis {k:.3g}, crest "
           f"factor {crest:.3g}" if kind == "impact" else
           f"force not impulsive in {len(runs) - n_imp} of {len(runs)} runs: median kurtosis "
           f"{k:.3g}, crest factor {crest:.3g}")
    other = "random" if kind == "impact" else "impact"
    return dataclasses.replace(s, excitation=kind), [
        RunReport(f"excitation {kind} ({why}; --excitation {other} to change)")]


#: Welch defaults for a continuous random force: segment samples, overlap, window
WELCH = (2048, 0.5, "hann")


def _shaker(runs: list[_Force], s: Settings) -> tuple[Settings, list[RunReport]]:
    """``s`` with how random-excitation records are cut (``records``, ``nperseg``,
    ``overlap``, ``window``) read from the forces when not given, and the line saying so."""
    if s.records is not None and s.nperseg is not None:
        return s, []
    if s.welch_given or s.records == "welch":
        return dataclasses.replace(s, records="welch", nperseg=s.nperseg or WELCH[0],
                                   overlap=WELCH[1] if s.overlap is None else s.overlap,
                                   window=s.window or WELCH[2]), []
    sig = [r.signal for r in runs if r.signal is not None]
    kind = Counter(g.kind for g in sig).most_common(1)[0][0]
    same = [g for g in sig if g.kind == kind]
    fs = runs[0].fs
    change = "--nperseg, --overlap, --window for Welch segments"
    if kind == "periodic":
        period = Counter(g.period for g in same).most_common(1)[0][0]
        assert period is not None
        return dataclasses.replace(s, records="periodic", nperseg=period, overlap=0.0,
                                   window="boxcar"), [RunReport(
            f"shaker force periodic in {len(same)} of {len(runs)} runs (period {period / fs:.4g}"
            f" s, autocorrelation {np.median([g.correlation for g in same]):.3g}): one record "
            "a period, rectangular window, once the responses repeat (" + change + ")")]
    if kind == "burst":
        length = min(g.period for g in same if g.period is not None)
        return dataclasses.replace(s, records="burst", nperseg=length, overlap=0.0,
                                   window="boxcar"), [RunReport(
            f"shaker force in bursts in {len(same)} of {len(runs)} runs (every "
            f"{length / fs:.4g} s at least, on {np.median([g.duty for g in same]) * 100:.0f} % "
            f"of the time): one record of {length / fs:.4g} s from each burst's onset, "
            "rectangular window (" + change + ")")]
    n, ov, win = WELCH
    return dataclasses.replace(s, records="welch", nperseg=n, overlap=ov, window=win), [
        RunReport(f"shaker force continuous in {len(same)} of {len(runs)} runs: Welch segments "
                  f"of {n} samples ({n / fs:.4g} s, lines {fs / n:.3g} Hz apart), Hann window, "
                  f"{ov * 100:.0f} % overlap (--nperseg, --overlap, --window to change)")]


def _burst_carryover(runs: _Passes, s: Settings) -> tuple[Settings, list[RunReport]]:
    """``s`` with ``carryover`` resolved for random excitation: for burst records, on when
    the responses still ring at the records' ends (:data:`CARRY_GATE`, median over the
    runs) unless given, and the line saying so; a ``--carryover`` given for other records
    is said to be unused."""
    if s.records != "burst":
        return s, [RunReport(f"--carryover is for hammer hits and burst records, not "
                             f"{s.records} records: not used")] if s.carryover else []
    L = s.nperseg
    if s.carryover is not None or L is None:
        return s, []
    rings = []
    for r in runs.runs():
        if (st := _burst_starts(r, L)).size:
            rings.append(burst_ringing(_stacked(r), r.fs, st, L))
        del r  # before the next run is read
    ring = float(np.median(rings)) if rings else 0.0
    on = ring >= CARRY_GATE
    return dataclasses.replace(s, carryover=on), [RunReport(
        f"earlier bursts' ringing: {ring:.2g} x the responses' noise at the end of the records "
        + ("(median): each record less the earlier bursts' free decay, its own continued past "
           "its end and put back at its start (--carryover off to change)" if on else
           f"(median, under {CARRY_GATE:g}): records used as they are (--carryover on to "
           "change)"))]


def _record(d: list[ImpactDefaults], decay: float, pre: float) -> float:
    """Record length, s, for every run: twice the runs' median decay
    (:data:`processing.impact.TAIL_FACTOR`) plus the pre-trigger (at least
    :data:`processing.impact.MIN_RECORD`), as far as the closest hits of any run allow (95 %
    of their spacing), and never shorter than the shortest run's own choice."""
    want = wanted_record(decay, pre)
    limit = min(x.record if x.spacing is None else np.floor(0.95 * x.spacing * 100) / 100
                for x in d)
    return float(max(min(want, limit), min(x.record for x in d)))


def _impact_defaults(runs: _Passes, pre: float) -> dict[int, ImpactDefaults]:
    """Each run's defaults read from its data (:func:`processing.impact.impact_defaults`) for
    a pre-trigger of ``pre`` s, by load case; a run without an impact is left out (its
    processing reports it)."""
    found: dict[int, ImpactDefaults] = {}
    for r in runs.runs():
        with contextlib.suppress(InputError):
            found[r.load_case] = impact_defaults(r.force, r.responses, r.fs, pre)
        del r  # before the next run is read
    return found


def _resolve(forces: list[_Force], runs: _Passes, s: Settings,
             ) -> tuple[Settings, dict[int, float], list[RunReport]]:
    """The settings with every default read from the data (``forces``; the runs read whole
    again when a default needs their responses), the runs' trigger levels (N, by load case)
    and one line per default chosen."""
    s, lines = _excitation(forces, s)
    if s.excitation != "impact":
        s, more = _shaker(forces, s)
        s, bursts = _burst_carryover(runs, s)
        return s, {}, lines + more + bursts
    pre = s.pretrigger if s.pretrigger is not None else PRETRIGGER
    found = _impact_defaults(runs, pre)
    if s.pretrigger is None and found:  # hold the force's ringing before a pulse
        before = max(x.ring_before for x in found.values())
        chosen = pretrigger_for(before, forces[0].fs)
        if chosen != pre:
            pre, found = chosen, _impact_defaults(runs, chosen)
        lines.append(RunReport(
            f"pre-trigger {pre:.3g} s (the force rings above its noise up to {before} samples "
            f"before a pulse: twice that, at least {PRETRIGGER:g} s; --pretrigger to change)"))
    levels = {lc: d.level for lc, d in found.items()}
    if not found:
        return (dataclasses.replace(s, pretrigger=pre, record=s.record or 1.0,
                                    exp_tau=s.exp_tau or 0.0, carryover=bool(s.carryover)),
                levels, lines)
    d = list(found.values())
    ringing = int(np.median([x.ring_after for x in d]))
    ring = s.ring or 0
    if s.level is None:
        lv = np.array(list(levels.values()))
        lines.append(RunReport(
            f"trigger level {lv.min():.3g}-{lv.max():.3g} N by run (10 x the force's noise, "
            f"{np.median([x.noise for x in d]):.2g} N, at least 2 % of the largest impact; "
            "--level to change)"))
    spacing = [x.spacing for x in d if x.spacing is not None]
    decay = float(np.median([x.decay for x in d]))
    ratio = float(np.median([x.ratio for x in d]))
    record = s.record if s.record is not None else _record(d, decay, pre)
    tau = (s.exp_tau if s.exp_tau is not None else 0.0 if s.tail
           else exponential_for(record, pre, decay, ratio))
    tail = s.tail if s.tail is not None else not tau
    hits = f"hits {min(spacing):.2g} s apart at least" if spacing else "one hit a run"
    if s.record is None or s.exp_tau is None:
        window = (f"exponential window tau = {tau:.2g} s" if tau else "no exponential window")
        lines.append(RunReport(
            f"record {record:g} s ({hits}; responses decay in {decay:.2g} s): {window} "
            "(--record, --exp-tau to change)"))
    width = f"{np.median([x.pulse_width for x in d]) * 1e3:.2g} ms"
    lines.append(RunReport(
        f"force window: each pulse's end plus the larger of its width ({width}) and {ring} "
        f"samples (--force-ring; the force rings above its noise {ringing} samples after a "
        "pulse), then a half-cosine as long; the force's median over each record taken off"))
    carry = float(np.median([x.carryover for x in d]))
    carryover = s.carryover if s.carryover is not None else carry >= CARRY_GATE
    if s.carryover is None:
        lines.append(RunReport(
            f"earlier hits' ringing: {carry:.2g} x the responses' noise just before the next "
            + ("hit (median): each record's responses less the free decay fitted before it "
               "(--carryover off to change)" if carryover else
               f"hit (median, under {CARRY_GATE:g}): records used as they are (--carryover on "
               "to change)")))
    if s.tail is None:
        lines.append(RunReport(
            "record tails: " + ("each record's responses continued past its end by their free "
                                "decay after the hit, folded back onto it: no leakage "
                                "(--tail off to change)" if tail else
                                "none put back (an exponential window; --tail on with "
                                "--exp-tau 0 to change)")))
    return dataclasses.replace(s, pretrigger=pre, record=record, exp_tau=tau or 0.0,
                               ring=ring, carryover=carryover, tail=tail), levels, lines


def open_time_uff(path: Path, s: Settings) -> Measurement:
    """The measurement of the time runs of a UFF file (:func:`open_time_records`)."""
    return open_time_records(read_time_file(path), s)  # headers only: runs read when reached


def open_time_records(file: TimeSource, s: Settings) -> Measurement:
    """The measurement of the time runs of a file (a time UFF, a TDMS or MDF file through its
    channel map): FRFs with coherence and geometry, estimated here, with the per-hit or
    per-block spectra, the exponential window's tau and the hammer's usable band.

    The FRFs are on the lines up to ``s.fmax`` (default fs / 2.56); the reports (in the
    provenance) are each run's verdicts, each bad run (skipped), the coherence gate and the
    rigidity check. Raises :class:`OpenError` (one line) when no run is usable or a setting
    fits no run.

    The file is read one run at a time (:class:`_Passes`): the forces alone for the
    settings read from the data, each run whole again for the defaults that need its
    responses (hammer tests, burst records), then each run whole once for its spectra.
    Memory holds one run and the spectra, never the file's samples.
    """
    bad: dict[int, str] = {}
    good: set[int] = set()
    while True:  # again without a run found bad after its force counted in a setting
        m = _attempt(file.path, file, _Passes(file, bad, good), s)
        if m is not None:
            return m


def _attempt(path: Path, file: TimeSource, runs: _Passes, s: Settings,
             ) -> Measurement | None:
    """:func:`open_time_records` with the runs known bad so far left out; None when a run is
    found bad after its force counted in a setting."""
    forces = runs.forces(s)
    levels: dict[int, float] = {}
    chosen: list[RunReport] = []
    if forces:  # options that depend on the data: once for the file, not once per run
        try:
            s.check_rate(forces[0].fs, max(r.n_samples / r.fs for r in forces))
        except InputError as err:
            runs.check_all()
            if runs.late:
                return None
            raise OpenError(str(err), runs.problems()) from err
        s, levels, chosen = _resolve(forces, runs, s)
        if runs.late:
            return None
    longest = max((r.n_samples for r in forces), default=0)
    if forces and s.excitation == "random" and s.nperseg is not None and longest < s.nperseg:
        runs.check_all()
        if runs.late:
            return None
        raise OpenError(f"the longest run has {longest} samples, fewer than --nperseg "
                        f"{s.nperseg}: lower --nperseg", chosen + runs.problems())
    try:
        geometry: Geometry | None = file.geometry()
    except InputError:  # said below, once the runs are read
        geometry = None
    cols, first, more = _columns(runs, s, levels, geometry)
    if runs.late:
        return None
    reports = chosen + runs.problems() + more
    if not cols or first is None:
        raise OpenError(f"{path}: no usable time run ({n_skipped(reports)} bad run(s), see "
                        "above)", reports)
    geometry = geometry or file.geometry()
    keys = list(cols)
    fmax = _fmax(s, first.fs)
    out, _ = assemble(cols[keys[0]][2], [cols[k][0] for k in keys],
                      [cols[k][1] for k in keys], first.resp_nodes, first.resp_dirs,
                      np.array([k[0] for k in keys]), np.array([k[1] for k in keys]), geometry,
                      fmax, reports)
    units = [u for k in keys if (u := cols[k][3]) is not None]
    time_units, top = None, None
    if len(units) == len(keys):  # per-unit spectra: the bootstrap, the hammer's usable band
        time_units = TimeUnits(
            "hit" if s.excitation == "impact" else "block", tuple(units),
            np.array([k[0] for k in keys]), np.array([k[1] for k in keys]), s.estimator)
        if s.excitation == "impact":
            top = force_band_top(units[0].freq, np.stack([u.Sff.mean(axis=0) for u in units]))
    if s.excitation == "random":
        out = _from_signal(out, s.coherence, reports)
    reports += check_reports(out, s.coherence)
    return Measurement(out, Provenance(
        origin="estimated", excitation=str(s.excitation), estimator=s.estimator,
        units=time_units, exponential_tau=s.exp_tau or None if s.excitation == "impact"
        else None, force_band_top=top, anti_alias_fmax=fmax,
        window="" if s.excitation == "impact" else str(s.window), reports=tuple(reports)),
        Path(path).name)


def _spares_needed(groups: dict[DofKey, _ImpactColumn | _RandomColumn], geometry: Geometry,
                   s: Settings) -> None:
    """The points whose every hit is a double hit, used when the excitations do not span the
    six rigid-body motions without them and do with them (the identification would refuse
    the file): in the file's order, those that raise the rank. A recorded point cannot be hit
    again, and a double hit's FRF is the structure's all the same; where the rank does not
    need them they stay out (on the reference model's tests they cost more than the point
    gives)."""
    impact = {k: g for k, g in groups.items() if isinstance(g, _ImpactColumn)}
    spares = [g for g in impact.values() if g.spare is not None and not g.results]
    if not spares:
        return
    used = [k for k, g in impact.items() if g.results]

    def rank(keys: list[DofKey]) -> int:  # as the identification's geometry check counts it
        if not keys:
            return 0
        return excitation_rank(geometry.coordinates(np.array([k[0] for k in keys]),
                                                    "excitation"),
                               np.array([k[1] for k in keys], dtype=float))

    chosen: list[_ImpactColumn] = []
    with contextlib.suppress(InputError):  # a node without coordinates: assemble says so
        have = rank(used)
        for g in spares:
            if have < 6 and (more := rank([*used, g.key])) > have:
                chosen.append(g)
                used.append(g.key)
                have = more
        if have >= 6:
            for g in chosen:
                g.use_spare(s)


def _columns(runs: _Passes, s: Settings, levels: dict[int, float],
             geometry: Geometry | None = None,
             ) -> tuple[dict[DofKey, Column], _Layout | None, list[RunReport]]:
    """One FRF column per excitation DOF (in order of first appearance; a DOF without a
    usable run has none), each run read whole once and added to its DOF's column; the first
    good run's layout; the reports: the runs left out for another rate or other response
    DOFs, then each column's."""
    make = _ImpactColumn if s.excitation == "impact" else _RandomColumn
    groups: dict[DofKey, _ImpactColumn | _RandomColumn] = {}
    first: _Layout | None = None
    left_out: list[RunReport] = []
    for r in runs.runs():
        if first is None:
            first = _Layout(r.load_case, r.fs, r.resp_nodes, r.resp_dirs)
        why = first.mismatch(r)
        if why is not None:
            left_out.append(why)
        else:
            key = (int(r.exc_node), tuple(np.round(r.exc_dir, 6)))
            groups.setdefault(key, make(key)).add(r, s, levels)
        del r  # before the next run is read
    if geometry is not None:
        _spares_needed(groups, geometry, s)
    cols = {key: col for key, g in groups.items() if (col := g.column(s)) is not None}
    return cols, first, left_out + [line for g in groups.values() for line in g.reports]


#: fewest lines left by :func:`_from_signal`
MIN_LINES = 8


def _from_signal(frf: FRFSet, gate: float, reports: list[RunReport]) -> FRFSet:
    """Random excitation: the FRFs from the lowest line where the median coherence over all
    FRFs reaches ``gate`` (the lines below it hold responses under their noise: accelerances
    fall as the square of the frequency under the rigid-body modes); a line says so.
    Unchanged when ``gate`` is 0, there is no coherence or fewer than :data:`MIN_LINES`
    would be left."""
    if frf.coherence is None or not gate > 0:
        return frf
    med = np.median(frf.coherence, axis=(0, 1))
    k = int(np.argmax(med >= gate)) if np.any(med >= gate) else 0
    if k == 0 or frf.freq.size - k < MIN_LINES:
        return frf
    reports.insert(0, RunReport(
        f"FRFs from {frf.freq[k]:.4g} Hz: the {k} lines below have a median coherence under "
        f"{gate:g} (responses under their noise; --coherence 0 keeps them)"))
    return dataclasses.replace(frf, freq=frf.freq[k:], H=frf.H[..., k:],
                               coherence=frf.coherence[..., k:])
