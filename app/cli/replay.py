"""``insitu replay RUN.h5``: recompute FRFs and the identification from a run's raw records.

The run file is loaded as every view loads it (:func:`app.pipeline.load`: the live run's own
code on the records as stored, with the operator's overrides) and fitted
(:func:`processing.identify.fit`): the FRFs and the result are identical to the live run's,
and the command says whether they are. A run whose force was aligned by host timing only
is refused. To change an override, see ``insitu acquire --resume --override``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from app.cli.common import VERB_HELP, UserError, check_output, fit_progress, write_output
from app.cli.summary import print_result
from app.io.runfile import read_run
from app.pipeline import RUN_FILE, load
from processing.identify import fit


def add_parser(sub: Any) -> None:
    p = sub.add_parser("replay", help=VERB_HELP["replay"],
                       description=__doc__)
    p.add_argument("file", type=Path, help="run file (HDF5) written by insitu acquire")
    p.add_argument("--out", type=Path, help="write the result JSON here")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.out is not None:
        check_output(args.out, inputs=(args.file,))  # before the run is read
    data = read_run(args.file)
    if len(data.records) == 0:
        raise UserError(f"{args.file}: the run holds no record yet")
    m = load(args.file, fmt=RUN_FILE)
    with fit_progress() as progress:
        frf, result = m.frf, fit(m, progress=progress)
    what = "blocks" if data.method == "shaker" else "hits"
    console = Console()
    acc = int(np.count_nonzero(data.records.accepted))
    console.print(f"[bold]{args.file}[/bold] ({data.state}): {len(data.records)} {what}, "
                  f"{acc} used, {frf.H.shape[0]} x {frf.H.shape[1]} FRFs")
    if data.measurement is not None:
        stored = data.measurement.frf.select_lines(frf.freq[-1])  # kept on all its lines
        same = np.array_equal(stored.H, frf.H) and data.result == json.loads(
            json.dumps(result.to_json()))
        console.print("identical to the live run" if same else
                      "[yellow]differs from the FRFs stored by the live run[/yellow]")
    print_result(result, console)
    if args.out:
        write_output(args.out, json.dumps(result.to_json(), indent=2))
        console.print(f"result written to {args.out}")
    return 0
