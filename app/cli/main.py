"""The ``insitu`` command line: one module per verb under ``app.cli``.

Each verb module defines ``add_parser(subparsers)`` and ``run(args) -> int``.
Bad input raises :class:`app.cli.common.UserError` (or a ``ValueError`` from
``processing``); ``main`` turns it into one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from app.cli.common import UserError

#: verb -> module under app.cli
VERBS = ("identify", "simulate", "demo", "frf", "mock-bench", "acquire", "replay", "repair",
         "gui", "report")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="insitu",
        description="In situ identification of inertia parameters and mount stiffness from FRFs.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="verb", required=True, metavar="VERB")
    for verb in VERBS:
        module = importlib.import_module(f"app.cli.{verb.replace('-', '_')}")
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.run(args) or 0)
    except (UserError, ValueError, OSError) as err:
        print(f"insitu {args.verb}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"insitu {args.verb}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
