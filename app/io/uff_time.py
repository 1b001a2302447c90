"""UFF time records (dataset 58, function type 1): read and write measurement runs.

Contract (``docs/conventions.md``, time-data input): one record per channel per run; the
records of one run share the load case number (record 6 field 4); the force record
is the one with ordinate type 13 and its node/direction are the run's excitation
DOF; the other records are accelerations (ordinate type 12) at their node/direction.
The sample rate comes from the abscissa increment, units from dataset 164 and the
records' unit exponents.

A file is read one run at a time (:func:`read_time_file`, :meth:`TimeFile.read_run`): memory
holds the records of one run, never the file's samples.

The E13.5 abscissa increment holds 6 significant digits, so 1/2048 s reads back as
4.88281e-4 s; a rate is snapped to the integer whose period prints to the same six
digits (2048 Hz here). Non-integer rates keep that 6-digit precision in ASCII files;
binary files then store every sample time.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any, Literal, Protocol, overload

import numpy as np
from numpy.typing import NDArray

from app.io._uff_common import (
    Dataset,
    UnitFactors,
    dof_direction,
    exponents,
    open_uff,
    read_set,
    read_units,
    record_label,
    sample_axis,
    snapped_rate,
    type_name,
)
from app.io._uff_write import AxisInfo, open_for_writing
from app.io.uff_geometry import assign_node_frames, read_geometry
from processing.data import Geometry, InputError

__all__ = ["TimeFile", "TimeRun", "TimeSource", "read_time_file", "read_time_uff",
           "uff_holds_time_data", "write_time_uff"]

log = logging.getLogger(__name__)

_TIME = 1
_FORCE, _ACCELERATION = 13, 12

Problem = tuple[int, str]


@dataclass(frozen=True, eq=False)
class TimeRun:
    """One excitation run: the force and the accelerations it caused, SI units.

    Attributes
    ----------
    load_case : load case number shared by the run's records
    fs : sample rate, Hz
    force : (n_samples,) excitation force, N
    exc_node : node of the excitation DOF
    exc_dir : (3,) unit vector of the excitation, global frame
    responses : (n_resp, n_samples) accelerations, m/s^2
    resp_nodes : (n_resp,) node of each response
    resp_dirs : (n_resp, 3) unit vector of each response, global frame

    Runs compare by identity (their arrays make field-wise equality ambiguous).
    """

    load_case: int
    fs: float
    force: NDArray[np.float64]
    exc_node: int
    exc_dir: NDArray[np.float64]
    responses: NDArray[np.float64]
    resp_nodes: NDArray[np.int64]
    resp_dirs: NDArray[np.float64]

    def __post_init__(self) -> None:
        force = np.asarray(self.force, dtype=float).ravel()
        resp = np.asarray(self.responses, dtype=float)
        resp = resp.reshape(-1, force.size) if resp.size else resp.reshape(0, force.size)
        rn = np.asarray(self.resp_nodes, dtype=np.int64).ravel()
        rd = np.asarray(self.resp_dirs, dtype=float).reshape(-1, 3)
        ed = np.asarray(self.exc_dir, dtype=float).reshape(3)
        if not (np.isfinite(self.fs) and self.fs > 0):
            raise InputError(
                f"load case {self.load_case}: sample rate {self.fs} Hz is not positive"
            )
        if rn.size != resp.shape[0] or rd.shape[0] != resp.shape[0]:
            raise InputError(
                f"load case {self.load_case}: {resp.shape[0]} response channels but "
                f"{rn.size} nodes and {rd.shape[0]} directions"
            )
        norms = np.linalg.norm(np.vstack([ed, rd]), axis=1)
        if np.any(norms < 1e-12) or not np.all(np.isfinite(norms)):
            raise InputError(f"load case {self.load_case}: a direction is zero or not finite")
        object.__setattr__(self, "load_case", int(self.load_case))
        object.__setattr__(self, "fs", float(self.fs))
        object.__setattr__(self, "force", force)
        object.__setattr__(self, "exc_node", int(self.exc_node))
        object.__setattr__(self, "exc_dir", ed / norms[0])
        object.__setattr__(self, "responses", resp)
        object.__setattr__(self, "resp_nodes", rn)
        object.__setattr__(self, "resp_dirs", rd / norms[1:, None])

    @property
    def n_samples(self) -> int:
        return int(self.force.size)


class TimeSource(Protocol):
    """A file of time runs read one run at a time: a time UFF (:class:`TimeFile`) or a TDMS
    or MDF file through its channel map (:class:`app.io.time_channels.MappedTimeFile`)."""

    @property
    def path(self) -> Path: ...

    @property
    def load_cases(self) -> tuple[int, ...]:
        """The runs' load case numbers, in the file's order."""
        ...

    def read_run(self, load_case: int, force_only: bool = False) -> TimeRun:
        """Run ``load_case`` in SI units (``force_only``: its force alone); InputError naming
        the load case and the problem."""
        ...

    def geometry(self) -> Geometry:
        """The node coordinates, m."""
        ...


def _rate(ds: Dataset, x: NDArray[np.float64], where: str) -> float:
    """Sample rate of a time record, Hz."""
    if int(ds.get("abscissa_spacing", 1)) == 1:
        inc = float(ds.get("abscissa_inc", 0.0))
        if not (np.isfinite(inc) and inc > 0):
            raise InputError(f"{where}: abscissa increment {inc} s is not positive")
        return snapped_rate(inc)
    step = np.diff(x)
    if x.size < 2 or step[0] <= 0 or not np.allclose(step, step[0], rtol=1e-6, atol=0.0):
        raise InputError(f"{where}: samples are not evenly spaced in time: resample the record")
    return float((x.size - 1) / (x[-1] - x[0]))


def _run(
    load_case: int,
    records: Iterable[tuple[int, Dataset]],
    units: UnitFactors,
    rotations: dict[int, NDArray[np.float64]],
) -> TimeRun:
    """One run from its records, the force first then the responses (none: a run of its
    force alone), each parsed when reached and dropped once converted; InputError names
    the load case and the problem."""
    lc = f"load case {load_case}"
    rates, signals = [], []
    resp_nodes: list[int] = []
    resp_dirs: list[NDArray[np.float64]] = []
    seen: set[tuple[int, int]] = set()
    exc_node, exc_dir = 0, np.zeros(3)
    for i, ds in records:
        where = f"{lc}: {record_label(i, ds)}"
        kind, rate, signal = _time_signal(ds, units, where)
        rates.append(rate)
        signals.append(signal)
        node, code = int(ds.get("rsp_node", 0)), int(ds.get("rsp_dir", 0))
        what = "excitation" if kind == _FORCE else "response"
        axis, _, vec = dof_direction(node, code, rotations, what, where)
        if kind == _ACCELERATION:
            if (node, axis) in seen:
                raise InputError(f"{where}: response {node}:{code:+d} recorded twice in the run")
            seen.add((node, axis))
            resp_nodes.append(node)
            resp_dirs.append(vec)
        else:
            exc_node, exc_dir = node, vec
    _check_one_timebase(lc, rates, [sig.size for sig in signals])
    return TimeRun(
        load_case=load_case,
        fs=rates[0],
        force=signals[0],
        exc_node=exc_node,
        exc_dir=exc_dir,
        responses=np.vstack(signals[1:]) if len(signals) > 1 else np.zeros((0, signals[0].size)),
        resp_nodes=np.array(resp_nodes, dtype=np.int64),
        resp_dirs=np.array(resp_dirs).reshape(-1, 3),
    )


def _force_and_responses(lc: str, items: list[tuple[int, Dataset]],
                         ) -> tuple[tuple[int, Dataset], list[tuple[int, Dataset]]]:
    """The run's one force record and its other records; InputError (naming ``lc``, the
    load case) without a force, with several, or without any other record."""
    forces = [(i, ds) for i, ds in items if int(ds.get("ordinate_spec_data_type", 0)) == _FORCE]
    if not forces:
        raise InputError(
            f"{lc}: no force record (ordinate type 13) among its {len(items)} record(s): "
            "export the excitation force channel with the run"
        )
    if len(forces) > 1:
        which = ", ".join(f"#{i + 1}" for i, _ in forces)
        raise InputError(
            f"{lc}: {len(forces)} force records (datasets {which}): one excitation per run "
            "is supported; give each excitation its own load case"
        )
    responses = [(i, ds) for i, ds in items if i != forces[0][0]]
    if not responses:
        raise InputError(f"{lc}: no acceleration records (ordinate type 12) besides the force")
    return forces[0], responses


def _time_signal(ds: Dataset, units: UnitFactors, where: str,
                 ) -> tuple[int, float, NDArray[np.float64]]:
    """A time record's ordinate type (force or acceleration), sample rate (Hz) and samples in
    SI units; InputError for any other type, a non-time abscissa, or bad samples."""
    kind = int(ds.get("ordinate_spec_data_type", 0))
    if kind not in (_FORCE, _ACCELERATION):
        raise InputError(
            f"{where}: ordinate type {type_name(kind)}; time responses must be "
            "acceleration (12): export accelerations or drop the channel"
        )
    absc = int(ds.get("abscissa_spec_data_type", 0) or 0)
    if absc not in (0, 17):
        raise InputError(f"{where}: abscissa type {type_name(absc)} is not time (17)")
    values = np.asarray(ds.get("data"))
    if np.iscomplexobj(values):
        raise InputError(f"{where}: complex values in a time record: export real samples")
    x = sample_axis(ds, where)
    bad = int(np.sum(~np.isfinite(values)))
    if bad:
        raise InputError(f"{where}: {bad} NaN or infinite sample(s): repair or drop the run")
    rate = _rate(ds, x, where)
    return kind, rate, values.astype(float) * units.to_si(*exponents(ds, "ordinate"))


def _check_one_timebase(lc: str, rates: list[float], sizes: list[int]) -> None:
    """InputError (naming ``lc``) unless the run's records share one length and one rate."""
    if len(set(sizes)) > 1:
        raise InputError(
            f"{lc}: records of different lengths ({', '.join(map(str, sorted(set(sizes))))} "
            "samples): export every channel of a run with the same length"
        )
    if not np.allclose(rates, rates[0], rtol=1e-9, atol=0.0):
        shown = ", ".join(f"{r:.6g}" for r in sorted(set(rates)))
        raise InputError(
            f"{lc}: records with different sample rates ({shown} Hz): "
            "export every channel of a run at one rate"
        )


@overload
def read_time_uff(path: str | Path, strict: Literal[True] = ...) -> list[TimeRun]: ...


@overload
def read_time_uff(
    path: str | Path, strict: Literal[False]
) -> tuple[list[TimeRun], list[Problem]]: ...


def read_time_uff(
    path: str | Path, strict: bool = True
) -> list[TimeRun] | tuple[list[TimeRun], list[Problem]]:
    """Read the time records of a UFF file as runs, one per load case.

    Parameters
    ----------
    path : file name (ASCII 58 or binary 58b records)
    strict : with True (default) any bad run raises; with False the good runs are
        returned together with a list of ``(load_case, message)`` problems, so the
        good runs of a file can still be processed.

    Returns
    -------
    list[TimeRun]
        In order of first appearance in the file (``strict=True``), or
    tuple[list[TimeRun], list[tuple[int, str]]]
        The good runs and the problems of the others (``strict=False``).

    Notes
    -----
    Directions are read in each node's displacement coordinate system when the file
    has nodes (dataset 15/2411 + 2420); without nodes they are global axes. Node
    coordinates are not part of a run: use :func:`app.io.uff_geometry.read_geometry_uff`.

    Raises
    ------
    InputError
        Missing or unparsable file, no time records, a bad geometry/units dataset, or
        (``strict=True``) a run without a force record, with records of different
        sample rates or lengths, with NaN values or an unknown ordinate type. The
        message names the load case.
    """
    runs: list[TimeRun] = []
    problems: list[Problem] = []
    f = read_time_file(path)
    for load_case in f.load_cases:
        try:
            runs.append(f.read_run(load_case))
        except InputError as err:
            log.info("%s: %s", f.path.name, err)
            problems.append((load_case, str(err)))
    if strict:
        if problems:
            more = f" ({len(problems) - 1} more run(s) with problems)" if len(problems) > 1 else ""
            raise InputError(problems[0][1] + more)
        return runs
    return runs, problems


@dataclass(frozen=True)
class TimeFile:
    """A time-data UFF file indexed from its headers: its runs' load cases in order of first
    appearance and its other datasets (units, nodes, coordinate systems); each run's samples
    are read when asked for (:meth:`read_run`), so memory holds one run, never the file.

    Attributes
    ----------
    path : the file
    load_cases : the runs' load case numbers, in order of first appearance
    datasets : the datasets other than dataset 58 (parsed), for :meth:`geometry`
    units : the file's unit factors (dataset 164)
    """

    path: Path
    load_cases: tuple[int, ...]
    datasets: list[Dataset]
    units: UnitFactors
    uff: Any = field(repr=False)  # the pyuff.UFF index
    records: dict[int, list[tuple[int, Dataset]]] = field(repr=False)  # headers by load case
    rotations: dict[int, NDArray[np.float64]] = field(repr=False)

    def geometry(self) -> Geometry:
        """The file's node geometry (m); InputError when it has none."""
        return read_geometry(self.datasets)[0]

    def read_run(self, load_case: int, force_only: bool = False) -> TimeRun:
        """Run ``load_case`` read from the file, one record at a time (``force_only``: its
        force record alone, the run's responses then empty).

        Raises
        ------
        InputError
            The run's problem, named as :func:`read_time_uff` names it: the checks run in
            the same order, so a force-only read that passes can still fail in full.
        """
        force, responses = _force_and_responses(f"load case {load_case}",
                                                self.records[load_case])
        chosen = [force] if force_only else [force, *responses]
        data = ((i, read_set(self.uff, i)) for i, _ in chosen)
        return _run(load_case, data, self.units, self.rotations)


def read_time_file(path: str | Path) -> TimeFile:
    """A time-data UFF file indexed from its headers (:class:`TimeFile`): its runs are then
    read one at a time with :meth:`TimeFile.read_run` (:func:`read_time_uff` reads them all;
    :meth:`TimeFile.geometry` the nodes of :func:`app.io.uff_geometry.read_geometry_uff`).

    Raises
    ------
    InputError
        Missing or unparsable file, no time records, a bad geometry/units dataset.
    """
    p = Path(path)
    uff, types = open_uff(p)
    headers = [(i, read_set(uff, i, header_only=t == 58)) for i, t in enumerate(types)]
    sets = [ds for (_, ds), t in zip(headers, types, strict=True) if t != 58]
    units = read_units(sets)
    has_nodes = any(ds.get("type") in (15, 2411) for ds in sets)
    rotations = read_geometry(sets)[1] if has_nodes else {}
    groups: dict[int, list[tuple[int, Dataset]]] = {}
    for i, ds in headers:
        if ds.get("type") == 58 and ds.get("func_type") == _TIME:
            groups.setdefault(int(ds.get("load_case_id", 0)), []).append((i, ds))
    if not groups:
        raise InputError(
            f"{p.name} has no time records (dataset 58 with function type 1): "
            "give a file of time records, or give an FRF file to insitu identify"
        )
    return TimeFile(p, tuple(groups), sets, units, uff, groups, rotations)


def write_time_uff(
    path: str | Path, runs: Sequence[TimeRun], geometry: Geometry, *, binary: bool = False
) -> None:
    """Write runs as UFF time records (SI units) with their geometry.

    Datasets: 164 (SI), 2420 for nodes whose directions are not global axes, 2411,
    then per run the force record (ordinate 13) and the acceleration records (12),
    all with the run's load case number, abscissa time from 0 s.

    Parameters
    ----------
    path : output file, replaced atomically
    runs : runs with distinct load case numbers
    geometry : coordinates of every node the runs use, m
    binary : write 58b records (IEEE doubles) instead of ASCII 58 (12 digits)

    Raises
    ------
    InputError
        No runs, repeated load cases, NaN/infinite samples, a node without
        coordinates, directions at a node not along one orthonormal frame.
    """
    runs = list(runs)
    if not runs:
        raise InputError("no runs to write")
    cases = [r.load_case for r in runs]
    if len(set(cases)) != len(cases):
        raise InputError(f"load case numbers repeat ({cases}): give each run its own load case")
    for r in runs:
        if not (np.all(np.isfinite(r.force)) and np.all(np.isfinite(r.responses))):
            raise InputError(f"load case {r.load_case}: NaN or infinite samples: repair the run")
    nodes = np.concatenate([np.r_[r.exc_node, r.resp_nodes] for r in runs]).astype(np.int64)
    dirs = np.concatenate([np.vstack([r.exc_dir, r.resp_dirs]) for r in runs])
    geometry.coordinates(nodes, "time record")
    frames, codes = assign_node_frames(nodes, dirs)
    stamp = datetime.now().strftime("%d-%b-%y %H:%M:%S")
    time_axis = AxisInfo(17, 0, 0, "Time", "s")
    kinds = {True: AxisInfo(13, 0, 1, "Force", "N"),
             False: AxisInfo(12, 1, 0, "Acceleration", "m/s^2")}
    start = 0
    with open_for_writing(path) as w:
        w.units(UnitFactors())
        w.geometry(geometry, frames, 1.0)
        func_id = 0
        for r in runs:
            x = np.arange(r.n_samples) / r.fs
            exact = snapped_rate(float(f"{1.0 / r.fs:13.5e}")) == r.fs
            ch_nodes = np.r_[r.exc_node, r.resp_nodes]
            ch_codes = codes[start : start + ch_nodes.size]
            start += ch_nodes.size
            ref = (int(r.exc_node), int(ch_codes[0]))
            for k, signal in enumerate([r.force, *r.responses]):
                func_id += 1
                dof = (int(ch_nodes[k]), int(ch_codes[k]))
                w.function(
                    func_type=_TIME,
                    func_id=func_id,
                    load_case=r.load_case,
                    response=dof,
                    reference=ref,
                    x=x,
                    data=signal,
                    abscissa=time_axis,
                    ordinate=kinds[k == 0],
                    denominator=AxisInfo(),
                    ids=[f"{'Force' if k == 0 else 'Acceleration'} {dof[0]}:{dof[1]:+d}",
                         "insitu", stamp, f"load case {r.load_case}"],
                    binary=binary,
                    even=True if exact else None,
                )
    log.info("wrote %d runs to %s", len(runs), path)


def uff_holds_time_data(path: str | Path) -> bool:
    """True when the file's first dataset-58 record is a time record (function type 1):
    such a file needs FRFs computed before identification. Reads the headers only, up to
    that record's record 6 (its data are not parsed); False for a file that cannot be read
    (its reader then says why)."""
    try:
        with Path(path).open("rb") as f:
            prev = b""
            for line in f:
                s = line.strip()
                if prev == b"-1" and (s == b"58" or s.startswith(b"58b")):
                    fields = [next(f, b"") for _ in range(6)][5].split()
                    return bool(fields) and fields[0].isdigit() and int(fields[0]) == _TIME
                prev = s
    except OSError:
        return False
    return False
