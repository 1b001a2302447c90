"""``insitu export RUN.h5 --tdms OUT.tdms --mf4 OUT.mf4 --uff OUT.uff``: a run's raw records
for other systems.

Each record the run uses (its verdict in force: the automatic one or the operator's
override; ``--all`` every record) becomes one time run: its force and responses as stored
(N, m/s^2, float64, on the front end's clock), excited at its point of the plan. A TDMS file
holds one group a record, an MDF file one channel group a record (acquisition name
``record N``, N the record's number as the run printed it), each written with its channel
map beside it (``OUT.map.toml``); a UFF file (binary 58b records: the samples to their last
bit) holds one load case a record. ``insitu identify OUT.tdms`` (or ``.mf4``, ``.uff``)
then computes the FRFs from the records by the time-records code, the same FRFs from each
of the three (docs/time-files.md). A record with lost samples (NaN) is not exported.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from app.cli.common import VERB_HELP, UserError, check_output, reason, write_output


def add_parser(sub: Any) -> None:
    p = sub.add_parser("export", help=VERB_HELP["export"], description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", type=Path, help="run file (.h5) written by insitu acquire")
    p.add_argument("--tdms", type=Path, metavar="OUT.tdms",
                   help="write a TDMS file (one group a record) and OUT.map.toml beside it "
                        "(needs insitu[tdms])")
    p.add_argument("--mf4", type=Path, metavar="OUT.mf4",
                   help="write an MDF 4 file (one channel group a record) and OUT.map.toml "
                        "beside it (needs insitu[mdf])")
    p.add_argument("--uff", type=Path, metavar="OUT.uff",
                   help="write a UFF file of time records (binary 58b, one load case a record)")
    p.add_argument("--all", action="store_true",
                   help="every record, rejected ones too (default: the records the run uses)")
    p.set_defaults(run=run)


def run_records(path: Path, every: bool = False) -> tuple[Any, list[int], list[Any]]:
    """A run file's records as time runs: the run (:class:`app.io.runfile.RunData`), the
    records kept (indices: those used, or ``every`` one, without lost samples) and their
    :class:`app.io.uff_time.TimeRun` (load cases 1, 2, ... in that order)."""
    from app.acquire.plan import parse_plan
    from app.io.runfile import read_run
    from app.io.uff_time import TimeRun

    run = read_run(path)
    rec = run.records
    if len(rec) == 0:
        raise UserError(f"{path}: the run holds no record yet: nothing to export")
    plan = parse_plan(run.plan_data, f"{path}:/plan")
    if plan.n_references > 1:
        raise UserError(f"{path}: each record holds {plan.n_references} forces (shakers "
                        "driven together); a time run has one force: export runs of one "
                        "shaker or hammer")
    rows = run.channels[1:]
    nodes = np.array([c.node for c in rows], dtype=np.int64)
    dirs = np.array([c.direction for c in rows], dtype=float)
    whole = np.all(np.isfinite(rec.data), axis=(1, 2))
    keep = np.flatnonzero(whole & (True if every else rec.accepted))
    if keep.size == 0:
        hint = "" if every else " (--all for the rejected ones)"
        raise UserError(f"{path}: no record to export (none used{hint} or every one has lost "
                        "samples)")
    runs = []
    for k, i in enumerate(keep.tolist()):
        point = plan.excitations[int(rec.point[i])]
        data = rec.data[i]
        runs.append(TimeRun(k + 1, rec.fs, data[0], point.node, np.array(point.direction),
                            data[1:], nodes, dirs))
    return run, keep.tolist(), runs


def _map(run: Any, keep: list[int], runs: list[Any], groups: list[str], names: list[str],
         source: str) -> str:
    """The channel map of the exported records (one excitation per plan point used)."""
    from app.io.channel_map import map_text

    by_point: dict[int, list[str]] = {}
    for i, g in zip(keep, groups, strict=True):
        by_point.setdefault(int(run.records.point[i]), []).append(g)
    first = {int(run.records.point[i]): r for i, r in zip(keep, runs, strict=True)}
    rows = run.channels[1:]
    return map_text(source, names[0],
                    [(n, c.node, c.direction) for n, c in zip(names[1:], rows, strict=True)],
                    [(first[p].exc_node, first[p].exc_dir, g) for p, g in by_point.items()],
                    run.geometry)


def run(args: argparse.Namespace) -> int:
    outs = {"--tdms": args.tdms, "--mf4": args.mf4, "--uff": args.uff}
    if not any(outs.values()):
        raise UserError("say what to write: --tdms OUT.tdms, --mf4 OUT.mf4 and/or --uff OUT.uff")
    from app.io.channel_map import default_map_path

    wanted = {".tdms": (".tdms",), ".mf4": (".mf4", ".mdf"), ".uff": (".uff", ".unv")}
    for flag, out in outs.items():
        if out is None:
            continue
        if out.suffix.lower() not in wanted["." + flag[2:]]:
            raise UserError(f"{flag} {out}: give a file name ending in "
                            f"{' or '.join(wanted['.' + flag[2:]])}")
        check_output(out, flag, inputs=(args.file,))
        if flag != "--uff":
            check_output(default_map_path(out), flag, inputs=(args.file,))
    if args.tdms is not None:
        from app.io.tdms import nptdms

        nptdms()  # a missing extra said before the run is read
    if args.mf4 is not None:
        from app.io.mdf import asammdf

        asammdf()
    run_data, keep, runs = run_records(args.file, args.all)
    groups = [f"record {i + 1}" for i in keep]
    names = [c.name for c in run_data.channels]
    if len(set(names)) != len(names):
        names = ["force", *(f"response {k}" for k in range(1, len(names)))]
    rec = run_data.records
    source = args.file.name
    for flag, out in outs.items():
        if out is None:
            continue
        t0 = time.perf_counter()
        try:
            if flag == "--tdms":
                from app.io.tdms import write_time_tdms

                write_time_tdms(out, runs, groups, names, [
                    {"point": int(rec.point[i]) + 1, "time": float(rec.time[i]),
                     "accepted": int(rec.accepted[i]), "reason": rec.reason[i],
                     "source": source} for i in keep])
            elif flag == "--mf4":
                from app.io.mdf import write_time_mdf

                write_time_mdf(out, runs, groups, names, [
                    f"{source} record {i + 1}: point {int(rec.point[i]) + 1}, "
                    f"{'accepted' if rec.accepted[i] else 'rejected'}"
                    + (f" ({rec.reason[i]})" if rec.reason[i] else "") for i in keep])
            else:
                from app.io.uff_time import write_time_uff

                write_time_uff(out, runs, run_data.geometry, binary=True)
        except OSError as err:
            raise UserError(f"{flag} {out}: {reason(err)}: free some space or choose "
                            f"another {flag}") from err
        line = f"{len(runs)} records written to {out}"
        if flag != "--uff":
            m = default_map_path(out)
            write_output(m, _map(run_data, keep, runs, groups, names, source), flag)
            line += f", channel map {m}"
        print(f"{line} ({time.perf_counter() - t0:.2f} s)")
    return 0
