"""The hammer procedure: triggered hits, automatic verdicts, overrides, next point when done.

Example
-------
>>> proc = HammerProcedure(plan, station, "run.h5", listeners=[my_listener])  # doctest: +SKIP
>>> proc.start(); proc.wait()  # doctest: +SKIP
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.acquire.analysis import RunAnalysis, analysis_measurement, host_timed, margin_samples
from app.acquire.events import HitRecord
from app.acquire.plan import ExcitationPoint, PlanError, TestPlan
from app.acquire.procedure import StopRequestedError
from app.acquire.recording import RecordingProcedure, resumed_plan
from app.acquire.streams import HitStreams, RawHit
from app.io.runfile import RunWriter, iter_record_data, read_run
from drivers.base import AcquisitionFrontEnd, ChannelConfig
from drivers.errors import DeviceError
from drivers.registry import create_device
from drivers.station import StationConfig
from processing.data import FRFSet
from processing.geometry import GeometryReport
from processing.identify import IdentificationResult
from processing.measurement import Measurement

__all__ = ["HammerProcedure", "station_summary"]

logger = logging.getLogger(__name__)


def station_summary(station: StationConfig) -> dict[str, Any]:
    """The station as JSON-able data for the run file (its ``[extra]`` and ``[simulation]``
    tables too)."""
    out: dict[str, Any] = {"name": station.name, "source": station.source, "devices": {},
                           "extra": json.loads(json.dumps(station.extra, default=str)),
                           "simulation": json.loads(json.dumps(station.simulation, default=str))}
    for name, dev in station.devices.items():
        out["devices"][name] = {
            "backend": dev.backend, "fs": dev.fs, "transport": asdict(dev.transport),
            "options": dict(dev.options),
            "channels": [asdict(c) for c in dev.channels],
        }
    return out


class HammerProcedure(RecordingProcedure):
    """Impact-hammer acquisition of a test plan into one run file.

    Parameters
    ----------
    plan : TestPlan or None
        The plan (None with ``resume=True``: the plan stored in the file).
    station : StationConfig
        Devices and channels; the responses must all be on one front end, and the
        station must have a force channel (the hammer's digitiser, or a front-end input).
    path : str or Path
        The run file to write (or to continue with ``resume=True``).
    listeners : iterable
        :class:`~app.acquire.events.Listener`-like objects.
    resume : bool
        Continue the run in ``path`` from its state.
    device_options : mapping
        Per device name, keyword overrides for the driver (e.g. ``stall_timeout``).
    identify : bool
        Identify inertia and stiffness when every point is done.
    partial : bool
        Accept a plan whose excitations or responses cannot span the 6 rigid-body DOFs
        (a partial run: FRFs only, no identification).
    force_channel : str, optional
        Name of the station's force channel to use. Default: a force input of the
        responses' front end (same clock, phase exact), else the hammer digitiser's,
        aligned by :mod:`drivers.sync`.
    sync_channel : str, optional
        With the force from a separate device (the hammer's digitiser): the front end's
        channel that records the same force (a common channel), on which every hit is
        aligned to a fraction of a sample. Default: the front end's force input, if any.
        Without one the alignment is host-timed (about 1 ms: the mass line's phase is
        ruined), and a run that should identify is refused (:class:`PlanError`);
        ``identify=False`` records such FRFs anyway.
    """

    analysis: RunAnalysis

    def __init__(self, plan: TestPlan | None, station: StationConfig, path: str | Path, *,
                 listeners: Iterable[Any] = (), resume: bool = False,
                 device_options: Mapping[str, Mapping[str, Any]] | None = None,
                 identify: bool = True, force_channel: str | None = None,
                 partial: bool = False, sync_channel: str | None = None) -> None:
        super().__init__(listeners)
        self.path = Path(path)
        self.resume_file = resume
        stored = read_run(self.path, with_data=False) if resume else None
        if stored is not None:
            plan = resumed_plan(stored, plan)
        elif plan is None:
            raise PlanError("give a test plan (or resume a run file)")
        if plan.method != "hammer":
            raise PlanError(f"{plan.source}: plan.method is {plan.method!r}; "
                            "this is the hammer procedure")
        self.plan = plan
        self.station = station
        self.device_options = {k: dict(v) for k, v in (device_options or {}).items()}
        self.do_identify = identify
        self._force_choice = force_channel
        self._sync_choice = sync_channel
        self.geometry_report: GeometryReport = plan.check(station, strict=not partial)
        self._resolve_channels()
        if stored is not None:
            self._check_stored_channels(stored)
        if self.force_alignment == "host-timed" and identify and self.geometry_report.ok:
            raise PlanError(f"{station.source}: {host_timed(self.force_name, self.ref_name)}")
        self.devices: dict[str, AcquisitionFrontEnd] = {}
        self.writer: RunWriter | None = None
        self.analysis = RunAnalysis(plan, [c.name for c in self.rows], np.array(
            [c.full_scale for c in self.rows]), loader=self._load_records)
        self.point_index = 0
        self.frf: FRFSet | None = None
        self.measurement: Measurement | None = None
        self.result: IdentificationResult | None = None
        self.hits: list[HitRecord] = []
        self._streams: HitStreams | None = None
        self._t0 = time.monotonic()
        self._t_offset = 0.0

    # -- set-up ---------------------------------------------------------------------------------
    def _resolve_channels(self) -> None:
        st, plan = self.station, self.plan
        resp = plan.response_channels(st)
        self.ref_name = self._response_frontend()
        forces = [(d.name, c) for d in st.devices.values() for c in d.channels
                  if c.quantity == "force"]
        if not forces:
            raise PlanError(f"{st.source}: no force channel: add the hammer's "
                            "(quantity = \"force\")")
        if self._force_choice is not None:
            forces = [f for f in forces if f[1].name == self._force_choice]
            if not forces:
                raise PlanError(f"{st.source}: no force channel {self._force_choice!r}")
        same = [f for f in forces if f[0] == self.ref_name]  # same clock: phase exact
        self.force_name, self.force_channel = (same or forces)[0]
        self.rows: tuple[ChannelConfig, ...] = (self.force_channel, *resp)
        self.row_devices = (self.force_name, *(self.ref_name for _ in resp))
        self.sync_channel: ChannelConfig | None = None
        if self.force_name == self.ref_name:
            self.force_alignment = "same-device"
            return
        common = [c for c in st.devices[self.ref_name].channels if c.quantity == "force"]
        if self._sync_choice is not None:
            common = [c for c in common if c.name == self._sync_choice]
            if not common:
                raise PlanError(f"{st.source}: sync channel {self._sync_choice!r} must be a "
                                f"force input of front end {self.ref_name!r} (the hammer's "
                                "force signal, split to both devices)")
        self.sync_channel = common[0] if common else None
        self.force_alignment = "common-channel" if common else "host-timed"

    def _open_devices(self) -> None:
        for name in dict.fromkeys((self.ref_name, self.force_name)):
            dev = create_device(self.station.devices[name], **self.device_options.get(name, {}))
            if not isinstance(dev, AcquisitionFrontEnd):
                raise PlanError(f"{self.station.source}: device {name!r} is not an acquisition "
                                "device")
            self.devices[name] = dev
            dev.open()
        ref, fdev = self.devices[self.ref_name], self.devices[self.force_name]
        rec = self.plan.record
        if ref.fs != rec.fs:
            raise PlanError(f"{self.plan.source}: record.fs is {rec.fs:g} Hz but front end "
                            f"{self.ref_name!r} runs at {ref.fs:g} Hz: make them equal")
        names = [c.name for c in ref.channels]
        sync = None if self.sync_channel is None else names.index(self.sync_channel.name)
        self._streams = HitStreams(
            ref, [names.index(c.name) for c in self.rows[1:]], fdev,
            [c.name for c in fdev.channels].index(self.force_channel.name),
            rec.n_pretrigger, rec.n_samples, rec.trigger_level, sync_row=sync,
            samples=self._samples)

    def _samples(self, data: NDArray[np.float64], t_first: float | None) -> None:
        self.emit_samples(data, self.plan.record.fs, [c.name for c in self.rows], t_first)

    def _open_file(self) -> None:
        rec = self.plan.record
        margin = margin_samples(rec.fs)
        n_store = rec.n_samples + 2 * margin
        if self.resume_file:
            run = read_run(self.path, with_data=False)
            self._check_stored_channels(run)
            self.writer = RunWriter.resume(self.path)
            recs = run.records
            self._keep_stored(recs)
            # the points' averages rebuilt from the stored records, read one at a time
            for i, data in iter_record_data(self.path, range(len(recs))):
                if self.stop_asked:  # a long run takes a while to read back: stop now
                    raise StopRequestedError
                res = self.analysis.add(i, int(recs.point[i]), data, recs.override[i])
                self.analysis.set_used(i, bool(recs.accepted[i]) and res is not None)
            self._t_offset = float(recs.time.max()) + 1.0 if len(recs) else 0.0
            return
        assert self._streams is not None
        fdev = self.devices[self.force_name]
        separate = self.force_name != self.ref_name
        fs_raw = fdev.fs if separate else 0.0
        n_raw = self._streams.raw_length(n_store) if separate else 0
        self.writer = RunWriter.create(
            self.path, plan_data=self.plan.to_dict(), station_data=station_summary(self.station),
            channels=self.rows, devices=self.row_devices, geometry=self.plan.geometry(),
            fs=rec.fs, n_samples=n_store, method="hammer", fs_raw=fs_raw, n_raw=n_raw,
            force_alignment=self.force_alignment,
            sync_channel="" if self.sync_channel is None else self.sync_channel.name)

    # -- procedure ------------------------------------------------------------------------------
    def execute(self) -> None:
        assert self._streams is not None
        self._start_streams()
        # points left incomplete by a later override (a hit rejected there) are visited again
        while (point := self.next_to_do(
                self.plan.excitations,
                lambda p: self.analysis.n_used(p.index) >= self.plan.hits)) is not None:
            self._acquire_point(point)
        self._streams.stop()
        self._complete()

    def _acquire_point(self, point: ExcitationPoint) -> None:
        assert self._streams is not None
        self.point_index = point.index
        self.emit("on_next_point", point)
        while self.analysis.n_used(point.index) < self.plan.hits:
            self.poll()
            try:
                self._streams.read()
                trig = self._streams.next_trigger()
                if trig is None:
                    continue
                raw = self._streams.record(trig, margin_samples(self.plan.record.fs))
            except DeviceError as err:
                self.pause_for(f"{err}; acquired hits are saved. Check the device, "
                               "then resume")
                self.emit("on_next_point", point)
                continue
            self._store(point, raw)

    def _start_streams(self) -> None:
        assert self._streams is not None
        self._streams.start()
        self._streams.settle()

    def on_pause(self) -> None:
        if self._streams is not None:
            self._streams.stop()

    def on_resume(self) -> None:
        # a device that stopped answering may still stream or be half configured:
        # release every device and open it again (each driver's open() sends STOP first)
        self._close_devices()
        self._open_devices()
        self._start_streams()

    def _close_devices(self) -> None:
        for dev in self.devices.values():
            try:
                dev.shutdown()
            except DeviceError as err:
                logger.warning("%s: shutdown failed: %s", dev.name, err)
        self.devices.clear()

    # -- hits -----------------------------------------------------------------------------------
    def _store(self, point: ExcitationPoint, raw: RawHit) -> None:
        assert self.writer is not None
        hit_id = self.writer.n_records
        res = self.analysis.add(hit_id, point.index, raw.data)
        v = res.verdicts[0] if res is not None and res.verdicts else None
        auto = not raw.problem and v is not None and v.accepted
        if raw.problem:
            reason = f"{raw.problem}: hit not used"
        elif v is None:
            reason = "no trigger in the aligned record"
        else:
            reason = v.reason
        src = raw.force_raw if raw.force_raw is not None else raw.data[0]
        finite = src[np.isfinite(src)]
        peak = v.peak_force if v is not None else (float(finite.max()) if finite.size
                                                    else float("nan"))
        t = time.monotonic() - self._t0 + self._t_offset
        self.writer.add_record(point.index, raw.data, time=t, peak_force=peak,
                               auto_accepted=auto, reason=reason, bad_frames=raw.bad_frames,
                               missing=raw.missing, force_raw=raw.force_raw, sync=raw.sync,
                               sync_offset=raw.sync_offset)
        self.analysis.set_used(hit_id, auto)
        self._report(HitRecord(hit_id, point.index, t, peak, auto, reason, "", raw.bad_frames,
                               raw.missing, data=raw.data, fs=self.plan.record.fs))

    def _load_records(self, ids: Sequence[int]) -> Iterator[tuple[int, NDArray[np.float64]]]:
        """Stored records ``ids`` read back from the run file, one at a time."""
        return iter_record_data(self.path, ids)

    def _records_needed(self) -> int:
        return self.plan.hits

    def record_values(self) -> int:
        rec = self.plan.record
        n_store = rec.n_samples + 2 * margin_samples(rec.fs)
        n = len(self.rows) * n_store
        if self.sync_channel is not None:  # the common channel's record and its offset
            n += n_store + 1
        if self.force_name != self.ref_name:  # the hammer digitiser's own samples (at most)
            fs_raw = self.station.devices[self.force_name].fs or rec.fs
            n += int(np.ceil(n_store * fs_raw / rec.fs)) + 256
        return n

    def frf_lines(self) -> int:
        return self.plan.record.n_samples // 2 + 1

    def _bad_frames(self) -> int:
        return self._streams.bad_frames if self._streams is not None else 0

    def apply_override(self, hit_id: int, override: str) -> None:
        if self.writer is None or not 0 <= hit_id < self.writer.n_records:
            self.emit("on_error", f"no hit {hit_id} to override")
            return
        old = self.hits[hit_id] if hit_id < len(self.hits) else None
        run_point = old.point if old is not None else self.analysis.point_of(hit_id)
        data = next(iter(self._load_records([hit_id])))[1]
        res = self.analysis.add(hit_id, run_point, data, override)
        if override == "accept" and res is None:
            self.emit("on_error", f"hit {hit_id} lost samples and cannot be used")
            return
        self.writer.set_override(hit_id, override)
        auto = old.auto_accepted if old is not None else False
        self.analysis.set_used(hit_id, override == "accept" or (not override and auto))
        if old is not None:
            self._report(HitRecord(**{**old.__dict__, "override": override}))

    def _complete(self) -> None:
        """All points done: FRFs, identification, final state in the file."""
        assert self.writer is not None
        m = analysis_measurement(self.analysis, self.plan.geometry(),
                                 *self.plan.response_dofs(self.station), self.path.name)
        assert len(self.rows) - 1 == m.frf.H.shape[0]
        self._finish_run(m)
