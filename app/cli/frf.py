"""``insitu frf INPUT [--out FRF.uff|FRF.h5]``: FRFs and coherence from time data.

INPUT is a UFF file of time records or a run file (``.h5``) written by ``insitu acquire``.

UFF: each run (its records sharing a load case: one force, the accelerations) gives
the FRF column of its excitation DOF; runs at the same DOF are averaged together.
``--method random`` (shaker: continuous random, Welch with Hann window and overlap;
also burst random and periodic chirp with ``--window boxcar --overlap 0``) or
``--method impact`` (hammer: trigger, per-hit checks, force and exponential windows).

Run file: every stored hit is processed again with the plan's settings and the
operator's overrides, as ``insitu replay`` does (the time-data options do not apply).

The FRFs, their coherence and geometry are written as UFF (``.uff``, ``.unv``) or as
an HDF5 FRF file (``.h5``, ``.hdf5``), chosen by the suffix of ``--out``. A bad run
(no force channel, records of different rates or lengths, NaN samples, no hit found,
every hit rejected, ...) is reported on one line and skipped: the FRFs of the good
runs are still written, and the exit status is then 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.cli.common import UserError
from app.io.frf_h5 import write_frf_h5
from app.io.uff import read_time_uff, write_frf_uff
from app.io.uff_geometry import read_geometry_uff
from app.io.uff_time import TimeRun
from processing.coherence import coherence_gate
from processing.data import FRFSet, Geometry, InputError
from processing.geometry import GeometryError
from processing.impact import (
    ImpactResult,
    ImpactSettings,
    impact_frfset,
    merge_results,
    process_impacts,
)
from processing.rigidity import rigidity_check
from processing.spectral import ESTIMATORS, CrossSpectra, SpectralAccumulator, combine, frf

H5_SUFFIXES = (".h5", ".hdf5")
UFF_SUFFIXES = (".uff", ".unv")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("frf", help="FRFs and coherence from UFF time records or a run file",
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", type=Path,
                   help="UFF file with geometry and time records (58, type 1), or a run "
                        "file (.h5) written by insitu acquire")
    p.add_argument("--out", type=Path,
                   help="FRF file to write: .uff/.unv (UFF 58) or .h5/.hdf5 (HDF5 FRF file); "
                        "default INPUT's name with _frf.uff")
    add_processing_arguments(p, method_alias=True)
    p.add_argument("--binary", action="store_true", help="UFF output: write binary 58b records")
    p.set_defaults(run=run)


def add_processing_arguments(p: Any, *, method_alias: bool = False) -> None:
    """The options that turn time records into FRFs (shared with ``insitu identify``)."""
    flags = ("--excitation", "--method") if method_alias else ("--excitation",)
    p.add_argument(*flags, dest="excitation", choices=("random", "impact"),
                   default="random", help="time data: shaker random or hammer impact")
    p.add_argument("--estimator", choices=ESTIMATORS, default="H1")
    p.add_argument("--nperseg", type=int, default=2048,
                   help="random: samples per segment (line spacing fs/nperseg)")
    p.add_argument("--overlap", type=float, default=0.5, help="random: segment overlap, 0..<1")
    p.add_argument("--window", default="hann", help="random: window (hann, boxcar, ...)")
    p.add_argument("--averages", type=int, metavar="N",
                   help="use at most N averages: random, the first N segments of each run; "
                        "impact, the first N accepted hits of each excitation point "
                        "(default: all)")
    p.add_argument("--level", type=float,
                   help="impact: trigger level, N (default: 10 %% of the run's largest force)")
    p.add_argument("--record", type=float, default=1.0, help="impact: record length, s")
    p.add_argument("--pretrigger", type=float, default=0.01, help="impact: pre-trigger, s")
    p.add_argument("--exp-tau", type=float,
                   help="impact: exponential window time constant, s (default: none)")
    p.add_argument("--coherence", type=float, default=0.8, help="coherence gate threshold")
    p.add_argument("--fmax", type=float,
                   help="highest line kept, Hz (default fs / 2.56, the anti-alias filters' "
                        "usable band)")


def skipped(args: argparse.Namespace, message: str) -> None:
    """One stderr line for a run that is reported and skipped."""
    print(f"insitu {getattr(args, 'verb', 'frf')}: {message} (skipped)", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    out = args.out or args.file.with_name(args.file.stem + "_frf.uff")
    suffix = out.suffix.lower()
    if suffix not in H5_SUFFIXES + UFF_SUFFIXES:
        raise UserError(f"--out {out}: unknown suffix {out.suffix!r}: use .uff or .unv (UFF 58) "
                        "or .h5 or .hdf5 (HDF5 FRF file)")
    if args.file.suffix.lower() in H5_SUFFIXES:
        frfs, n_bad = frfset_from_run_file(args.file, args)
    else:
        frfs, n_bad = frfset_from_time_uff(args.file, args)
    if suffix in H5_SUFFIXES:
        write_frf_h5(out, frfs, source=str(args.file))
    else:
        write_frf_uff(out, frfs, binary=args.binary, coherence=True)
    print(f"{frfs.H.shape[0]} x {frfs.H.shape[1]} FRFs ({frfs.meta.get('estimator', 'H1')}), "
          f"{frfs.freq.size} lines, written to {out}"
          + (f"; {n_bad} bad run(s) skipped, exit status 2" if n_bad else ""))
    return 2 if n_bad else 0


# ----------------------------------------------------------------------------------------------
# UFF time records
# ----------------------------------------------------------------------------------------------
def _random_spectra(r: TimeRun, args: argparse.Namespace) -> CrossSpectra:
    nperseg = args.nperseg
    if r.n_samples < nperseg:
        raise InputError(f"load case {r.load_case}: {r.n_samples} samples, fewer than "
                         f"--nperseg {nperseg}: lower --nperseg or record longer")
    noverlap = round(args.overlap * nperseg)
    # a whole recording in one block: both cores of a bench PC (more gain little, see
    # docs/processing.md)
    acc = SpectralAccumulator(r.fs, nperseg, noverlap, window=args.window,
                              workers=min(2, os.cpu_count() or 1))
    n = r.n_samples
    if args.averages is not None:  # the samples of the first N segments
        n = min(n, (args.averages - 1) * (nperseg - noverlap) + nperseg)
    acc.update(np.vstack([r.force[None, :n], r.responses[:, :n]]))
    return acc.spectra()


def _impact(r: TimeRun, args: argparse.Namespace, max_averages: int | None = None
            ) -> ImpactResult:
    """Hits of one run, the first ``max_averages`` accepted ones averaged; InputError (naming
    the load case) when none can be used."""
    lc = f"load case {r.load_case}"
    peak = float(np.max(np.abs(r.force)))
    if args.level is None and peak == 0:
        raise InputError(f"{lc}: the force channel is zero throughout: check the hammer channel")
    level = args.level if args.level is not None else 0.1 * peak
    settings = ImpactSettings(
        level=level, record_length=round(args.record * r.fs),
        pretrigger=round(args.pretrigger * r.fs),
        slope="rising" if level > 0 else "falling", exp_tau=args.exp_tau,
    )
    names = ["force", *(f"response {i + 1}" for i in range(r.responses.shape[0]))]
    res = process_impacts(np.vstack([r.force[None], r.responses]), r.fs, settings,
                          channel_names=names, estimator=args.estimator,
                          max_averages=max_averages)
    if not res.verdicts:
        raise InputError(f"{lc}: no hit found (the force never crosses {level:g} N): lower "
                         "--level or check the force channel")
    if res.H is None:
        why = "; ".join(f"hit {v.index + 1}: {v.reason}" for v in res.verdicts)
        raise InputError(f"{lc}: every hit rejected ({why}): measure the point again")
    return res


def frfset_from_time_uff(path: Path, args: argparse.Namespace) -> tuple[FRFSet, int]:
    """FRFs with coherence and geometry from the time runs of a UFF file.

    Prints each run's verdicts, the coherence gate and the rigidity check; each bad run
    gets one stderr line and is skipped. Returns the FRF set and the number of bad runs;
    raises UserError (one line) when no run is usable or a setting fits no run.
    """
    if not 0 <= args.overlap < 1:
        raise UserError(f"--overlap must be in [0, 1), got {args.overlap}")
    if args.averages is not None and args.averages < 1:
        raise UserError(f"--averages must be at least 1, got {args.averages}")
    runs, problems = read_time_uff(path, strict=False)
    for _, msg in problems:
        skipped(args, msg)
    n_bad = len(problems)
    if runs and args.excitation == "random" and max(r.n_samples for r in runs) < args.nperseg:
        raise UserError(f"the longest run has {max(r.n_samples for r in runs)} samples, fewer "
                        f"than --nperseg {args.nperseg}: lower --nperseg")
    first = runs[0] if runs else None
    good: list[TimeRun] = []
    for r in runs:
        assert first is not None
        if r.fs != first.fs or not (np.array_equal(r.resp_nodes, first.resp_nodes)
                                    and np.allclose(r.resp_dirs, first.resp_dirs)):
            what = (f"sample rate {r.fs:g} Hz differs from load case {first.load_case}'s "
                    f"{first.fs:g} Hz" if r.fs != first.fs else
                    f"response DOFs differ from load case {first.load_case}'s")
            skipped(args, f"load case {r.load_case}: {what}: process such runs in separate files")
            n_bad += 1
        else:
            good.append(r)
    # one excitation column per distinct excitation DOF, in order of appearance
    groups: dict[tuple[int, tuple[float, ...]], list[TimeRun]] = {}
    for r in good:
        groups.setdefault((int(r.exc_node), tuple(np.round(r.exc_dir, 6))), []).append(r)
    cols: dict[tuple[int, tuple[float, ...]], tuple[Any, Any, Any]] = {}
    for key, members in groups.items():
        if args.excitation == "impact":
            results: list[ImpactResult] = []
            for r in members:
                left = None
                if args.averages is not None:  # the first N accepted hits of the point
                    left = args.averages - sum(one.n_accepted for one in results)
                    if left == 0:
                        print(f"load case {r.load_case} (node {key[0]}): not used, the first "
                              f"{args.averages} accepted hits of the point are averaged")
                        continue
                try:
                    one = _impact(r, args, left)
                except InputError as err:
                    skipped(args, str(err))
                    n_bad += 1
                    continue
                results.append(one)
                bad = [v for v in one.rejected if not v.reason.startswith("not used")]
                n_unused = len(one.rejected) - len(bad)
                print(f"load case {r.load_case} (node {key[0]}): {one.n_accepted} hits accepted"
                      + (", rejected: " + "; ".join(f"hit {v.index + 1}: {v.reason}"
                                                   for v in bad) if bad else "")
                      + (f"; {n_unused} more not used (--averages {args.averages})"
                         if n_unused else ""))
            if results:
                res = merge_results(results)
                cols[key] = (res.H, res.coherence, res.freq)
        else:
            spectra = []
            for r in members:
                try:
                    if not np.any(r.force):
                        raise InputError(f"load case {r.load_case}: the force channel is zero "
                                         "throughout: check the shaker's force channel")
                    spectra.append(_random_spectra(r, args))
                except InputError as err:
                    skipped(args, str(err))
                    n_bad += 1
            if spectra:
                sp = spectra[0]
                for other in spectra[1:]:
                    sp = combine(sp, other)
                H, coh = frf(sp, args.estimator)
                cols[key] = (H, coh, sp.freq)
                print(f"excitation node {key[0]}: {sp.n_averages} averages")
    if not cols:
        raise UserError(f"{path}: no usable time run ({n_bad} bad run(s), see above)")
    assert first is not None
    geometry, _ = read_geometry_uff(path)
    keys = list(cols)
    meta = {"estimator": args.estimator, "excitation": args.excitation,
            "exponential_tau": args.exp_tau if args.excitation == "impact" else None}
    out, n_undefined = _assemble(
        cols[keys[0]][2], [cols[k][0] for k in keys], [cols[k][1] for k in keys],
        first.resp_nodes, first.resp_dirs, np.array([k[0] for k in keys]),
        np.array([k[1] for k in keys]), geometry, meta,
        args.fmax if args.fmax is not None else first.fs / 2.56, args)
    print_checks(out, args.coherence)
    return out, n_bad + n_undefined


# ----------------------------------------------------------------------------------------------
# shared: columns -> FRF set, checks
# ----------------------------------------------------------------------------------------------
def _assemble(freq: NDArray[np.float64], Hs: list[Any], cohs: list[Any],
              resp_nodes: NDArray[np.int64], resp_dirs: NDArray[np.float64],
              exc_nodes: NDArray[np.int64], exc_dirs: NDArray[np.float64], geometry: Geometry,
              meta: dict[str, object], fmax: float,
              args: argparse.Namespace) -> tuple[FRFSet, int]:
    """Excitation columns -> FRF set on the lines above 0 Hz up to ``fmax`` Hz.

    A column with undefined values there (no force at those frequencies) is reported and
    dropped; returns the set and the number of columns dropped.
    """
    keep = (freq > 0) & (freq <= fmax)
    if np.count_nonzero(keep) < 8:
        raise UserError(f"fewer than 8 lines between 0 and --fmax {fmax:g} Hz: raise --fmax "
                        "or the record length")
    H = np.concatenate(Hs, axis=1)[..., keep]
    coh = np.nan_to_num(np.concatenate(cohs, axis=1)[..., keep])
    finite = np.all(np.isfinite(H), axis=(0, 2))
    for j in np.flatnonzero(~finite):
        n = int(np.count_nonzero(~np.all(np.isfinite(H[:, j]), axis=0)))
        skipped(args, f"excitation node {exc_nodes[j]}: FRF undefined at {n} lines (no force "
                      "there): excite the whole band")
    if not finite.any():
        raise UserError("every FRF column is undefined somewhere (no force at some "
                        "frequencies): excite the whole band")
    out = FRFSet(freq=freq[keep], H=H[:, finite], resp_nodes=resp_nodes, resp_dirs=resp_dirs,
                 exc_nodes=exc_nodes[finite], exc_dirs=exc_dirs[finite], geometry=geometry,
                 coherence=coh[:, finite], meta=meta)
    return out, int(np.count_nonzero(~finite))


def print_checks(out: FRFSet, threshold: float) -> None:
    """Print the coherence gate summary and the rigidity check of an FRF set."""
    assert out.coherence is not None
    print(coherence_gate(out.coherence, out.freq, threshold).summary())
    try:
        print(rigidity_check(out).summary())
    except GeometryError as err:
        print(f"rigidity check not possible: {err}")


def frfset_from_run_file(path: Path, args: argparse.Namespace) -> tuple[FRFSet, int]:
    """FRFs of a run file's points, every stored hit processed again as ``insitu replay`` does
    (``app.acquire.analysis.analyse_records``: the plan's settings, the overrides).

    A point without a usable hit gets one stderr line and is left out; returns the FRF set
    and the number of such points. The time-data options (but ``--coherence``, ``--fmax``
    and ``--averages``: the first N used hits or blocks of each point) do not apply: the
    plan's record settings do.
    """
    from app.acquire.analysis import analyse_records, run_frfs
    from app.io.runfile import RunFileError, read_run

    if args.averages is not None and args.averages < 1:
        raise UserError(f"--averages must be at least 1, got {args.averages}")

    try:
        data = read_run(path)
    except RunFileError as err:
        raise UserError(str(err)) from err
    if len(data.records) == 0:
        raise UserError(f"{path}: the run holds no hit yet: record hits (insitu acquire)")
    rows = data.channels
    fmax = args.fmax if args.fmax is not None else data.records.fs / 2.56
    if data.method != "hammer":  # shaker runs: the run's own FRFs (every point needed)
        try:
            frfs = run_frfs(data, args.averages)[0]
        except InputError as err:
            raise UserError(str(err)) from err
        out, n_bad = _assemble(frfs.freq, [frfs.H], [frfs.coherence], frfs.resp_nodes,
                               frfs.resp_dirs, frfs.exc_nodes, frfs.exc_dirs, frfs.geometry,
                               dict(frfs.meta), fmax, args)
        print_checks(out, args.coherence)
        return out, n_bad
    plan, ana = analyse_records(data)
    rec = data.records
    good: list[int] = []
    results: list[ImpactResult] = []
    n_bad = 0
    for j, point in enumerate(plan.excitations):
        mine = np.flatnonzero(rec.point == j)
        res = ana.point(j, args.averages)
        if res is None or res.H is None or res.coherence is None:
            why = ("no hit recorded" if mine.size == 0 else
                   f"every hit rejected ({'; '.join(rec.reason[i] or 'rejected' for i in mine)})")
            skipped(args, f"{point.label}: {why}: hit it again (insitu acquire --resume)")
            n_bad += 1
            continue
        n_used = ana.n_used(j) if args.averages is None else min(ana.n_used(j), args.averages)
        print(f"{point.label}: {n_used} of {mine.size} hits used")
        good.append(j)
        results.append(res)
    if not results:
        raise UserError(f"{path}: no point has an accepted hit ({n_bad} points, see above)")
    col = impact_frfset(results, data.geometry, np.array([c.node for c in rows[1:]]),
                        np.array([c.direction for c in rows[1:]]), plan.exc_nodes[good],
                        plan.exc_dirs[good])
    out, n_undefined = _assemble(col.freq, [col.H], [col.coherence], col.resp_nodes,
                                 col.resp_dirs, col.exc_nodes, col.exc_dirs, col.geometry,
                                 col.meta, fmax, args)
    print_checks(out, args.coherence)
    return out, n_bad + n_undefined
