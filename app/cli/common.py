"""Shared pieces of the command-line verbs."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

#: verb -> its one line of help: ``insitu --help`` lists them without importing the verbs
VERB_HELP = {
    'identify': 'identify inertia parameters and K, C from a UFF file',
    'simulate': "write a simulated bench's FRFs as UFF",
    'demo': 'run the main job on the built-in simulated bench',
    'frf': 'FRFs and coherence from UFF time records or a run file',
    'mock-bench': 'run a simulated bench and print its station file',
    'acquire': 'acquire a test plan into an HDF5 run file',
    'replay': 'recompute FRFs and identification from a run file',
    'repair': 'make a crashed run file readable by any HDF5 tool',
    'gui': 'start the desktop application',
    'report': 'write the HTML report of a run, an FRF file or a UFF file',
    'batch': 'identify many files on a Dask cluster, one table',
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
