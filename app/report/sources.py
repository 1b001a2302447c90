"""Open the FRFs a report or the GUI replays: a UFF FRF file or a recorded run file."""

from __future__ import annotations

from pathlib import Path

from app.io.uff import read_frf_uff
from processing.data import FRFSet, InputError

__all__ = ["FRF_SUFFIXES", "RUN_SUFFIXES", "load_frfs"]

FRF_SUFFIXES = (".uff", ".unv")
RUN_SUFFIXES = (".h5", ".hdf5")


def load_frfs(path: str | Path) -> FRFSet:
    """The FRF set stored in ``path`` (UFF FRF file or HDF5 run file).

    Raises
    ------
    InputError
        Unknown file type, or a file that holds no usable FRFs (message names the file).
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in FRF_SUFFIXES:
        return read_frf_uff(p)
    if suffix in RUN_SUFFIXES:
        from app.report.runs import read_run_frfs

        return read_run_frfs(p)
    raise InputError(
        f"{p.name}: unknown file type {p.suffix!r}: open a UFF FRF file "
        f"({', '.join(FRF_SUFFIXES)}) or a run file ({', '.join(RUN_SUFFIXES)})"
    )
