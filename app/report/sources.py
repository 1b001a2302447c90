"""Open the measurement a report or the GUI shows: any file the command line reads.

A thin view over :func:`app.pipeline.load`: the GUI and ``insitu report`` accept the
suffixes of :data:`app.pipeline.SUFFIXES` and load every file with the command line's
default settings, as ``insitu identify`` does (a run file's records processed again).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from app.pipeline import RUN_FILE, SUFFIXES, Settings, detect_format, load
from processing.data import FRFSet, InputError
from processing.measurement import Measurement

__all__ = ["SETTINGS", "SUFFIXES", "load_frfs", "open_source", "plan_prediction"]

#: how the views open a file: as ``insitu identify`` does, with its default settings
SETTINGS = Settings()


def open_source(path: str | Path, channel_map: Path | None = None) -> tuple[Measurement, str]:
    """The measurement of ``path`` (its reports in its provenance) and the file's format
    (:data:`app.pipeline.FORMATS`); ``channel_map``: a TDMS or MDF file's channel map (None:
    the one beside the file, ``docs/time-files.md``).

    Raises
    ------
    InputError
        Unknown file type, or a file that holds no usable FRFs (message names the file).
    """
    p = Path(path)
    if p.suffix.lower() not in SUFFIXES:
        raise InputError(
            f"{p.name}: unknown file type {p.suffix!r}: open a UFF file of FRFs or time "
            f"records (.uff, .unv), a run file or an FRF file (.h5, .hdf5), or a TDMS or MDF "
            "file of time records (.tdms, .mf4, .mdf)"
        )
    fmt = detect_format(p)
    settings = SETTINGS if channel_map is None else dataclasses.replace(
        SETTINGS, channel_map=channel_map)
    return load(p, settings, fmt=fmt), fmt


def load_frfs(path: str | Path) -> FRFSet:
    """The FRF set of ``path`` (see :func:`open_source`)."""
    return open_source(path)[0].frf


def plan_prediction(path: str | Path, fmt: str | None = None) -> dict[str, Any] | None:
    """The ``[prediction]`` table of a run file's plan (``insitu plan``'s predicted std,
    docs/planning.md), or None: no prediction, or ``path`` is no run file (``fmt``: its
    format when known). Raises the run file's or the plan's one-line error when damaged."""
    p = Path(path)
    if (fmt or detect_format(p)) != RUN_FILE:
        return None
    from app.acquire.plan import parse_plan  # a run file's: not for an FRF file (start-up)
    from app.io.runfile import read_run  # HDF5 loads for HDF5 files only

    run = read_run(p, with_data=False)
    return parse_plan(run.plan_data, f"{p}:/plan").prediction
