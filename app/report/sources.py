"""Open the FRFs a report or the GUI shows: any file the command line reads.

A thin view over :func:`app.pipeline.open_frfs`: the GUI and ``insitu report`` accept the
suffixes of :data:`app.pipeline.SUFFIXES`, open a finished run's stored FRFs, and compute
FRFs from time records with the command line's default settings.
"""

from __future__ import annotations

from pathlib import Path

from app.pipeline import SUFFIXES, RunReport, Settings, detect_format, open_frfs
from processing.data import FRFSet, InputError

__all__ = ["SETTINGS", "SUFFIXES", "load_frfs", "open_source"]

#: how the views open a file: a finished run's stored FRFs, time data as ``insitu frf`` does
SETTINGS = Settings(stored=True)


def open_source(path: str | Path) -> tuple[FRFSet, list[RunReport], str]:
    """The FRFs of ``path``, the pipeline's reports, and the file's format
    (:data:`app.pipeline.FORMATS`).

    Raises
    ------
    InputError
        Unknown file type, or a file that holds no usable FRFs (message names the file).
    """
    p = Path(path)
    if p.suffix.lower() not in SUFFIXES:
        raise InputError(
            f"{p.name}: unknown file type {p.suffix!r}: open a UFF file of FRFs or time "
            f"records (.uff, .unv), a run file or an FRF file ({', '.join(SUFFIXES[2:])})"
        )
    fmt = detect_format(p)
    frf, reports = open_frfs(p, SETTINGS, fmt=fmt)
    return frf, reports, fmt


def load_frfs(path: str | Path) -> FRFSet:
    """The FRF set of ``path`` (see :func:`open_source`)."""
    return open_source(path)[0]
