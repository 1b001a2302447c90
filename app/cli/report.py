"""``insitu report RUN.h5|FRF.uff [--out report.html]``: the test report, without a GUI."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from app.cli.common import UserError


def add_parser(sub: Any) -> None:
    p = sub.add_parser("report", help="write the HTML report of a run or a UFF FRF file",
                       description=__doc__)
    p.add_argument("file", type=Path, help="run file (.h5) or UFF FRF file (.uff)")
    p.add_argument("--out", type=Path, help="HTML file (default: FILE with .html)")
    p.add_argument("--physical", action="store_true",
                   help="constrain the inertia to physically consistent values")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from app.report.analysis import analyse
    from app.report.sources import load_frfs
    from processing.identify import IdentifyOptions

    if not args.file.is_file():
        raise UserError(f"no such file {args.file}")
    out = args.out or args.file.with_suffix(".html")
    a = analyse(load_frfs(args.file), IdentifyOptions(physical=args.physical), args.file.name)
    # figures are drawn by Qt off screen: no display needed
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6 import QtWidgets

    from app.report.html import build_report

    _qt_app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(["insitu-report"])
    html = build_report(a, f"In situ identification report: {args.file.name}")
    out.write_text(html, encoding="utf-8")
    print(a.summary())
    print(f"report written to {out}")
    return 0 if a.result is not None else 1
