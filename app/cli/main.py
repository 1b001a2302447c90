"""The ``insitu`` command line: one module per verb under ``app.cli``.

Each verb module defines ``add_parser(subparsers)`` and ``run(args) -> int``.
Bad input raises :class:`app.cli.common.UserError` (or a ``ValueError`` from
``processing``); ``main`` turns it into one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import logging.handlers
import os
import sys
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any, NoReturn

from app.cli.common import VERB_HELP, UserError, in_flags

#: terminal width (characters) assumed when the output is a file or a pipe
PIPE_COLUMNS = 200

#: the verbs (modules under app.cli), in the order ``insitu --help`` lists them
VERBS = tuple(VERB_HELP)


class _Parser(argparse.ArgumentParser):
    """A usage mistake is one line naming the option and where the help is, exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(verbs: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The command line's parser: every verb's options, or only those of ``verbs`` (the
    others listed with their line of help: their modules, and what they import, are not
    loaded)."""
    parser = _Parser(
        prog="insitu",
        description="In situ identification of inertia parameters and mount stiffness from FRFs.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="verb", required=True, metavar="VERB")
    for verb in VERBS:
        if verbs is None or verb in verbs:
            importlib.import_module(f"app.cli.{verb.replace('-', '_')}").add_parser(sub)
        else:
            sub.add_parser(verb, help=VERB_HELP[verb])
    return parser


def named_verb(argv: Sequence[str]) -> set[str]:
    """The verb a command line names (its first word after ``-v``), as a set; empty when
    it names none (``insitu --help``, a typo: the parser then says so)."""
    for word in argv:
        if word in ("-v", "--verbose"):
            continue
        return {word} & set(VERBS)
    return set()


class _OneLine(logging.Formatter):
    """The terminal's form of a log record: its first line, no traceback."""

    def format(self, record: logging.LogRecord) -> str:
        text = f"{record.levelname} {record.name}: {record.getMessage()}"
        first = text.splitlines()[0] if text else text
        # some libraries (python-can's socketcand client) put a traceback in the message
        return first.split("Traceback (most recent call last)")[0].rstrip()


class _Stderr(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record comes (a test may swap it)."""

    @property
    def stream(self) -> Any:
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:
        pass


class _Tracebacks(logging.Filter):
    """Keeps records that carry a traceback off the terminal (they go to the log file)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.exc_info is None


class _Errors(logging.Handler):
    """Counts the errors logged during the command (the log file then holds their details)."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.count += 1


def log_path() -> Path:
    """The log file: ``$INSITU_LOG``, else ``insitu.log`` in the user's state folder."""
    if "INSITU_LOG" in os.environ:
        return Path(os.environ["INSITU_LOG"])
    state = Path(os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state")
    return state / "insitu" / "insitu.log"


def _configure_logging(verbose: bool) -> tuple[_Errors, Path | None]:
    """Terminal: warnings, one line each, no traceback. Log file: everything, in full."""
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, "_insitu", False):
            root.removeHandler(h)
            h.close()
    term = _Stderr()
    term.setLevel(logging.DEBUG if verbose else logging.WARNING)
    term.setFormatter(_OneLine())
    term.addFilter(_Tracebacks())
    errors = _Errors()
    handlers: list[logging.Handler] = [term, errors]
    path: Path | None = log_path()
    try:
        assert path is not None
        path.parent.mkdir(parents=True, exist_ok=True)
        file = logging.handlers.RotatingFileHandler(path, maxBytes=5_000_000, backupCount=2,
                                                    encoding="utf-8")
        file.setLevel(logging.DEBUG if verbose else logging.INFO)
        file.setFormatter(logging.Formatter("%(asctime)s %(process)d %(levelname)s "
                                            "%(name)s: %(message)s"))
        handlers.append(file)
    except OSError:
        path = None  # no writable state folder: the terminal still gets every line
    for h in handlers:
        h._insitu = True  # type: ignore[attr-defined]
        root.addHandler(h)
    root.setLevel(logging.DEBUG if verbose else logging.INFO)
    return errors, path


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(named_verb(argv)).parse_args(argv)
    if not sys.stdout.isatty():
        # rich sizes tables to COLUMNS, 80 when output goes to a file or a pipe: a log of
        # `insitu demo > run.log` would cut the K and C cells
        os.environ.setdefault("COLUMNS", str(PIPE_COLUMNS))
    errors, path = _configure_logging(args.verbose)
    try:
        return int(args.run(args) or 0)
    except (UserError, ValueError, OSError) as err:
        details = f" (details in {path})" if errors.count and path is not None else ""
        print(f"insitu {args.verb}: error: {in_flags(err)}{details}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"insitu {args.verb}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # a bug of ours: one line here, the traceback in the log file
        logging.getLogger(__name__).exception("insitu %s failed", args.verb)
        where = f"details in {path}" if path is not None else "run again with -v"
        first = str(err).splitlines()[0] if str(err) else ""
        print(f"insitu {args.verb}: internal error: {type(err).__name__}: {first} ({where}; "
              "please report it)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
