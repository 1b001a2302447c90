"""``insitu frf INPUT [--out FRF.uff|FRF.h5]``: FRFs and coherence from time data.

INPUT is a UFF file of time records, a TDMS (NI) or MDF 4 (.mf4) file of time records with
its channel map (``--channels MAP.toml``, or ``INPUT.map.toml`` beside it: which channel is
the force, which node and direction each response measures, docs/time-files.md), or a run
file (``.h5``) written by ``insitu acquire``.

UFF, TDMS, MDF: each run (its records sharing a load case: one force, the accelerations) gives
the FRF column of its excitation DOF; runs at the same DOF are averaged together.
``--method random`` (shaker: continuous random, Welch with Hann window and overlap;
a periodic force, e.g. periodic chirp, one record per period with a rectangular window
once the responses repeat; burst random, one record from each burst's onset, rectangular;
read from the force unless ``--nperseg``, ``--overlap`` or ``--window`` is given) or
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
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from app.cli.common import FLAGS, VERB_HELP, UserError, check_output, reason
from app.io.frf_h5 import write_frf_h5
from app.io.uff import write_frf_uff
from app.pipeline import (
    FRF_H5,
    FRF_UFF,
    RUN_FILE,
    TIME_FORMATS,
    TIME_MDF,
    TIME_TDMS,
    OpenError,
    RunReport,
    Settings,
    detect_format,
    load,
)
from app.pipeline.formats import H5_SUFFIXES, UFF_SUFFIXES
from processing.data import ESTIMATORS
from processing.measurement import Measurement


def add_parser(sub: Any) -> None:
    p = sub.add_parser("frf", help=VERB_HELP["frf"],
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", type=Path,
                   help="UFF file with geometry and time records (58, type 1), a TDMS or MDF "
                        "file of time records (with --channels), or a run file (.h5) written by "
                        "insitu acquire")
    p.add_argument("--out", type=Path,
                   help="FRF file to write: .uff/.unv (UFF 58) or .h5/.hdf5 (HDF5 FRF file); "
                        "default INPUT's name with _frf.uff")
    add_processing_arguments(p, method_alias=True)
    p.add_argument("--binary", action="store_true", help="UFF output: write binary 58b records")
    p.set_defaults(run=run)


#: the time-data options (their ``dest``) and their values when not given (``--coherence``
#: is not one: the identification of any input weighs FRF values by it)
TIME_OPTIONS: dict[str, object] = {
    "excitation": None, "estimator": "H1", "nperseg": None, "overlap": None, "window": None,
    "averages": None, "level": None, "record": None, "pretrigger": None, "ring": None,
    "exp_tau": None, "carryover": None, "tail": None, "fmax": None, "channels": None}
#: the options of Welch segments (random excitation) and of hammer records (impact)
WELCH_OPTIONS = ("nperseg", "overlap", "window")
HAMMER_OPTIONS = ("level", "record", "pretrigger", "ring", "exp_tau", "tail")
#: the time-data options ``insitu frf`` uses on a run file (the points it averages, the band)
RUN_FILE_OPTIONS = ("averages", "fmax")


def ignored_options(args: argparse.Namespace, fmt: str, name: str, *,
                    run_file_options: Sequence[str] = (),
                    excitation: str | None = None) -> str | None:
    """The one line naming the options given that do not apply to input ``name`` of format
    ``fmt`` (None when all apply): time-data options on FRFs, on a run file (but
    ``run_file_options``), Welch options on impact data, hammer options on random data
    (``excitation``: the time records' excitation when known), ``--bootstrap`` on FRFs."""
    given = [d for d, unset in TIME_OPTIONS.items() if getattr(args, d, unset) != unset]
    if fmt in TIME_FORMATS and "channels" in given:  # time records: a map or not, said apart
        given.remove("channels")
    if fmt in (FRF_UFF, FRF_H5):
        if getattr(args, "bootstrap", None):
            given.append("bootstrap")
        why = f"{name} holds FRFs, not time records"
    elif fmt == RUN_FILE:
        given = [d for d in given if d not in run_file_options]
        why = f"{name} is a run file: its records are processed with its plan's settings"
    elif excitation == "impact":
        given = [d for d in given if d in WELCH_OPTIONS]
        why = "the excitation is impact (they cut the Welch segments of random excitation)"
    elif excitation == "random":
        given = [d for d in given if d in HAMMER_OPTIONS]
        why = "the excitation is random (they set the records of hammer hits)"
    else:
        return None
    if not given:
        return None
    flags = {**FLAGS, "excitation": "--excitation", "estimator": "--estimator",
             "bootstrap": "--bootstrap", "channels": "--channels"}
    return f"{', '.join(flags[d] for d in given)} ignored: {why}"


def warn_ignored(args: argparse.Namespace, fmt: str, path: Path, *,
                 run_file_options: Sequence[str] = (),
                 excitation: str | None = None) -> None:
    """Prints :func:`ignored_options`' line on stderr, if any."""
    line = ignored_options(args, fmt, path.name, run_file_options=run_file_options,
                           excitation=excitation)
    if line:
        print(f"insitu {getattr(args, 'verb', 'frf')}: warning: {line}", file=sys.stderr)


def given_excitation(args: argparse.Namespace) -> str | None:
    """The time records' excitation the options say (a hammer option given means impact),
    or None when the data tell."""
    if args.excitation is not None:
        return str(args.excitation)
    return "impact" if any(getattr(args, d) is not None for d in HAMMER_OPTIONS) else None


def add_processing_arguments(p: Any, *, method_alias: bool = False) -> None:
    """The options that turn time records into FRFs (shared with ``insitu identify``)."""
    flags = ("--excitation", "--method") if method_alias else ("--excitation",)
    p.add_argument("--channels", type=Path, metavar="MAP.toml",
                   help="TDMS or MDF file: its channel map (force and response channels, "
                        "nodes, directions, units, runs; docs/time-files.md); default: "
                        "FILE.map.toml beside it")
    p.add_argument(*flags, dest="excitation", choices=("random", "impact"),
                   help="time data: shaker random or hammer impact (default: from the force "
                        "channel, an impulsive force is a hammer test; a hammer option given "
                        "means impact)")
    p.add_argument("--estimator", choices=ESTIMATORS, default="H1")
    p.add_argument("--nperseg", type=int,
                   help="random: samples per Welch segment (line spacing fs/nperseg; default "
                        "from the force: one period of a periodic force, one burst of burst "
                        "random, else 2048)")
    p.add_argument("--overlap", type=float,
                   help="random: Welch segment overlap, 0..<1 (default 0.5)")
    p.add_argument("--window", help="random: Welch window (hann, boxcar, ...; default hann)")
    p.add_argument("--averages", type=int, metavar="N",
                   help="use at most N averages: random, the first N segments of each run; "
                        "impact, the first N accepted hits of each excitation point "
                        "(default: all)")
    p.add_argument("--level", type=float,
                   help="impact: trigger level, N (default: from each run's force noise)")
    p.add_argument("--record", type=float,
                   help="impact: record length, s (default: from the hit spacing and the "
                        "responses' decay)")
    p.add_argument("--pretrigger", type=float, help="impact: pre-trigger, s (default 0.01)")
    p.add_argument("--force-ring", type=int, dest="ring", metavar="SAMPLES",
                   help="impact: samples the force window keeps after each pulse's end at "
                        "least, then a half-cosine as long (default 0: one pulse width; the "
                        "force's ringing read from the data is printed)")
    p.add_argument("--exp-tau", type=float,
                   help="impact: exponential window time constant, s (default: chosen when "
                        "the responses have not decayed by the end of the record; 0: none)")
    p.add_argument("--carryover", choices=("on", "off"),
                   help="impact and burst random: take the earlier hits' or bursts' ringing "
                        "off each record (its free decay fitted before the record, continued "
                        "and subtracted; a burst record also gets its own cut-off tail back); "
                        "default: on when the responses still ring above their noise at the "
                        "next hit or the record's end")
    p.add_argument("--tail", choices=("on", "off"),
                   help="impact: put each record's own tail back (the responses' free decay "
                        "after the hit continued past the record's end and folded onto it: "
                        "no leakage without an exponential window); default: on when no "
                        "exponential window is used")
    p.add_argument("--coherence", type=float, default=0.8, help="coherence gate threshold")
    p.add_argument("--fmax", type=float,
                   help="highest line kept, Hz (default fs / 2.56, the anti-alias filters' "
                        "usable band)")


def skipped(args: argparse.Namespace, message: str) -> None:
    """One stderr line for a run that is reported and skipped."""
    print(f"insitu {getattr(args, 'verb', 'frf')}: {message} (skipped)", file=sys.stderr)


def settings_from(args: argparse.Namespace, **kwargs: Any) -> Settings:
    """The pipeline's settings from the time-data options (``kwargs``: the others)."""
    return Settings(excitation=args.excitation, estimator=args.estimator, nperseg=args.nperseg,
                    overlap=args.overlap, window=args.window, averages=args.averages,
                    level=args.level, record=args.record, pretrigger=args.pretrigger,
                    exp_tau=args.exp_tau, ring=args.ring,
                    carryover=None if args.carryover is None else args.carryover == "on",
                    tail=None if args.tail is None else args.tail == "on",
                    coherence=args.coherence,
                    fmax=args.fmax, channel_map=getattr(args, "channels", None), **kwargs)


def load_and_show(path: Path, args: argparse.Namespace, settings: Settings, fmt: str, *,
                  run_file_options: Sequence[str] = ()) -> Measurement:
    """``path``'s measurement through the pipeline (:func:`app.pipeline.load`), its reports
    printed (a run left out: one stderr line); a spinner on a terminal while it reads. The
    options given that do not apply are named (:func:`warn_ignored`; ``run_file_options``
    those that apply to a run file): before the reading, or after it when the time records'
    excitation comes from the data."""
    import contextlib

    from rich.console import Console

    err = Console(stderr=True)
    # a spinner on a terminal's stderr while the file is read (a time UFF takes seconds)
    spinner = err.status(f"reading {path.name}") if err.is_terminal else contextlib.nullcontext()
    excitation = given_excitation(args)
    warn_ignored(args, fmt, path, run_file_options=run_file_options, excitation=excitation)
    if fmt in TIME_FORMATS and fmt not in (TIME_TDMS, TIME_MDF) and getattr(
            args, "channels", None) is not None:
        print(f"insitu {getattr(args, 'verb', 'frf')}: warning: --channels ignored: "
              f"{path.name} is a UFF file, its records name their channels' DOFs and units",
              file=sys.stderr)
    try:
        with spinner:
            m = load(path, settings, fmt=fmt)
    except OpenError as err:
        show_reports(args, err.reports)
        raise
    show_reports(args, m.provenance.reports)
    if fmt in TIME_FORMATS and excitation is None:
        warn_ignored(args, fmt, path, excitation=m.provenance.excitation)
    return m


def show_reports(args: argparse.Namespace, reports: Sequence[RunReport]) -> None:
    """Print the pipeline's reports: a run left out on stderr (:func:`skipped`)."""
    for r in reports:
        if r.skipped:
            skipped(args, r.message)
        else:
            print(r.message)


def run(args: argparse.Namespace) -> int:
    settings = settings_from(args, run_points="usable")  # options checked before any file
    out = args.out or args.file.with_name(args.file.stem + "_frf.uff")
    suffix = out.suffix.lower()
    if suffix not in H5_SUFFIXES + UFF_SUFFIXES:
        raise UserError(f"--out {out}: unknown suffix {out.suffix!r}: use .uff or .unv (UFF 58) "
                        "or .h5 or .hdf5 (HDF5 FRF file)")
    check_output(out, inputs=(args.file,))  # before the records are read
    fmt = detect_format(args.file)
    if fmt in (FRF_UFF, FRF_H5):  # FRFs are no input of insitu frf: read as time records
        fmt = RUN_FILE if args.file.suffix.lower() in H5_SUFFIXES else TIME_FORMATS[0]
    m = load_and_show(args.file, args, settings, fmt, run_file_options=RUN_FILE_OPTIONS)
    frfs, n_bad = m.frf, m.provenance.skipped
    try:
        if suffix in H5_SUFFIXES:
            write_frf_h5(out, m, source=str(args.file))
        else:
            write_frf_uff(out, frfs, binary=args.binary, coherence=True)
    except OSError as err:  # the folder went away or the disk filled since the check
        raise UserError(f"--out {out}: {reason(err)}: free some space or choose another "
                        "--out; no FRF file was written") from err
    print(f"{frfs.H.shape[0]} x {frfs.H.shape[1]} FRFs ({m.provenance.estimator}), "
          f"{frfs.freq.size} lines, written to {out}"
          + (f"; {n_bad} bad run(s) skipped, exit status 2" if n_bad else ""))
    return 2 if n_bad else 0
