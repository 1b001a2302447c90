"""MDF files (ASAM MDF 4, as test-cell loggers write them): time records read through a
channel map, and written.

asammdf reads and writes them; it is an extra (``pip install 'insitu[mdf]'``), imported when
an MDF file is read or written, never when the command line starts. An MDF file holds
channel groups, each with a master (time) channel its other channels are sampled on; a
group's name here is its acquisition name, else its comment, else its number from 0.
asammdf reads a file it is given open (its own opening of a damaged file leaves an object
whose clean-up fails), held open until the reader goes; its values are the physical ones
(the channels' conversions applied).
"""

from __future__ import annotations

import logging
import os
import traceback
import weakref
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from app.io._optional import optional_package
from app.io.time_channels import GroupedFile, RawSignal, snapped_rate
from app.io.uff_time import TimeRun
from processing.data import InputError

__all__ = ["MAGIC", "MdfRaw", "write_time_mdf"]

log = logging.getLogger(__name__)

#: the first bytes of every MDF file (versions 3 and 4)
MAGIC = b"MDF     "


def asammdf() -> ModuleType:
    """asammdf, or one line naming the extra to install."""
    return optional_package("asammdf", "reading or writing MDF files", "asammdf", "mdf")


def _unreadable(path: Path, err: BaseException) -> InputError:
    first = str(err).splitlines()[0] if str(err) else type(err).__name__
    return InputError(f"cannot read MDF file {path.name} ({first}): it is truncated or "
                      "damaged; copy or export the file again")


class MdfRaw(GroupedFile):
    """An MDF file's channel groups and channels (:class:`app.io.time_channels.RawFile`)."""

    def __init__(self, path: Path) -> None:
        if not path.is_file():
            raise InputError(f"MDF file {path} not found: check the path")
        with path.open("rb") as fh:
            head = fh.read(len(MAGIC))
        if head != MAGIC:
            raise InputError(f"{path.name} is not an MDF file (it does not start with "
                             "'MDF     '): give an MDF file (.mf4) written by a logger or "
                             "insitu export")
        super().__init__(path)
        opened = _Opened(asammdf(), path)
        self._mdf = opened.__enter__()
        weakref.finalize(self, opened.__exit__)
        for i, g in enumerate(self._mdf.groups):
            cg = g.channel_group
            name = (getattr(cg, "acq_name", "") or getattr(cg, "comment", "") or str(i))
            self._groups.append((str(name), tuple(ch.name for ch in g.channels)))

    def read(self, group: int, names: Sequence[str]) -> list[RawSignal]:
        where = f"{self._path.name}: group {self._groups[group][0]!r}"
        out = []
        for name in names:
            try:
                sig = self._mdf.get(name, group=group)
                values, t = np.asarray(sig.samples), np.asarray(sig.timestamps, dtype=float)
            except Exception as err:  # asammdf raises many kinds on a damaged file
                raise _unreadable(self._path, err) from err
            if values.dtype.kind not in "iuf":
                raise InputError(f"{where}: channel {name!r} holds {values.dtype} values, "
                                 "not numbers: map a measured channel")
            out.append(RawSignal(values.astype(np.float64, copy=False),
                                 _rate(t, f"{where}: channel {name!r}"), str(sig.unit or "")))
        return out


class _Opened:
    """The file open and asammdf's MDF on it (``__enter__``), both closed by ``__exit__``."""

    def __init__(self, lib: ModuleType, path: Path) -> None:
        self.lib, self.path = lib, path

    def __enter__(self) -> Any:
        self.fh = self.path.open("rb")
        try:
            self.mdf = self.lib.MDF(self.fh)
        except Exception as err:  # asammdf raises many kinds on a damaged file
            self.fh.close()
            _half_built(err)
            raise _unreadable(self.path, err) from err
        return self.mdf

    def __exit__(self, *exc: object) -> None:
        try:
            self.mdf.close()
        finally:
            self.fh.close()


def _half_built(err: BaseException) -> None:
    """Closes the temporary file of each MDF object a failed opening left half built and
    marks it closed: its ``__del__`` would close it and fail on the blocks never read (an
    exception Python can only print, at some later moment)."""
    for frame, _ in traceback.walk_tb(err.__traceback__):
        obj = frame.f_locals.get("self")
        if obj is not None and type(obj).__module__.startswith("asammdf.blocks.mdf_v"):
            tmp = getattr(obj, "_tempfile", None)
            if tmp is not None:
                tmp.close()
            obj._closed = True


def _rate(t: Any, where: str) -> float:
    """Sample rate (Hz) of evenly spaced timestamps (s)."""
    if t.size < 2:
        raise InputError(f"{where}: fewer than 2 samples: record the run longer")
    step = np.diff(t)
    if not (step[0] > 0 and np.allclose(step, step[0], rtol=1e-6, atol=0.0)):
        raise InputError(f"{where}: samples are not evenly spaced in time: resample the record")
    return snapped_rate(float((t.size - 1) / (t[-1] - t[0])))


def write_time_mdf(path: Path, runs: Sequence[TimeRun], groups: Sequence[str],
                   channels: Sequence[str], comments: Sequence[str] | None = None) -> None:
    """Write ``runs`` to an MDF 4.10 file (replaced whole), one channel group a run whose
    acquisition name is ``groups[k]`` (``comments[k]`` its comment), its channels named
    ``channels`` (force first), float64 samples in SI units (N, m/s^2) on a master channel
    of timestamps ``i / fs`` (s)."""
    from app.io.replace import replacing

    lib = asammdf()
    notes = comments or list(groups)
    mdf = lib.MDF(version="4.10")
    try:
        for run, gname, note in zip(runs, groups, notes, strict=True):
            t = np.arange(run.n_samples) / run.fs
            rows = [run.force, *run.responses]
            mdf.append([lib.Signal(np.ascontiguousarray(row), t, name=name,
                                   unit="N" if k == 0 else "m/s^2")
                        for k, (name, row) in enumerate(zip(channels, rows, strict=True))],
                       acq_name=gname, comment=note)
        with replacing(path) as tmp:
            saved = mdf.save(tmp.with_suffix(".mf4"), overwrite=True)
            os.replace(saved, tmp)
    finally:
        mdf.close()
    log.info("wrote %d runs to %s", len(runs), path)
