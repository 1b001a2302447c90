"""``insitu repair RUN.h5``: make a run file killed in the middle of a write readable by any tool.

The writer opens the run file only while it appends a record, so after a crash the
file is nearly always readable as it is. If the crash struck during a write, the file
is still marked open for writing: HDF5 tools refuse it, and so does ``insitu`` unless the
writer had SWMR on. This verb clears the mark (as HDF5's ``h5clear -s``) and rewrites the
file into a clean copy (every completed record kept) that then replaces it.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from app.cli.common import VERB_HELP
from app.io.runfile import read_run, repair


def add_parser(sub: Any) -> None:
    p = sub.add_parser("repair", help=VERB_HELP["repair"],
                       description=__doc__)
    p.add_argument("file", type=Path, help="run file (HDF5) written by insitu acquire")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    mended = repair(args.file)  # one line if it is no run file
    data = read_run(args.file, with_data=False)
    what = "repaired" if mended else "already readable by any HDF5 tool"
    print(f"{args.file}: {what}; {len(data.records)} records ({data.state})")
    return 0
