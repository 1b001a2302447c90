"""Shared pieces of the command-line verbs."""

from __future__ import annotations

import contextlib
import errno
import math
import os
import secrets
import stat
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

#: verb -> its one line of help: ``insitu --help`` lists them without importing the verbs
VERB_HELP = {
    'identify': 'identify inertia parameters and K, C from a file',
    'simulate': "write a simulated bench's FRFs as UFF",
    'demo': 'run the main job on the built-in simulated bench',
    'frf': 'FRFs and coherence from time records or a run file',
    'mock-bench': 'run a simulated bench and print its station file',
    'acquire': 'acquire a test plan into an HDF5 run file',
    'replay': 'recompute FRFs and identification from a run file',
    'repair': 'make a crashed run file readable by any HDF5 tool',
    'export': "a run's records as TDMS, MDF 4 or UFF time records",
    'gui': 'start the desktop application',
    'report': 'write the HTML report of a run, an FRF file or a UFF file',
    'batch': 'identify many files on a Dask cluster, one table',
    'plan': 'choose sensors and hit points before a test, predict its uncertainty',
}

#: the command line's name of each pipeline setting (:class:`app.pipeline.Settings`,
#: :class:`app.pipeline.settings.TestUncertaintySettings`): their errors name the setting,
#: the command line says the flag
FLAGS = {
    "nperseg": "--nperseg", "overlap": "--overlap", "window": "--window",
    "averages": "--averages", "level": "--level", "record": "--record",
    "pretrigger": "--pretrigger", "exp_tau": "--exp-tau", "ring": "--force-ring",
    "tail": "--tail", "carryover": "--carryover", "coherence": "--coherence", "fmax": "--fmax",
    "location_uncertainty": "--location-uncertainty", "angle_uncertainty": "--angle-uncertainty",
    "gain_uncertainty": "--gain-uncertainty", "draws": "--draws",
}


class UserError(Exception):
    """A problem the user can fix; printed as one line, exit status 2."""


# --- numbers checked before any file is read ------------------------------------------------


def check_range(flag: str, value: float | None, lo: float, hi: float, unit: str, *,
                above: bool = False) -> None:
    """Refuses (one line naming the allowed range) a number outside ``lo`` (above it when
    ``above``) to ``hi``, or not finite; None (not given) passes."""
    if value is None:
        return
    low_ok = value > lo if above else value >= lo
    if not (math.isfinite(value) and low_ok and value <= hi):
        first = f"above {lo:.10g} and at most" if above else f"from {lo:.10g} to"
        raise UserError(f"{flag} must be {first} {hi:.10g}{' ' + unit if unit else ''}, got "
                        f"{value:.10g}")


# --- output files checked before any work, written without losing the old one ----------------


def check_output(path: Path, option: str = "--out", *, inputs: Sequence[Path] = ()) -> None:
    """Refuses (one line naming ``path`` and what to do) an output file that cannot be
    written: a folder or a special file (a device, a pipe, a /proc entry), a missing or
    read-only folder (a file is created and removed there to know), a read-only file, or
    one of the ``inputs``. Called before any file is read or anything is computed."""
    where = f"{option} {path}"
    if path.is_dir():
        raise UserError(f"{where} is a folder: give a file name in it")
    if any(path.exists() and i.exists() and path.samefile(i) for i in inputs):
        raise UserError(f"{where} is the input file: it would be replaced; choose another "
                        f"{option}")
    if path.exists() and not stat.S_ISREG(path.stat().st_mode):
        raise UserError(f"{where} is a device or special file, not a regular file: give a "
                        "file in a folder of yours")
    check_folder(path.parent, option, where)
    if path.exists():
        try:
            os.close(os.open(path, os.O_WRONLY))  # no truncation: the file stays as it is
        except OSError as err:
            raise UserError(f"{where} cannot be replaced ({err.strerror}): choose another "
                            f"{option}") from err


def check_folder(folder: Path, option: str, where: str) -> None:
    """Refuses a missing folder, a file, or a folder where no file can be created (tried:
    a file created and removed)."""
    folder = folder if str(folder) else Path(".")
    if not folder.exists():
        raise UserError(f"{where}: folder {folder} does not exist: create it or choose "
                        f"another {option}")
    if not folder.is_dir():
        raise UserError(f"{where}: {folder} is not a folder: choose another {option}")
    probe = folder / f".insitu-probe-{secrets.token_hex(4)}"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as err:
        why = "" if err.errno == errno.ENOENT else f" ({err.strerror})"
        raise UserError(f"{where}: folder {folder} is not writable{why}: choose another "
                        f"{option}") from err
    with contextlib.suppress(OSError):
        probe.unlink()


def reason(err: OSError) -> str:
    """Why a write failed, in words, without the temporary file's name an OSError may carry:
    ``cannot write it (No space left on device)``."""
    return (f"cannot write it ({os.strerror(err.errno)})" if err.errno
            else f"cannot write it ({str(err).splitlines()[0]})")


def write_output(path: Path, text: str, option: str = "--out") -> None:
    """``text`` (UTF-8) written to a temporary file beside ``path`` and moved onto it: an
    old file stays whole if the write fails; a failure is one line naming ``path``."""
    from app.io.replace import replacing

    try:
        with replacing(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except OSError as err:
        raise UserError(f"{option} {path}: {reason(err)}: free some space or choose another "
                        f"{option}") from err


def in_flags(err: BaseException) -> str:
    """The one line of ``err`` in the command line's words: a setting's error (or one that
    stems from it) names the flag."""
    from app.pipeline.settings import SettingError

    cause = err if isinstance(err, SettingError) else err.__cause__
    return cause.worded(FLAGS) if isinstance(cause, SettingError) else str(err)


@contextlib.contextmanager
def fit_progress() -> Iterator[Callable[[int, int], None] | None]:
    """A ``progress`` for :func:`processing.identify.fit`: while the bootstrap's resamples
    are solved, a rich progress bar on stderr, gone when the block ends (None when stderr
    is not a terminal: a pipe or a log gets no line of it)."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TaskID,
        TextColumn,
        TimeElapsedColumn,
    )

    err = Console(stderr=True)
    if not err.is_terminal:
        yield None
        return
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=err, transient=True) as bars:
        task: list[TaskID] = []

        def update(done: int, total: int) -> None:
            if not task:
                task.append(bars.add_task("bootstrap resamples", total=total))
            bars.update(task[0], completed=done, total=total)

        yield update
