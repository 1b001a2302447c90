"""``insitu report FILE [--out report.html]``: the test report, without a GUI.

FILE is any file ``insitu identify`` reads: a run file (its records processed again), an
FRF file (``.h5``), a UFF file of FRFs or of time records, a TDMS or MDF file of time
records with its channel map (FRFs computed with the default time-data settings of
``insitu frf``; a bad run is reported and left out).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from app.cli.common import (
    VERB_HELP,
    UserError,
    check_output,
    check_range,
    fit_progress,
    write_output,
)


def add_parser(sub: Any) -> None:
    p = sub.add_parser("report", help=VERB_HELP["report"],
                       description=__doc__)
    p.add_argument("file", type=Path,
                   help="run file or FRF file (.h5), UFF file of FRFs or time records (.uff), "
                        "TDMS or MDF file of time records (.tdms, .mf4)")
    p.add_argument("--channels", type=Path, metavar="MAP.toml",
                   help="TDMS or MDF file: its channel map (docs/time-files.md); default: "
                        "FILE.map.toml beside it")
    p.add_argument("--out", type=Path, help="HTML file (default: FILE with .html)")
    p.add_argument("--physical", action="store_true",
                   help="constrain the inertia to physically consistent values")
    p.add_argument("--mounts", type=Path, metavar="TOML",
                   help="mounts file: individual mount rates and the torque roll axis")
    p.add_argument("--excitation-hz", type=float, metavar="F",
                   help="excitation frequency for the modes' isolation margins, Hz")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from app.cli.frf import show_reports
    from app.pipeline import OpenError
    from app.pipeline.settings import MAX_FMAX
    from app.report.analysis import analyse
    from app.report.sources import open_source, plan_prediction
    from processing.identify import IdentifyOptions

    check_range("--excitation-hz", args.excitation_hz, 0, MAX_FMAX, "Hz", above=True)
    if not args.file.is_file():
        raise UserError(f"no such file {args.file}")
    out = args.out or args.file.with_suffix(".html")
    check_output(out, inputs=(args.file,))  # the default too: beside the input
    from app.io.mounts import load_mounts
    from processing.mounts import check_mounts

    mounts = load_mounts(args.mounts) if args.mounts is not None else None
    if mounts is not None:
        check_mounts(mounts.mounts)
    try:
        m, fmt = open_source(args.file, args.channels)
    except OpenError as err:
        show_reports(args, err.reports)
        raise
    prediction = plan_prediction(args.file, fmt)
    show_reports(args, m.provenance.reports)
    with fit_progress() as progress:
        a = analyse(m, IdentifyOptions(physical=args.physical), args.file.name, progress)
    # figures are drawn by Qt off screen: no display needed
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6 import QtWidgets

    from app.report.html import build_report

    _qt_app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(["insitu-report"])
    html = build_report(a, f"In situ identification report: {args.file.name}", mounts,
                        args.excitation_hz, prediction)
    write_output(out, html)
    if a.result is None:  # the report still shows the FRFs and checks
        raise UserError(f"{args.file.name}: identification failed: {a.error}; the report of "
                        f"the FRFs and checks is in {out}")
    print(a.summary())
    print(f"report written to {out}")
    return 0
