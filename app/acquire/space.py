"""Will the run fit on its disk? The plan's run-file size against the free space, up front.

:func:`check_disk_space` is called before any device opens and before the run file is
created (by ``insitu acquire`` and by every procedure's start): a run that cannot fit is
refused in one line naming the space it needs and the space there is, instead of
stopping on a full disk half way. The size is :func:`expected_bytes`: the records still
to acquire (a quarter more, for the rejected hits or blocks that are replaced), each of
``rows x samples`` float64 values, the FRFs and coherences written when the run
finishes, the writer's reserve (:data:`app.io.runfile.RESERVE_BYTES`) and the HDF5
structures. A disk that fills during the run anyway (another program writing to it)
ends the run cleanly: see :class:`app.io.runfile.DiskFullError`.

Example
-------
>>> check_disk_space(proc)  # doctest: +SKIP
Traceback (most recent call last):
DiskSpaceError: run.h5: the run needs about 6.0 MB (...) but /mnt/usb has 1.2 MB free: ...
"""

from __future__ import annotations

import math
import shutil
from typing import TYPE_CHECKING

import numpy as np

from app.acquire.plan import PlanError
from app.io.runfile import RESERVE_BYTES, read_run

if TYPE_CHECKING:
    from app.acquire.recording import RecordingProcedure

__all__ = ["MARGIN", "OVERHEAD", "DiskSpaceError", "check_disk_space", "expected_bytes"]

#: extra records counted, as a fraction of the plan's: rejected hits (or blocks) replaced
MARGIN = 0.25
#: bytes counted for HDF5's structures, the settings, notes and the per-record columns' chunks
OVERHEAD = 1 << 20
#: bytes of one record's verdict columns (point, time, peak force, reason...)
_COLUMN_BYTES = 300
_MB = 1e6


class DiskSpaceError(PlanError):
    """The run file's disk has less free space than the run needs (one line)."""


def records_left(proc: RecordingProcedure) -> int:
    """Records the run still has to acquire: every point's, or what a resumed run lacks."""
    need = proc.records_needed()
    n_drives = len(proc.plan.drives)
    if not proc.resume_file:
        return n_drives * need
    rec = read_run(proc.path, with_data=False).records
    have = np.bincount(rec.point[rec.accepted], minlength=n_drives)[:n_drives]
    return int(np.maximum(need - have, 0).sum())


def expected_bytes(proc: RecordingProcedure) -> tuple[int, int]:
    """Bytes the run will add to its disk, and the records it still has to acquire (see the
    module docstring)."""
    left = records_left(proc)
    counted = math.ceil(left * (1 + MARGIN))
    record = 8 * proc.record_values() + _COLUMN_BYTES
    n_force = proc.plan.n_references
    frf = (len(proc.rows) - n_force) * len(proc.plan.excitations) * proc.frf_lines() * (16 + 8)
    return counted * record + frf + RESERVE_BYTES + OVERHEAD, left


def check_disk_space(proc: RecordingProcedure) -> None:
    """Refuse a run whose file cannot fit on its disk (:class:`DiskSpaceError`, one line)."""
    folder = proc.path.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return  # no folder (refused elsewhere) or a file system that cannot tell
    need, left = expected_bytes(proc)
    if need <= free:
        return
    raise DiskSpaceError(
        f"{proc.path}: the run needs about {need / _MB:.1f} MB ({left} {proc.record_word}s and "
        f"{MARGIN:.0%} more for rejected ones, {8 * proc.record_values() / _MB:.2f} MB each; "
        f"the FRFs; {(RESERVE_BYTES + OVERHEAD) / _MB:.1f} MB for the file's structures) but "
        f"{folder} has {free / _MB:.1f} MB free: free space there or write the run to another "
        "disk")
