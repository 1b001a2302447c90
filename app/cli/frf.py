"""``insitu frf FILE.uff --out FRF.uff``: FRFs and coherence from UFF time records.

Each run of the file (its records sharing a load case: one force, the accelerations)
gives the FRF column of its excitation DOF; runs at the same DOF are averaged
together. ``--method random`` (shaker: continuous random, Welch with Hann window and
overlap; also burst random and periodic chirp with ``--window boxcar --overlap 0``)
or ``--method impact`` (hammer: trigger, per-hit checks, force and exponential
windows). Writes the FRFs with their coherence and geometry as UFF, and prints the
hits rejected, the coherence gate and the rigidity check.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from app.cli.common import UserError
from app.io.uff import read_time_uff, write_frf_uff
from app.io.uff_geometry import read_geometry_uff
from processing.coherence import coherence_gate
from processing.data import FRFSet
from processing.geometry import GeometryError
from processing.impact import ImpactResult, ImpactSettings, merge_results, process_impacts
from processing.rigidity import rigidity_check
from processing.spectral import ESTIMATORS, CrossSpectra, SpectralAccumulator, combine, frf


def add_parser(sub: Any) -> None:
    p = sub.add_parser("frf", help="FRFs and coherence from UFF time records",
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", type=Path, help="UFF file with geometry and time records (58, type 1)")
    p.add_argument("--out", type=Path, required=True, help="UFF file to write the FRFs to")
    add_processing_arguments(p, method_alias=True)
    p.add_argument("--binary", action="store_true", help="write binary 58b records")
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


def _random_spectra(force: np.ndarray, responses: np.ndarray, fs: float,
                    args: argparse.Namespace) -> CrossSpectra:
    nperseg = args.nperseg
    if force.size < nperseg:
        raise UserError(f"a run has {force.size} samples, fewer than --nperseg {nperseg}")
    acc = SpectralAccumulator(fs, nperseg, round(args.overlap * nperseg),
                              window=args.window)
    acc.update(np.vstack([force[None], responses]))
    return acc.spectra()


def _impact(force: np.ndarray, responses: np.ndarray, fs: float,
            args: argparse.Namespace) -> ImpactResult:
    level = args.level if args.level is not None else 0.1 * float(np.max(np.abs(force)))
    settings = ImpactSettings(
        level=level, record_length=round(args.record * fs),
        pretrigger=round(args.pretrigger * fs),
        slope="rising" if level > 0 else "falling", exp_tau=args.exp_tau,
    )
    names = ["force", *(f"response {i + 1}" for i in range(responses.shape[0]))]
    return process_impacts(np.vstack([force[None], responses]), fs, settings,
                           channel_names=names, estimator=args.estimator)


def run(args: argparse.Namespace) -> int:
    out = frfset_from_time_uff(args.file, args)
    write_frf_uff(args.out, out, binary=args.binary, coherence=True)
    print(f"{out.H.shape[0]} x {out.H.shape[1]} FRFs ({args.estimator}), {out.freq.size} lines, "
          f"written to {args.out}")
    return 0


def frfset_from_time_uff(path: Path, args: argparse.Namespace) -> FRFSet:
    """FRFs with coherence and geometry from the time runs of a UFF file; prints per-run
    verdicts, the coherence gate and the rigidity check."""
    if not 0 <= args.overlap < 1:
        raise UserError(f"--overlap must be in [0, 1), got {args.overlap}")
    runs, problems = read_time_uff(path, strict=False)
    for case, msg in problems:
        print(f"load case {case} skipped: {msg}")
    if not runs:
        raise UserError(f"{path}: no usable time run")
    geometry, _ = read_geometry_uff(path)
    first = runs[0]
    for r in runs[1:]:
        if (r.fs != first.fs or not np.array_equal(r.resp_nodes, first.resp_nodes)
                or not np.allclose(r.resp_dirs, first.resp_dirs)):
            raise UserError(
                f"load case {r.load_case}: sample rate or response DOFs differ from load case "
                f"{first.load_case}; process such runs in separate files"
            )
    # one excitation column per distinct excitation DOF, in order of appearance
    keys: list[tuple[int, tuple[float, ...]]] = []
    groups: dict[tuple[int, tuple[float, ...]], list[int]] = {}
    for i, r in enumerate(runs):
        key = (int(r.exc_node), tuple(np.round(r.exc_dir, 6)))
        if key not in groups:
            keys.append(key)
            groups[key] = []
        groups[key].append(i)

    cols, cohs = [], []
    freq = None
    for key in keys:
        members = [runs[i] for i in groups[key]]
        if args.excitation == "impact":
            results = [_impact(r.force, r.responses, r.fs, args) for r in members]
            res = merge_results(results)
            for r, one in zip(members, results, strict=True):
                bad = one.rejected
                print(f"load case {r.load_case} (node {key[0]}): {one.n_accepted} hits accepted"
                      + (", rejected: " + "; ".join(f"hit {v.index + 1}: {v.reason}"
                                                   for v in bad) if bad else ""))
            if res.H is None or res.coherence is None:
                raise UserError(f"excitation node {key[0]}: no accepted hit")
            H, coh, f = res.H, res.coherence, res.freq
        else:
            sp = _random_spectra(members[0].force, members[0].responses, members[0].fs, args)
            for r in members[1:]:
                sp = combine(sp, _random_spectra(r.force, r.responses, r.fs, args))
            H, coh = frf(sp, args.estimator)
            f = sp.freq
            print(f"excitation node {key[0]}: {sp.n_averages} averages")
        cols.append(H)
        cohs.append(coh)
        freq = f
    assert freq is not None
    H_all = np.concatenate(cols, axis=1)
    coh_all = np.concatenate(cohs, axis=1)
    # 0 Hz carries no accelerance information (and NaN estimates): start at the first line;
    # above fs / 2.56 the DAQ's anti-alias filters shape the data
    fmax = args.fmax if args.fmax is not None else first.fs / 2.56
    keep = (freq > 0) & (freq <= fmax)
    if np.count_nonzero(keep) < 8:
        raise UserError(f"fewer than 8 lines between 0 and --fmax {fmax:g} Hz: raise --fmax "
                        "or the record length")
    if not np.all(np.isfinite(H_all[..., keep])):
        raise UserError("some FRF lines are undefined (no force at those frequencies)")
    out = FRFSet(
        freq=freq[keep], H=H_all[..., keep], resp_nodes=first.resp_nodes,
        resp_dirs=first.resp_dirs, exc_nodes=np.array([k[0] for k in keys]),
        exc_dirs=np.array([k[1] for k in keys]), geometry=geometry,
        coherence=np.nan_to_num(coh_all[..., keep]),
        meta={"estimator": args.estimator, "excitation": args.excitation,
              "exponential_tau": args.exp_tau if args.excitation == "impact" else None},
    )
    assert out.coherence is not None
    print(coherence_gate(out.coherence, out.freq, args.coherence).summary())
    try:
        print(rigidity_check(out).summary())
    except GeometryError as err:
        print(f"rigidity check not possible: {err}")
    return out
