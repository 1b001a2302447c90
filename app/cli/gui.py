"""``insitu gui [--station FILE]``: the operator's desktop application."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from app.cli.common import VERB_HELP, UserError


def add_parser(sub: Any) -> None:
    p = sub.add_parser("gui", help=VERB_HELP["gui"], description=__doc__)
    p.add_argument("--station", type=Path,
                   help="station file (default: the last one used, or the built-in mock bench)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.station is not None and not args.station.is_file():
        raise UserError(f"no station file {args.station}")
    from app.gui import run_gui

    return run_gui(args.station)
