"""Time records of other systems' files (TDMS, MDF) as runs, through a channel map.

A reader of such a file (:mod:`app.io.tdms`, :mod:`app.io.mdf`) gives its groups, their
channels and each channel's samples, sample rate and unit (:class:`RawFile`); the channel
map (:mod:`app.io.channel_map`) says which channel is what. :class:`MappedTimeFile` joins
the two into the runs a time UFF gives (:class:`app.io.uff_time.TimeRun`, one at a time,
:class:`app.io.uff_time.TimeSource`), so the pipeline computes FRFs from them by the same
code as from a time UFF.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from app.io.channel_map import ChannelMap, ExcitationSpec
from app.io.uff_time import TimeRun
from processing.data import Geometry, InputError

__all__ = ["GroupedFile", "MappedTimeFile", "RawFile", "RawSignal", "snapped_rate"]


@dataclass(frozen=True, eq=False)
class RawSignal:
    """One channel of a group as the file stores it: samples (float64, the file's unit after
    the file's own scaling), sample rate (Hz) and the file's unit text ("" if none)."""

    samples: NDArray[np.float64]
    fs: float
    unit: str


class RawFile(Protocol):
    """A file of named groups of named channels (a TDMS file, an MDF file)."""

    @property
    def path(self) -> Path: ...

    def index(self) -> list[tuple[str, tuple[str, ...]]]:
        """Each group's name and its channels' names, in the file's order."""
        ...

    def read(self, group: int, names: Sequence[str]) -> list[RawSignal]:
        """The channels ``names`` of group number ``group`` (from 0, :meth:`index`'s order)."""
        ...


class GroupedFile:
    """What a :class:`RawFile` reader keeps of its file once opened: its path and each
    group's name with its channels' names (``_groups``, filled by the reader)."""

    def __init__(self, path: Path) -> None:
        self._path = path
        self._groups: list[tuple[str, tuple[str, ...]]] = []

    @property
    def path(self) -> Path:
        return self._path

    def index(self) -> list[tuple[str, tuple[str, ...]]]:
        """Each group's name and its channels' names, in the file's order."""
        return list(self._groups)


def snapped_rate(fs: float) -> float:
    """A rate within 1e-9 of a whole number of Hz is that number (a sample interval stored
    as 1/fs, or timestamps i/fs, give the rate back to the last bits)."""
    r = round(fs)
    return float(r) if r > 0 and abs(fs - r) <= 1e-9 * fs else float(fs)


@dataclass(frozen=True)
class _Run:
    """One run of the file: its group (number, name), excitation, and its samples' span in
    the group (None: the whole group)."""

    group: int
    name: str
    excitation: ExcitationSpec
    span: tuple[int, int] | None = None


def _stretches(points: NDArray[np.float64]) -> list[tuple[int, int, int]]:
    """(point, start, stop) of each stretch of one nonzero value of a point channel."""
    p = np.rint(points).astype(np.int64)
    edges = np.flatnonzero(np.diff(p)) + 1
    starts = np.r_[0, edges]
    stops = np.r_[edges, p.size]
    return [(int(p[a]), int(a), int(b)) for a, b in zip(starts, stops, strict=True) if p[a] != 0]


class MappedTimeFile:
    """A TDMS or MDF file's runs as its channel map defines them (a
    :class:`app.io.uff_time.TimeSource`): load case ``k`` is the ``k``-th run in the file's
    order; each run is read when asked for (:meth:`read_run`), memory holds one group.

    Raises (at construction)
    ------------------------
    InputError
        A group or channel of the map missing from the file (naming what the file has), a
        run without an excitation in the map, no run at all.
    """

    def __init__(self, raw: RawFile, channel_map: ChannelMap) -> None:
        self.raw, self.map = raw, channel_map
        self._path = raw.path
        self._index = raw.index()
        self._runs = self._find_runs()
        self._cache: tuple[int, dict[str, RawSignal]] | None = None

    @property
    def path(self) -> Path:
        return self._path

    @property
    def load_cases(self) -> tuple[int, ...]:
        return tuple(range(1, len(self._runs) + 1))

    def geometry(self) -> Geometry:
        return self.map.geometry

    def run_name(self, load_case: int) -> str:
        """The group (and stretch) load case ``load_case`` is read from."""
        r = self._runs[load_case - 1]
        return f"group {r.name!r}" + ("" if r.span is None else
                                      f" samples {r.span[0]}-{r.span[1] - 1}")

    def _where(self) -> str:
        return f"{self.path.name} (channel map {self.map.path.name})"

    def _groups(self, needed: str) -> list[int]:
        """The groups read: the map's (each must exist), else those holding ``needed``."""
        names = [g for g, _ in self._index]
        if self.map.groups:
            missing = [g for g in self.map.groups if g not in names]
            if missing:
                raise InputError(f"{self._where()}: no group {missing[0]!r} in the file (it has "
                                 f"{_listed(names)}): fix [layout] groups")
            return [names.index(g) for g in self.map.groups]
        chosen = [i for i, (_, chans) in enumerate(self._index) if needed in chans]
        if not chosen:
            every = sorted({c for _, cs in self._index for c in cs})
            raise InputError(f"{self._where()}: no group holds channel {needed!r} (the file's "
                             f"channels: {_listed(every)}): fix the channel map's names")
        return chosen

    def _check_channels(self, groups: list[int]) -> None:
        """Every mapped channel in every group read (an unknown name refused, naming it)."""
        wanted = [c.name for c in self.map.channels] + (
            [self.map.point_channel] if self.map.runs == "point-channel" else [])
        for i in groups:
            name, chans = self._index[i]
            missing = [c for c in wanted if c not in chans]
            if missing:
                raise InputError(f"{self._where()}: group {name!r} has no channel "
                                 f"{missing[0]!r} (it has {_listed(list(chans))}): fix the "
                                 "channel map's names")

    def _find_runs(self) -> list[_Run]:
        m = self.map
        if m.runs == "groups":
            groups = self._groups(m.force.name)
            self._check_channels(groups)
            runs = []
            for i in groups:
                name = self._index[i][0]
                exc = m.excitation_of_group(name)
                if exc is None:
                    raise InputError(f"{self._where()}: group {name!r} is in no [[excitation]]:"
                                     " add it to the groups of the point it was excited at")
                runs.append(_Run(i, name, exc))
            known = {self._index[i][0] for i in groups}
            stray = [g for e in m.excitations for g in e.groups if g not in known]
            if stray:
                raise InputError(f"{self._where()}: [[excitation]] group {stray[0]!r} is not "
                                 "among the groups read: fix its name")
        else:
            groups = self._groups(m.point_channel)
            self._check_channels(groups)
            runs = []
            for i in groups:
                name = self._index[i][0]
                (points,) = self.raw.read(i, [m.point_channel])
                for point, a, b in _stretches(points.samples):
                    exc = m.excitation_of_point(point)
                    if exc is None:
                        raise InputError(f"{self._where()}: group {name!r}: point {point} "
                                         f"(samples {a}-{b - 1}) is in no [[excitation]]: add "
                                         "one with that point")
                    runs.append(_Run(i, name, exc, (a, b)))
        if not runs:
            raise InputError(f"{self._where()}: no run found (the point channel is 0 "
                             "throughout): check point_channel")
        return runs

    def _signals(self, group: int, names: list[str]) -> dict[str, RawSignal]:
        """The group's channels ``names``, the last group read kept (a group holds many runs
        in the point-channel layout)."""
        have = self._cache[1] if self._cache and self._cache[0] == group else {}
        todo = [n for n in names if n not in have]
        if todo:
            have = {**have, **dict(zip(todo, self.raw.read(group, todo), strict=True))}
            self._cache = (group, have)
        return have

    def read_run(self, load_case: int, force_only: bool = False) -> TimeRun:
        """Run ``load_case`` in SI units (``force_only``: its force alone, no responses).

        Raises
        ------
        InputError
            Naming the load case and group: channels of different sample rates or lengths,
            NaN or infinite samples, a unit it cannot convert.
        """
        r = self._runs[load_case - 1]
        lc = f"load case {load_case} ({self.run_name(load_case)})"
        specs = [self.map.force] if force_only else list(self.map.channels)
        signals = self._signals(r.group, [c.name for c in specs])
        rates = [signals[c.name].fs for c in specs]
        if len(set(rates)) > 1:
            shown = ", ".join(f"{c.name} {signals[c.name].fs:.9g}" for c in specs)
            raise InputError(f"{lc}: channels at different sample rates ({shown} Hz): record "
                             "every channel of a run at one rate")
        sizes = {signals[c.name].samples.size for c in specs}
        if len(sizes) > 1:
            shown = ", ".join(map(str, sorted(sizes)))
            raise InputError(f"{lc}: channels of different lengths ({shown} samples): record "
                             "every channel of a run with the same length")
        rows = []
        for c in specs:
            s = signals[c.name]
            x = s.samples if r.span is None else s.samples[r.span[0]:r.span[1]]
            bad = int(np.count_nonzero(~np.isfinite(x)))
            if bad:
                raise InputError(f"{lc}: channel {c.name!r}: {bad} NaN or infinite sample(s): "
                                 "repair or drop the run")
            rows.append(x * c.factor(s.unit, lc))
        fs = rates[0]
        if not (math.isfinite(fs) and fs > 0):
            raise InputError(f"{lc}: sample rate {fs} Hz is not positive: check the file's "
                             "time axis")
        resp = np.vstack(rows[1:]) if len(rows) > 1 else np.zeros((0, rows[0].size))
        m = self.map
        return TimeRun(load_case=load_case, fs=fs, force=rows[0], exc_node=r.excitation.node,
                       exc_dir=np.array(r.excitation.direction), responses=resp,
                       resp_nodes=m.resp_nodes if not force_only else np.zeros(0, np.int64),
                       resp_dirs=m.resp_dirs if not force_only else np.zeros((0, 3)))


def _listed(names: Sequence[str], most: int = 8) -> str:
    shown = ", ".join(repr(n) for n in names[:most])
    return (shown + f" and {len(names) - most} more" if len(names) > most else shown) or "none"
