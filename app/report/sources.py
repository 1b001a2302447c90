"""Open the measurement a report or the GUI shows: any file the command line reads.

A thin view over :func:`app.pipeline.load`: the GUI and ``insitu report`` accept the
suffixes of :data:`app.pipeline.SUFFIXES` and load every file with the command line's
default settings, as ``insitu identify`` does (a run file's records processed again).
"""

from __future__ import annotations

from pathlib import Path

from app.pipeline import SUFFIXES, Settings, detect_format, load
from processing.data import FRFSet, InputError
from processing.measurement import Measurement

__all__ = ["SETTINGS", "SUFFIXES", "load_frfs", "open_source"]

#: how the views open a file: as ``insitu identify`` does, with its default settings
SETTINGS = Settings()


def open_source(path: str | Path) -> tuple[Measurement, str]:
    """The measurement of ``path`` (its reports in its provenance) and the file's format
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
    return load(p, SETTINGS, fmt=fmt), fmt


def load_frfs(path: str | Path) -> FRFSet:
    """The FRF set of ``path`` (see :func:`open_source`)."""
    return open_source(path)[0].frf
