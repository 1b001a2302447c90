"""TDMS files (National Instruments): time records read through a channel map, and written.

npTDMS reads and writes them; it is an extra (``pip install 'insitu[tdms]'``), imported
when a TDMS file is read or written, never when the command line starts. A TDMS file holds
groups of channels; a waveform channel's sample interval is its ``wf_increment`` property
(s) and its unit NI's ``unit_string``. npTDMS reads a file cut short without a word (it
logs a warning and returns the samples it found), so the segments' lead-ins are walked
first (:func:`check_tdms`) and a truncated file is refused.
"""

from __future__ import annotations

import logging
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

__all__ = ["LEAD_IN", "TdmsRaw", "check_tdms", "write_time_tdms"]

log = logging.getLogger(__name__)

#: the first bytes of every TDMS segment
LEAD_IN = b"TDSm"
_LEAD_IN_BYTES = 28
_BIG_ENDIAN = 1 << 6  # kTocBigEndian in the lead-in's table of contents
_INCOMPLETE = 0xFFFF_FFFF_FFFF_FFFF  # next-segment offset of a segment never finished


def nptdms() -> ModuleType:
    """npTDMS, or one line naming the extra to install."""
    return optional_package("nptdms", "reading or writing TDMS files", "npTDMS", "tdms")


def check_tdms(path: Path) -> None:
    """Refuses (one line) a missing file, a file that is not TDMS (no ``TDSm`` lead-in) or
    one cut short (a segment reaching past the end, or never finished by its writer)."""
    if not path.is_file():
        raise InputError(f"TDMS file {path} not found: check the path")
    size = path.stat().st_size
    pos = 0
    with path.open("rb") as f:
        while pos < size:
            f.seek(pos)
            lead = f.read(_LEAD_IN_BYTES)
            if lead[:4] != LEAD_IN:
                if pos == 0:
                    raise InputError(f"{path.name} is not a TDMS file (it does not start with "
                                     "'TDSm'): give a TDMS file written by NI software or "
                                     "insitu export")
                raise InputError(f"{path.name} is damaged: no segment starts at byte {pos}: "
                                 "copy or export the file again")
            if len(lead) < _LEAD_IN_BYTES:
                break
            big = int.from_bytes(lead[4:8], "little") & _BIG_ENDIAN
            step = int.from_bytes(lead[12:20], "big" if big else "little")
            if step == _INCOMPLETE:
                pos = -1
                break
            pos += _LEAD_IN_BYTES + step
    if pos != size:
        raise InputError(f"{path.name} is truncated: its last segment "
                         + ("was never finished by its writer" if pos < 0 else
                            f"ends at byte {pos}, the file at {size}")
                         + ": copy or export the file again")


class TdmsRaw(GroupedFile):
    """A TDMS file's groups and channels (:class:`app.io.time_channels.RawFile`), the file
    held open (its metadata read once, the samples when asked for) until the object goes."""

    def __init__(self, path: Path) -> None:
        check_tdms(path)
        super().__init__(path)
        lib = nptdms()
        try:
            self._file = lib.TdmsFile.open(str(path))
        except (ValueError, KeyError, OSError, EOFError) as err:
            raise InputError(f"cannot read TDMS file {path.name} ({err}): check that it is a "
                             "complete TDMS file") from err
        weakref.finalize(self, self._file.close)
        self._groups = [(g.name, tuple(c.name for c in g.channels()))
                        for g in self._file.groups()]

    def read(self, group: int, names: Sequence[str]) -> list[RawSignal]:
        gname = self._groups[group][0]
        out = []
        try:
            for name in names:
                ch = self._file[gname][name]
                out.append(_signal(ch, ch[:], f"{self._path.name}: group {gname!r}"))
        except (ValueError, KeyError, OSError, EOFError) as err:
            raise InputError(f"cannot read TDMS file {self._path.name} ({err}): check that it "
                             "is a complete TDMS file") from err
        return out


def _signal(ch: Any, data: Any, where: str) -> RawSignal:
    """A TDMS channel's samples, rate (from ``wf_increment``) and unit (``unit_string``)."""
    values = np.asarray(data)
    if values.dtype.kind not in "iuf":
        raise InputError(f"{where}: channel {ch.name!r} holds {values.dtype} values, not "
                         "numbers: map a waveform channel")
    inc = ch.properties.get("wf_increment")
    if inc is None:
        raise InputError(f"{where}: channel {ch.name!r} has no wf_increment property (its "
                         "sample interval): store it as a waveform")
    inc = float(inc)
    fs = snapped_rate(1.0 / inc) if inc > 0 else float("nan")
    return RawSignal(values.astype(np.float64, copy=False), fs,
                     str(ch.properties.get("unit_string", "")))


def write_time_tdms(path: Path, runs: Sequence[TimeRun], groups: Sequence[str],
                    channels: Sequence[str],
                    properties: Sequence[dict[str, Any]] | None = None) -> None:
    """Write ``runs`` to a TDMS file (replaced whole), one group a run named ``groups[k]``,
    its channels named ``channels`` (force first), float64 samples in SI units (``unit_string``
    N and m/s^2), ``wf_increment`` 1 / fs, ``wf_start_offset`` 0; ``properties`` are each
    group's properties."""
    from app.io.replace import replacing

    lib = nptdms()
    props = properties or [{} for _ in runs]
    with replacing(path) as tmp, lib.TdmsWriter(str(tmp)) as w:
        w.write_segment([lib.RootObject(properties={"name": path.stem,
                                                    "author": "insitu export"})])
        for run, gname, gprops in zip(runs, groups, props, strict=True):
            objects: list[Any] = [lib.GroupObject(gname, properties=gprops)]
            rows = [run.force, *run.responses]
            for k, (name, row) in enumerate(zip(channels, rows, strict=True)):
                objects.append(lib.ChannelObject(
                    gname, name, np.ascontiguousarray(row), properties={
                        "wf_increment": 1.0 / run.fs, "wf_start_offset": 0.0,
                        "wf_samples": int(row.size),
                        "unit_string": "N" if k == 0 else "m/s^2"}))
            w.write_segment(objects)
    log.info("wrote %d runs to %s", len(runs), path)
