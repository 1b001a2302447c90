"""``insitu batch FILES... --out DIR``: many files identified on a Dask cluster, one table.

Each file (UFF FRFs or time records, HDF5 FRF file, run file) is opened and identified as
``insitu identify`` does it, with the same options and defaults, on the workers of a Dask
distributed cluster: a local cluster of worker processes by default (no set-up), or the
running scheduler given by ``--scheduler tcp://HOST:PORT`` (started with ``dask scheduler``
and ``dask worker ADDRESS``). One row per file (status, mass, CoG, inertia, principal
moments, first and last rigid-body mode, and each number's standard deviation when the
result has one; a file that fails gets its one-line error in its row and the others go on)
is written to DIR as ``campaign.csv``, ``campaign.parquet`` and ``campaign.html``. The exit
status is 2 when any file failed.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from app.batch.campaign import TABLE_NAME, Row, run_campaign, write_tables
from app.batch.cluster import open_client, total_threads
from app.cli import identify as identify_verb
from app.cli.common import VERB_HELP, UserError, check_folder, check_output, check_range, reason
from app.cli.frf import add_processing_arguments, settings_from

#: the ``insitu identify`` options a campaign takes, with identify's own definitions and
#: defaults (those of the FRFs from time data are added from identify's parser too); an option
#: is listed here once :func:`run` passes it on to :func:`app.batch.campaign.identify_file`
_IDENTIFY = {"mass_band", "stiffness_band", "physical", "method", "stiffening", "channel_delays",
             "refine_points",
             "no_uncertainty", "location_uncertainty", "angle_uncertainty", "gain_uncertainty",
             "draws", "bootstrap"}


#: the tables a campaign writes in ``--out``
TABLES = tuple(f"{TABLE_NAME}.{ext}" for ext in ("csv", "parquet", "html"))


class _Capture:
    """Stands for a subparsers object: keeps the parser ``insitu identify`` builds."""

    parser: argparse.ArgumentParser

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        self.parser = argparse.ArgumentParser(prog=name, add_help=False)
        return self.parser


def add_parser(sub: Any) -> None:
    p = sub.add_parser("batch", help=VERB_HELP["batch"],
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("files", type=Path, nargs="+", metavar="FILE",
                   help="run files (.h5), HDF5 FRF files or UFF files")
    p.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="folder for campaign.csv, campaign.parquet and campaign.html")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:port); default: a local "
                        "cluster started for this command")
    p.add_argument("--workers", type=int, metavar="N",
                   help="local cluster: worker processes, one thread each (default: one "
                        "per core)")
    g = p.add_argument_group("identification (as insitu identify)")
    capture = _Capture()
    identify_verb.add_parser(capture)
    scratch = argparse.ArgumentParser(add_help=False)
    add_processing_arguments(scratch)
    wanted = _IDENTIFY | {a.dest for a in scratch._actions}
    for action in capture.parser._actions:  # the same options and defaults as identify
        if action.dest in wanted:
            g._add_action(action)
    p.set_defaults(run=run)


#: most local worker processes (one thread each): beyond any machine's cores
MAX_WORKERS = 256


def check_out_folder(out: Path) -> None:
    """``--out DIR`` checked before any work: a folder (or one to create in an existing,
    writable folder) whose tables can be written."""
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} is a file, not a folder: give a folder for the tables")
    if out.is_dir():
        check_folder(out, "--out", f"--out {out}")
        for name in TABLES:
            check_output(out / name, "--out")
        return
    parent = out.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    check_folder(parent, "--out", f"--out {out}")  # the folders are created there


def run(args: argparse.Namespace) -> int:
    check_range("--workers", args.workers, 1, MAX_WORKERS, "worker processes")
    if args.workers is not None and args.scheduler is not None:
        raise UserError("--workers sizes the local cluster: leave it out with --scheduler "
                        "(the running cluster has its own workers)")
    settings = settings_from(args)  # every option checked before any work is sent
    options = identify_verb.options_from(args, identify_verb.stated_from(args))
    check_out_folder(args.out)
    missing = [str(f) for f in args.files if not f.is_file()]
    if missing:
        raise UserError(f"no such file: {', '.join(missing[:5])}"
                        + (f" and {len(missing) - 5} more" if len(missing) > 5 else ""))
    console = Console()
    t0 = time.perf_counter()
    with open_client(args.scheduler, args.workers) as client:
        where = args.scheduler or "a local cluster"
        n_workers = len(client.scheduler_info().get("workers", {}))
        console.print(f"{len(args.files)} files on {where}: {n_workers} workers, "
                      f"{total_threads(client)} threads")
        with Progress(TextColumn("identifying"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), TextColumn("{task.description}"),
                      console=console) as bar:
            task = bar.add_task("", total=len(args.files))

            def advance(row: Row) -> None:
                bar.update(task, advance=1, description=f"{Path(row['file']).name}: "
                           + (row["status"] if row["status"] == "ok" else "error"))

            rows = run_campaign(client, args.files, settings, options, advance)
    elapsed = time.perf_counter() - t0
    for r in rows:
        if r["status"] != "ok":
            console.print(f"[red]error[/red] {escape(str(r['file']))}: {escape(r['error'])}",
                          highlight=False)
    try:
        paths = write_tables(rows, args.out)
    except OSError as err:  # the disk filled or the folder went away since the check
        raise UserError(f"--out {args.out}: {reason(err)}: free some space or choose another "
                        "--out") from err
    n_bad = sum(r["status"] != "ok" for r in rows)
    console.print(f"{len(rows)} files: {len(rows) - n_bad} identified, {n_bad} failed, in "
                  f"{elapsed:.1f} s on {n_workers} workers; written "
                  + ", ".join(str(p) for p in paths), highlight=False)
    return 2 if n_bad else 0
