"""One HDF5 file per acquisition run: raw records, verdicts, settings, FRFs and results.

The layout is documented in ``docs/run-file.md`` (schema version :data:`SCHEMA_VERSION`).
Every object is created up front and records are *appended* to resizable
datasets; the writer opens the file only for each change and closes it after
an ``fsync``, so a power cut or ``kill -9`` leaves a file that any HDF5 tool
reads, with every record written so far (:func:`repair` mends the rare file
killed in the middle of a write). :meth:`RunWriter.finish` writes the state,
FRFs and identification result. While it writes, the writer holds a reserve file
beside the run file (:data:`RESERVE_BYTES`): when the disk fills, it deletes the
reserve and uses that room to close the file cleanly, without the record that did
not fit, in state ``failed`` (:class:`DiskFullError`).

Example
-------
>>> run = read_run("run.h5")  # doctest: +SKIP
>>> run.state, len(run.records.point)  # doctest: +SKIP
('finished', 54)
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import json
import logging
import os
import shutil
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from app.io._hdf5_mark import clear_write_mark
from app.io.mounts import MountsFile, MountsFileError, mounts_from_dict
from drivers.base import ChannelConfig
from processing.data import FRFSet, Geometry
from processing.measurement import Measurement, Provenance

__all__ = ["RESERVE_BYTES", "SCHEMA_VERSION", "ChannelInfo", "DiskFullError", "RecordTable",
           "RunData", "RunFileError", "RunWriter", "WriteMarkError", "iter_record_data",
           "read_run", "repair", "reserve_path", "run_mounts", "write_mounts"]

logger = logging.getLogger(__name__)

SCHEMA_VERSION = 1
FORMAT = "insitu-run"
TEXT = 256  # bytes of a reason / note in the fixed-width string columns
OVERRIDES = {"": 0, "accept": 1, "reject": -1}
_OVERRIDE_NAMES = {v: k for k, v in OVERRIDES.items()}
#: bytes the writer keeps in reserve beside the run file while it writes: the room to close
#: the file cleanly when the disk fills (HDF5's structures and the state need a few kB)
RESERVE_BYTES = 1 << 20

#: per-record columns: name -> (dtype, unit)
_COLUMNS: dict[str, tuple[str, str]] = {
    "point": ("i4", "1"), "time": ("f8", "s"), "peak_force": ("f8", "N"),
    "auto_accepted": ("u1", "1"), "reason": (f"S{TEXT}", "n/a"), "override": ("i1", "1"),
    "bad_frames": ("i4", "1"), "missing": ("i4", "1"),
}


class RunFileError(ValueError):
    """The run file is missing, foreign, of another schema version or damaged (one line)."""


class WriteMarkError(RunFileError):
    """The run file is still marked open for writing by a writer stopped while it wrote
    (``insitu repair`` clears the mark; one line)."""


class DiskFullError(RunFileError):
    """The disk of the run file is full: the change was not written, the file was closed
    cleanly with every record before it and state ``failed`` (one line)."""


def reserve_path(path: str | Path) -> Path:
    """The reserve file a writer holds beside the run file ``path`` (``RUN.h5.reserve``)."""
    p = Path(path)
    return p.with_name(p.name + ".reserve")


def _disk_full(err: OSError) -> bool:
    """True when ``err`` (an OSError, or h5py's wrapping of one) says the disk is full."""
    text = str(err)
    return err.errno in (errno.ENOSPC, errno.EDQUOT) or "No space left" in text or \
        f"errno = {errno.ENOSPC}," in text or "Disk quota exceeded" in text


def _free_mb(p: Path) -> float:
    try:
        return shutil.disk_usage(p.parent).free / 1e6
    except OSError:
        return float("nan")


@dataclass(frozen=True)
class ChannelInfo:
    """One row of the records: channel name, device, quantity, SI unit, sensitivity (mV/unit),
    range (V), IEPE, node and unit direction."""

    name: str
    device: str
    quantity: str
    unit: str
    sensitivity: float
    range_v: float
    iepe: bool
    node: int
    direction: tuple[float, float, float]


@dataclass(frozen=True)
class RecordTable:
    """Every record of a run, columns as arrays (row ``i`` is record ``i``)."""

    data: NDArray[np.float64]  # (n, n_ch, n_samples): force N, responses m/s^2
    fs: float
    point: NDArray[np.int32]
    time: NDArray[np.float64]
    peak_force: NDArray[np.float64]
    auto_accepted: NDArray[np.bool_]
    reason: tuple[str, ...]
    override: tuple[str, ...]
    bad_frames: NDArray[np.int32]
    missing: NDArray[np.int32]
    force_raw: NDArray[np.float64] | None = None  # (n, n_raw) hammer force at fs_raw
    fs_raw: float = 0.0
    #: how the force row is put on the front end's clock: "same-device", "common-channel"
    #: (a separate force device aligned per hit on the front end's copy of the force) or
    #: "host-timed" (a separate device aligned by host timing only, about 1 ms)
    force_alignment: str = "same-device"
    sync_channel: str = ""
    sync: NDArray[np.float64] | None = None  # (n, n_samples) common channel, N
    sync_offset: NDArray[np.float64] | None = None  # (n,) correction it gave, s

    def __len__(self) -> int:
        return int(self.point.size)

    @property
    def accepted(self) -> NDArray[np.bool_]:
        """The verdict in force: override where given, else the automatic one."""
        ov = np.array([OVERRIDES[o] for o in self.override], dtype=int)
        return np.where(ov == 0, self.auto_accepted, ov > 0)


@dataclass(frozen=True)
class RunData:
    """What :func:`read_run` returns. ``state`` is ``"interrupted"`` when the writer died."""

    path: str
    schema_version: int
    state: str
    message: str
    created: str
    method: str
    plan_data: dict[str, Any]
    station_data: dict[str, Any]
    channels: tuple[ChannelInfo, ...]
    geometry: Geometry
    records: RecordTable
    notes: tuple[tuple[float, str], ...]
    #: the FRFs stored when the run finished and their provenance (no per-hit spectra), or None
    measurement: Measurement | None
    result: dict[str, Any] | None
    #: the mounts table (optional group ``/mounts``), or None
    mounts: MountsFile | None = None


def _text(group: h5py.Group, name: str, obj: Any, units: str = "n/a") -> None:
    ds = group.create_dataset(name, data=json.dumps(obj))
    ds.attrs["units"] = units


def _array(group: h5py.Group, name: str, data: Any, units: str) -> h5py.Dataset:
    ds = group.create_dataset(name, data=data)
    ds.attrs["units"] = units
    return ds


def _column(group: h5py.Group, name: str, dtype: str, units: str,
            shape: tuple[int, ...] = ()) -> None:
    ds = group.create_dataset(name, shape=(0, *shape), maxshape=(None, *shape), dtype=dtype,
                              chunks=(1, *shape) if shape else (256,))
    ds.attrs["units"] = units


class RunWriter:
    """Appends records to a run file; use :meth:`create` or :meth:`resume`, then
    :meth:`add_record` per hit, :meth:`finish` at the end.

    Not thread-safe: one thread (the procedure's worker) writes. A change that fails
    (the disk full, :class:`DiskFullError`; any other write error, :class:`RunFileError`)
    is undone and ends the writer: the file is closed in state ``failed`` with every
    record before it, and :meth:`finish` does nothing more.
    """

    def __init__(self, path: Path, n_records: int) -> None:
        self.path = path
        self._n = n_records
        self._lock = threading.Lock()
        self._closed = False
        #: why a write failed (the writer is closed then), or ""
        self.failure = ""

    @contextlib.contextmanager
    def _session(self, what: str, undo: Callable[[h5py.File], None]
                 ) -> Iterator[h5py.File]:
        """The file, open for one change, then flushed to disk (fsync) and closed.

        ``what`` names the change in messages; ``undo`` takes it back out of the open file
        when a write fails (the disk full): see :meth:`_fail`.
        """
        with self._lock:
            if self._closed:
                raise RunFileError(f"{self.path}: the run file is closed")
            try:
                f = _append(self.path)
            except OSError as err:
                self._closed = True
                raise self._failed(err, self._message(what, err), saved=True) from err
            try:
                yield f
                f.flush()
                _fsync(f)
            except OSError as err:  # h5py's errors wrap the OS's (ENOSPC, EIO)
                message = self._message(what, err)
                raise self._failed(err, message, self._fail(f, undo, message)) from err
            finally:
                _close(f)

    def _message(self, what: str, err: OSError) -> str:
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        if _disk_full(err):
            return f"disk full ({_free_mb(self.path):.1f} MB free) writing {what} to {self.path}"
        return f"cannot write {what} to {self.path}: {first}"

    def _failed(self, err: OSError, message: str, saved: bool) -> RunFileError:
        """The one-line error of a failed change; ``saved``: the file was closed cleanly
        (else it needs ``insitu repair``)."""
        then = "resume the run" if saved else f"run insitu repair {self.path}"
        if _disk_full(err):
            return DiskFullError(f"{message}: free space on that disk, then {then}")
        return RunFileError(f"{message}: {then}" if not saved else message)

    def _fail(self, f: h5py.File, undo: Callable[[h5py.File], None], message: str) -> bool:
        """A write failed in ``f``: free the reserve, take the change back out, store state
        ``failed`` and ``message``, flush; the writer is closed. True when that worked (the
        file is whole, with every record before the change), False when it needs repair."""
        self._closed = True
        self.failure = message
        _drop_reserve(self.path)  # the room to finish this session (the disk is full)
        try:
            undo(f)
            f.attrs["state"] = "failed"
            f.attrs["message"] = message
            f.flush()
            _fsync(f)
        except (OSError, RuntimeError, KeyError) as err:
            logger.error("%s: could not close the run file cleanly after a failed write: %s",
                         self.path, err)
            return False
        return True

    def _hold_reserve(self) -> None:
        """Create the reserve file beside the run file (:data:`RESERVE_BYTES`)."""
        r = reserve_path(self.path)
        try:
            fd = os.open(r, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                try:
                    os.posix_fallocate(fd, 0, RESERVE_BYTES)
                except OSError as err:  # a file system without fallocate: write the bytes
                    if err.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
                        raise
                    os.write(fd, bytes(RESERVE_BYTES))
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as err:
            r.unlink(missing_ok=True)
            first = str(err).splitlines()[0]
            if _disk_full(err):
                raise DiskFullError(f"{self.path}: disk full ({_free_mb(self.path):.1f} MB "
                                    "free): free space on that disk") from err
            raise RunFileError(f"{r}: cannot write the run's reserve file: {first}") from err

    # -- opening --------------------------------------------------------------------------------
    @classmethod
    def create(cls, path: str | Path, *, plan_data: Mapping[str, Any],
               station_data: Mapping[str, Any], channels: Sequence[ChannelConfig],
               devices: Sequence[str], geometry: Geometry, fs: float, n_samples: int,
               method: str, fs_raw: float = 0.0, n_raw: int = 0,
               force_alignment: str = "", sync_channel: str = "",
               attrs: Mapping[str, Any] | None = None) -> RunWriter:
        """A new run file (overwrites ``path``).

        ``channels`` are the rows of every record (force first), ``devices`` the device each
        comes from; records are ``n_samples`` long at ``fs`` Hz; ``n_raw`` > 0 stores the
        hammer's own force samples (``fs_raw`` Hz) of every hit as well. ``force_alignment``
        (default: ``same-device``, or ``host-timed`` with ``n_raw``) says how the force row
        was put on the front end's clock; a ``sync_channel`` (common channel) adds its
        record and the correction it gave per record. ``attrs`` are extra ``/records``
        attributes (the shaker's window, for instance). The reserve file is made first; a
        disk too full for the file's structures raises :class:`DiskFullError` and leaves
        neither file.
        """
        p = Path(path)
        writer = cls(p, 0)
        writer._hold_reserve()
        try:
            f = h5py.File(h5py.h5f.create(os.fsencode(p), h5py.h5f.ACC_TRUNC,
                                          fapl=_write_access()))
        except OSError as err:
            _drop_reserve(p)
            raise RunFileError(f"{p}: cannot create the run file: {err}") from err
        try:
            _layout(f, plan_data=plan_data, station_data=station_data, channels=channels,
                    devices=devices, geometry=geometry, fs=fs, n_samples=n_samples,
                    method=method, fs_raw=fs_raw, n_raw=n_raw,
                    force_alignment=force_alignment, sync_channel=sync_channel, attrs=attrs)
            f.flush()
            _fsync(f)
        except OSError as err:  # nothing acquired yet: no half-made file is left behind
            _close(f)
            p.unlink(missing_ok=True)
            _drop_reserve(p)
            if _disk_full(err):
                raise DiskFullError(f"{p}: disk full ({_free_mb(p):.1f} MB free) while "
                                    "creating the run file: free space on that disk") from err
            raise RunFileError(f"{p}: cannot create the run file: "
                               f"{str(err).splitlines()[0]}") from err
        _close(f)
        return writer

    @classmethod
    def resume(cls, path: str | Path) -> RunWriter:
        """Reopen an interrupted or paused run to append to it.

        A file whose writer was killed carries HDF5's "open for writing" mark; it is
        copied object by object into a fresh file that then replaces it (the original
        stays in place until the copy is complete). A record left incomplete (some of
        its columns unwritten) is dropped, so the next one takes its place.
        """
        p = Path(path)
        read_run(p, with_data=False)  # one-line error if foreign or damaged
        repair(p)
        writer = cls(p, 0)
        writer._hold_reserve()
        with writer._session("the run's state", lambda f: None) as f:
            f.attrs["state"] = "running"
            f.attrs["message"] = ""
            for key in ("frf", "result"):
                if key in f:
                    del f[key]
            rec = f["records"]
            writer._n = min([rec[c].shape[0] for c in _COLUMNS] + [rec["data"].shape[0]])
            _truncate(rec, writer._n)
        return writer
    # -- appending ------------------------------------------------------------------------------
    @property
    def n_records(self) -> int:
        return self._n

    def add_record(self, point: int, data: NDArray[np.float64], *, time: float,
                   peak_force: float, auto_accepted: bool, reason: str, bad_frames: int = 0,
                   missing: int = 0, force_raw: NDArray[np.float64] | None = None,
                   sync: NDArray[np.float64] | None = None,
                   sync_offset: float = float("nan")) -> int:
        """Append one record with its verdict and flush; returns its index.

        ``sync`` is the common channel's record (N) and ``sync_offset`` the alignment
        correction it gave (s), for a run created with a ``sync_channel``.
        """
        i = self._n
        values = {"point": point, "time": time, "peak_force": peak_force,
                  "auto_accepted": bool(auto_accepted),
                  "reason": reason.encode("utf-8")[:TEXT], "override": 0,
                  "bad_frames": bad_frames, "missing": missing}
        with self._session(f"record {i + 1}", lambda f: _truncate(f["records"], i)) as f:
            rec = f["records"]
            rec["data"].resize(i + 1, axis=0)
            rec["data"][i] = data
            if "force_raw" in rec:
                raw = np.full(rec["force_raw"].shape[1], np.nan)
                if force_raw is not None:
                    k = min(raw.size, force_raw.size)
                    raw[:k] = force_raw[:k]
                rec["force_raw"].resize(i + 1, axis=0)
                rec["force_raw"][i] = raw
            if "sync" in rec:
                rec["sync"].resize(i + 1, axis=0)
                rec["sync"][i] = np.nan if sync is None else sync
                rec["sync_offset"].resize(i + 1, axis=0)
                rec["sync_offset"][i] = sync_offset
            for name, v in values.items():  # columns last: a record counts once its point is in
                ds = rec[name]
                ds.resize(i + 1, axis=0)
                ds[i] = v
        self._n = i + 1
        return i

    def set_override(self, index: int, override: str) -> None:
        """Set (``"accept"``, ``"reject"``) or clear (``""``) the operator's override."""
        if override not in OVERRIDES:
            raise ValueError(f"override must be one of accept, reject or '', got {override!r}")
        if not 0 <= index < self.n_records:
            raise ValueError(f"no record {index}: the run has {self.n_records}")
        with self._session(f"the override of record {index + 1}", lambda f: None) as f:
            f["records/override"][index] = OVERRIDES[override]

    def add_note(self, text: str, time: float) -> None:
        """Append an operator note (``time`` s since the run started)."""
        count: list[int] = []
        with self._session("a note", lambda f: _truncate(f["notes"], count[0]) if count
                           else None) as f:
            notes = f["notes"]
            i = notes["time"].shape[0]
            count.append(i)
            for name, v in (("time", time), ("text", text.encode("utf-8")[: 2 * TEXT])):
                notes[name].resize(i + 1, axis=0)
                notes[name][i] = v

    # -- ending ---------------------------------------------------------------------------------
    def finish(self, state: str, message: str = "", measurement: Measurement | None = None,
               result: Mapping[str, Any] | None = None) -> None:
        """Record the final state, FRFs and result; the writer is closed after it.

        Does nothing after a failed write (the file already says ``failed`` and why).
        """
        if self.failure:
            return

        def undo(f: h5py.File) -> None:
            for key in ("frf", "result"):
                if key in f:
                    del f[key]

        with self._session("the FRFs" if measurement is not None else "the run's state",
                           undo) as f:
            undo(f)
            if measurement is not None:
                frf = measurement.frf
                g = f.create_group("frf")
                attrs = measurement.provenance.stored()  # the per-hit spectra: the records
                attrs.pop("n_averages", None)  # a dataset of its own
                g.attrs.update(attrs)
                _array(g, "freq", frf.freq, "Hz")
                _array(g, "H", frf.H, "m/s^2/N")
                if frf.coherence is not None:
                    _array(g, "coherence", frf.coherence, "1")
                _array(g, "resp_nodes", frf.resp_nodes, "1")
                _array(g, "resp_dirs", frf.resp_dirs, "1")
                _array(g, "exc_nodes", frf.exc_nodes, "1")
                _array(g, "exc_dirs", frf.exc_dirs, "1")
                _array(g, "n_averages", np.asarray(measurement.provenance.n_averages, int), "1")
            if result is not None:
                _text(f, "result", dict(result), "SI, see docs/conventions.md")
            f.attrs["state"] = state  # last: a run is finished once its FRFs are in
            f.attrs["message"] = message
        self.close()

    def close(self) -> None:
        """Refuse further changes and delete the reserve file (idempotent); every record
        added is already on disk."""
        with self._lock:
            self._closed = True
            _drop_reserve(self.path)


def _layout(f: h5py.File, *, plan_data: Mapping[str, Any], station_data: Mapping[str, Any],
            channels: Sequence[ChannelConfig], devices: Sequence[str], geometry: Geometry,
            fs: float, n_samples: int, method: str, fs_raw: float, n_raw: int,
            force_alignment: str, sync_channel: str, attrs: Mapping[str, Any] | None) -> None:
    """Every object of a new run file (:meth:`RunWriter.create`), no record yet."""
    f.attrs.update({"format": FORMAT, "schema_version": SCHEMA_VERSION, "state": "running",
                    "message": "", "method": method,
                    "created": datetime.datetime.now().astimezone().isoformat(
                        timespec="seconds")})
    _text(f, "plan", dict(plan_data))
    _text(f, "station", dict(station_data))
    ch = f.create_group("channels")
    _array(ch, "name", np.array([c.name for c in channels], dtype="S64"), "n/a")
    _array(ch, "device", np.array(list(devices), dtype="S64"), "n/a")
    _array(ch, "quantity", np.array([c.quantity for c in channels], dtype="S16"), "n/a")
    _array(ch, "unit", np.array([c.unit for c in channels], dtype="S16"), "n/a")
    _array(ch, "sensitivity", [c.sensitivity for c in channels], "mV/unit")
    _array(ch, "range", [c.range_v for c in channels], "V")
    _array(ch, "iepe", np.array([c.iepe for c in channels], dtype="u1"), "1")
    _array(ch, "node", [-1 if c.node is None else c.node for c in channels], "1")
    _array(ch, "direction", [c.direction or (0.0, 0.0, 0.0) for c in channels], "1")
    g = f.create_group("geometry")
    _array(g, "node_ids", geometry.node_ids, "1")
    _array(g, "xyz", geometry.xyz, "m")
    rec = f.create_group("records")
    rec.attrs["fs"] = float(fs)
    rec.attrs["fs_raw"] = float(fs_raw)
    rec.attrs["force_alignment"] = force_alignment or (
        "host-timed" if n_raw else "same-device")
    rec.attrs["sync_channel"] = sync_channel
    rec.attrs.update(dict(attrs or {}))
    _column(rec, "data", "f8", "see /channels/unit", (len(channels), int(n_samples)))
    rec["data"].attrs["units"] = np.array([c.unit for c in channels], dtype="S16")
    if n_raw:
        _column(rec, "force_raw", "f8", "N", (int(n_raw),))
    if sync_channel:
        _column(rec, "sync", "f8", "N", (int(n_samples),))
        _column(rec, "sync_offset", "f8", "s")
    for name, (dtype, unit) in _COLUMNS.items():
        _column(rec, name, dtype, unit)
    notes = f.create_group("notes")
    _column(notes, "time", "f8", "s")
    _column(notes, "text", f"S{TEXT * 2}", "n/a")


def _truncate(group: h5py.Group, n: int) -> None:
    """Cut every per-record dataset of ``group`` (``/records``) to ``n`` rows."""
    for name in group:
        ds = group[name]
        if ds.shape and ds.shape[0] > n:
            ds.resize(n, axis=0)


def _close(f: h5py.File) -> None:
    """Close ``f``; after a failed write HDF5 may refuse (logged: the file was handled)."""
    try:
        f.close()
    except (OSError, RuntimeError) as err:
        logger.warning("closing %s after a failed write: %s", f.filename, err)


def _drop_reserve(p: Path) -> None:
    with contextlib.suppress(OSError):
        reserve_path(p).unlink(missing_ok=True)


def _fsync(f: h5py.File) -> None:
    """Push the file's written pages to the disk (the durability of every record)."""
    os.fsync(f.id.get_vfd_handle())


def repair(path: str | Path) -> bool:
    """Make a run file whose writer was killed readable by any HDF5 tool; True if it had to.

    The writer opens the file only while it appends a record, so a crash leaves HDF5's
    "open for writing" mark only if it struck during that write. Such a file is copied
    object by object into a fresh one that then replaces it (the original stays in place
    until the copy is complete); every record whose columns were all written reads back.
    The reserve file a killed writer left beside it (:func:`reserve_path`) is deleted. A
    writer killed without SWMR (the usual case) leaves a mark every HDF5 open refuses: it is
    cleared first (:func:`app.io._hdf5_mark.clear_write_mark`, as HDF5's ``h5clear -s``).
    """
    p = Path(path)
    try:
        f = _open(p)
    except WriteMarkError:
        # killed while it held the file, SWMR off: every HDF5 open refuses it until its
        # "open for writing" mark is cleared (HDF5's h5clear -s)
        if not clear_write_mark(p):
            raise
        f = _open(p)
        marked = True
    else:
        marked = False
    with f:
        _drop_reserve(p)
        if f.mode == "r" and not f.swmr_mode and not marked:
            return False
    tmp = p.with_name(p.name + ".repair-tmp")
    with h5py.File(p, "r", swmr=not marked) as src, h5py.File(tmp, "w", libver="latest") as dst:
        dst.attrs.update(dict(src.attrs))
        for key in src:
            src.copy(src[key], dst, name=key)
        dst.flush()
        _fsync(dst)
    os.replace(tmp, p)
    return True


# -- reading ------------------------------------------------------------------------------------
def _write_access() -> h5py.h5p.PropFAID:
    """How the writer opens a run file: latest format, no lock, and no raw-data buffers.

    Without the chunk cache and the sieve buffer every write reaches the file within the
    call, so a full disk raises there. (Buffered, the data were written when h5py released
    the dataset, where an error is only printed: the record was silently lost, and the
    file's close then crashed the process, exit 139, on the half-closed dataset.)
    """
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_libver_bounds(h5py.h5f.LIBVER_LATEST, h5py.h5f.LIBVER_LATEST)
    mdc, slots, _, w0 = fapl.get_cache()
    fapl.set_cache(mdc, slots, 0, w0)
    fapl.set_sieve_buf_size(0)
    fapl.set_file_locking(False, ignore_when_disabled=False)
    fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
    return fapl


def _append(p: Path) -> h5py.File:
    """The file opened to append, whoever reads it: a reader's lock never stops a record
    (and unbuffered: :func:`_write_access`)."""
    return h5py.File(h5py.h5f.open(os.fsencode(p), h5py.h5f.ACC_RDWR, fapl=_write_access()))


def _open(p: Path, patience: float = 2.0) -> h5py.File:
    """The run file opened to read; waits up to ``patience`` s while a record is written."""
    if not p.is_file():
        raise RunFileError(f"{p}: no such run file")
    deadline = time.monotonic() + patience
    while True:
        try:
            return h5py.File(p, "r")
        except OSError as err:
            first = err
        marked = "already open for write" in str(first)
        if marked:
            # killed mid-write (or being written): the SWMR reader sees every whole record
            # when the writer had SWMR on
            try:
                return h5py.File(p, "r", swmr=True)
            except OSError:
                pass
        if not (marked or "unable to lock file" in str(first)) or time.monotonic() > deadline:
            break
        time.sleep(0.02)  # the writer holds the file for a few ms per record
    if marked:  # still marked after the patience: no writer is at it any more
        raise WriteMarkError(f"{p}: its writer was stopped while writing to it (the file is "
                             f"still marked open for writing): mend it with insitu repair {p}")
    raise RunFileError(f"{p}: not a readable HDF5 run file (truncated or damaged?): "
                       f"{str(first).splitlines()[0]}") from first


def _str(v: Any) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def read_run(path: str | Path, with_data: bool = True) -> RunData:
    """Read a run file written by :class:`RunWriter`; raises :class:`RunFileError` (one line).

    ``with_data=False`` skips the record samples (``records.data`` is then empty).
    """
    p = Path(path)
    f = _open(p)
    try:
        if _str(f.attrs.get("format", "")) != FORMAT:
            raise RunFileError(f"{p}: not an insitu run file (no format={FORMAT!r} attribute)")
        version = int(f.attrs.get("schema_version", -1))
        if version != SCHEMA_VERSION:
            raise RunFileError(f"{p}: run-file schema version {version}; this insitu reads "
                               f"version {SCHEMA_VERSION}")
        with warnings.catch_warnings():
            # never drop an imaginary part, never cast NaN to a node number
            warnings.simplefilter("error", np.exceptions.ComplexWarning)
            warnings.simplefilter("error", RuntimeWarning)
            return _read(p, f, version, with_data)
    except (KeyError, OSError, ValueError, TypeError, IndexError, AttributeError,
            RuntimeWarning) as err:
        # an object missing, or of another type or shape than the schema's
        if isinstance(err, RunFileError):
            raise
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise RunFileError(f"{p}: damaged run file: {first}") from err
    finally:
        f.close()


def iter_record_data(path: str | Path, indices: Sequence[int] | None = None
                     ) -> Iterator[tuple[int, NDArray[np.float64]]]:
    """The samples of a run file's records, one record at a time: ``(index, data)``.

    ``data`` is (n_channels, n_samples) float64, force (N) then responses (m/s^2), as in
    :attr:`RecordTable.data`; ``indices`` picks records (default: every complete one, in
    order). Only one record is in memory at a time, whatever the run's length. Raises
    :class:`RunFileError` (one line) when the file cannot be read.
    """
    p = Path(path)
    f = _open(p)
    try:
        try:
            rec = f["records"]
            ds = rec["data"]
            n = min([rec[c].shape[0] for c in _COLUMNS] + [ds.shape[0]])
            if ds.ndim != 3 or ds.dtype.kind != "f":
                raise RunFileError(f"{p}: damaged run file: /records/data is {ds.dtype} of "
                                   f"shape {ds.shape}, expected float (records, channels, "
                                   "samples)")
        except (KeyError, OSError, ValueError, TypeError, AttributeError) as err:
            if isinstance(err, RunFileError):
                raise
            raise RunFileError(f"{p}: damaged run file: {str(err).splitlines()[0]}") from err
        for i in range(n) if indices is None else indices:
            if not 0 <= i < n:
                raise RunFileError(f"{p}: no record {i} (the file holds {n})")
            yield int(i), np.asarray(ds[i], dtype=float)
    finally:
        f.close()


def _check_shapes(p: Path, rec: h5py.Group, n_channels: int) -> None:
    """Each record column one value a record, of its kind; ``data`` (records, channels, samples)."""
    for name, (dtype, _) in _COLUMNS.items():
        ds = rec[name]
        if ds.ndim != 1 or ds.dtype.kind != np.dtype(dtype).kind:
            raise RunFileError(f"{p}: damaged run file: /records/{name} is {ds.dtype} of shape "
                               f"{ds.shape}, expected {np.dtype(dtype)} of shape (records,)")
    data = rec["data"]
    if data.ndim != 3 or data.shape[1] != n_channels or data.dtype.kind != "f":
        raise RunFileError(f"{p}: damaged run file: /records/data is {data.dtype} of shape "
                           f"{data.shape}, expected float (records, {n_channels}, samples)")


def _read(p: Path, f: h5py.File, version: int, with_data: bool) -> RunData:
    ch = f["channels"]
    names = [_str(x) for x in ch["name"][()]]
    channels = tuple(
        ChannelInfo(n, _str(d), _str(q), _str(u), float(s), float(r), bool(i), int(nd),
                    (float(v[0]), float(v[1]), float(v[2])))
        for n, d, q, u, s, r, i, nd, v in zip(
            names, ch["device"][()], ch["quantity"][()], ch["unit"][()], ch["sensitivity"][()],
            ch["range"][()], ch["iepe"][()], ch["node"][()], ch["direction"][()], strict=True))
    rec = f["records"]
    _check_shapes(p, rec, len(names))
    n = min(rec[c].shape[0] for c in _COLUMNS)  # rows complete in every column
    n = min(n, rec["data"].shape[0])
    data = rec["data"][:n] if with_data else np.zeros((0, *rec["data"].shape[1:]))
    raw = sync = None
    if "force_raw" in rec and with_data:
        raw = rec["force_raw"][:n]
    if "sync" in rec and with_data:
        sync = rec["sync"][:n]
    fs_raw = float(rec.attrs.get("fs_raw", 0.0))
    records = RecordTable(
        data=np.asarray(data, dtype=float), fs=float(rec.attrs["fs"]),
        point=rec["point"][:n], time=rec["time"][:n], peak_force=rec["peak_force"][:n],
        auto_accepted=rec["auto_accepted"][:n].astype(bool),
        reason=tuple(_str(x) for x in rec["reason"][:n]),
        override=tuple(_OVERRIDE_NAMES.get(int(x), "") for x in rec["override"][:n]),
        bad_frames=rec["bad_frames"][:n], missing=rec["missing"][:n],
        force_raw=raw, fs_raw=fs_raw,
        force_alignment=_str(rec.attrs.get("force_alignment",
                                           "host-timed" if fs_raw else "same-device")),
        sync_channel=_str(rec.attrs.get("sync_channel", "")), sync=sync,
        sync_offset=rec["sync_offset"][:n] if "sync_offset" in rec else None)
    nt = f["notes"]
    k = min(nt["time"].shape[0], nt["text"].shape[0])
    notes = tuple((float(t), _str(x)) for t, x in zip(nt["time"][:k], nt["text"][:k],
                                                     strict=True))
    geometry = Geometry(f["geometry/node_ids"][()], f["geometry/xyz"][()])
    stored = None
    if "frf" in f:
        g = f["frf"]
        attrs = {**g.attrs, "n_averages": g["n_averages"][()].tolist()}
        stored = Measurement(FRFSet(
            g["freq"][()], g["H"][()], g["resp_nodes"][()], g["resp_dirs"][()],
            g["exc_nodes"][()], g["exc_dirs"][()], geometry,
            g["coherence"][()] if "coherence" in g else None),
            Provenance.restored(attrs, "estimated"), p.name)
    result = json.loads(_str(f["result"][()])) if "result" in f else None
    mounts = _read_mounts(p, f["mounts"]) if "mounts" in f else None
    state = _str(f.attrs.get("state", ""))
    return RunData(
        path=str(p), schema_version=version,
        state="interrupted" if state == "running" else state,
        message=_str(f.attrs.get("message", "")), created=_str(f.attrs.get("created", "")),
        method=_str(f.attrs.get("method", "")),
        plan_data=json.loads(_str(f["plan"][()])),
        station_data=json.loads(_str(f["station"][()])),
        channels=channels, geometry=geometry, records=records, notes=notes, measurement=stored,
        result=result, mounts=mounts)


def _read_mounts(p: Path, g: h5py.Group) -> MountsFile:
    data = {"crank_axis": g["crank_axis"][()].tolist(),
            "mount": [{"name": _str(n), "position": pos.tolist(), "axes": ax.tolist()}
                      for n, pos, ax in zip(g["name"][()], g["position"][()], g["axes"][()],
                                            strict=True)]}
    try:
        return mounts_from_dict(data, f"{p} /mounts")
    except MountsFileError as err:
        raise RunFileError(str(err)) from err


def run_mounts(path: str | Path) -> MountsFile | None:
    """The mounts table of a run file (None when it has none or ``path`` is no run file:
    an FRF file); raises :class:`RunFileError` (one line) for a damaged run file."""
    p = Path(path)
    try:
        with h5py.File(p, "r") as f:
            if _str(f.attrs.get("format", "")) != FORMAT:
                return None
    except OSError:
        return None
    return read_run(p, with_data=False).mounts


def write_mounts(path: str | Path, mounts: MountsFile | None) -> None:
    """Store (or with None remove) the mounts table in the group ``/mounts`` of a run file
    that no writer has open (after :meth:`RunWriter.finish`); one-line :class:`RunFileError`."""
    p = Path(path)
    read_run(p, with_data=False)  # one-line error if foreign or damaged
    try:
        with _append(p) as f:
            if "mounts" in f:
                del f["mounts"]
            if mounts is None:
                return
            g = f.create_group("mounts")
            _array(g, "crank_axis", np.array(mounts.crank_axis), "1")
            _array(g, "name", np.array([m.name.encode("utf-8") for m in mounts.mounts],
                                       dtype="S64"), "n/a")
            _array(g, "position", np.array([m.position for m in mounts.mounts]), "m")
            _array(g, "axes", np.array([m.axes for m in mounts.mounts]), "1")
    except OSError as err:
        raise RunFileError(f"{p}: cannot write the mounts table: "
                           f"{str(err).splitlines()[0]}") from err
