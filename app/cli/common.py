"""Shared pieces of the command-line verbs."""

from __future__ import annotations

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
