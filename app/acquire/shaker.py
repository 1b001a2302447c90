"""The shaker procedure: per point attach, drive, ramp up, average blocks, ramp down.

Same listener events and run file as :class:`~app.acquire.hammer.HammerProcedure`
(records are blocks, ``/`` attribute ``method = "shaker"``). Per excitation point:
``on_next_point`` (the operator attaches the shaker there; with ``confirm_attach``
the run pauses until :meth:`resume`), waveform and level from the plan's
``[shaker]`` section, output on with its ramp, ``settle`` s streamed and dropped,
then blocks of ``nperseg`` samples from the front end (force sensor on its force
input, same clock), each stored and flushed, judged and averaged
(:mod:`app.acquire.blocks`), until ``averages`` blocks are accepted; then the
output ramps down and goes off.

The output goes off at the end of each point, on pause and stop, on any error
(the run pauses on a device error, fails on anything else) and when the
procedure dies: with an SG-1 (``shaker-scpi``) the device's watchdog is fed by
the procedure's own worker, after every read, not by a free-running thread, so a
worker that hangs (a listener blocking it, a deadlock) turns the output off
within ``heartbeat`` s as surely as a killed process does. So that the first
block's analysis is no slower than the others', the spectral kernels are loaded
and run once (:meth:`~app.acquire.blocks.BlockAnalysis.warm_up`) before any
device is opened.

Example
-------
>>> proc = ShakerProcedure(plan, bench.station, "run.h5",  # doctest: +SKIP
...                        listeners=[bench.shaker_operator])
>>> proc.start(); proc.wait()  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.acquire.analysis import analysis_measurement
from app.acquire.blocks import WINDOWS, BlockAnalysis, block_verdict
from app.acquire.events import HitRecord
from app.acquire.hammer import station_summary
from app.acquire.plan import ExcitationPoint, PlanError, TestPlan
from app.acquire.procedure import StopRequestedError
from app.acquire.recording import RecordingProcedure, resumed_plan
from app.acquire.shaker_io import BlockStream, ShakerDrive, ShakerDrives
from app.io.runfile import RunWriter, iter_record_data, read_run
from drivers.base import AcquisitionFrontEnd, ChannelConfig, ExcitationDevice
from drivers.errors import DeviceError
from drivers.registry import create_device, get_backend
from drivers.station import StationConfig
from processing.data import FRFSet
from processing.geometry import GeometryReport
from processing.identify import IdentificationResult
from processing.measurement import Measurement

__all__ = ["ShakerProcedure"]

logger = logging.getLogger(__name__)


class ShakerProcedure(RecordingProcedure):
    """Shaker acquisition of a test plan into one run file.

    Parameters
    ----------
    plan : TestPlan or None
        A plan with ``method = "shaker"`` (None with ``resume=True``: the file's).
    station : StationConfig
        The responses and a force channel on one front end, and an excitation device.
    path : str or Path
        The run file to write (or to continue with ``resume=True``).
    listeners : iterable
        :class:`~app.acquire.events.Listener`-like objects.
    resume : bool
        Continue the run in ``path``.
    device_options : mapping
        Per device name, keyword overrides for the driver.
    identify, partial : bool
        As for :class:`~app.acquire.hammer.HammerProcedure`.
    force_channel : str, optional
        The front end's force channel (default: its first).
    shaker : str, optional
        The station's excitation device (default: its only one).
    confirm_attach : bool
        Pause at each point until the operator resumes (the shaker is attached there).
    heartbeat : float, optional
        Watchdog time armed on an SG-1, s (the worker beats after every 0.1 s read); by
        default the shaker's ``heartbeat`` option in the station (a mock bench's is longer:
        its devices share the loaded host), else 0.5 s.
    """

    analysis: BlockAnalysis

    record_word = "block"

    def __init__(self, plan: TestPlan | None, station: StationConfig, path: str | Path, *,
                 listeners: Iterable[Any] = (), resume: bool = False,
                 device_options: Mapping[str, Mapping[str, Any]] | None = None,
                 identify: bool = True, partial: bool = False,
                 force_channel: str | None = None, shaker: str | None = None,
                 confirm_attach: bool = False, heartbeat: float | None = None) -> None:
        super().__init__(listeners)
        self.path = Path(path)
        self.resume_file = resume
        stored = read_run(self.path, with_data=False) if resume else None
        if stored is not None:
            plan = resumed_plan(stored, plan)
        elif plan is None:
            raise PlanError("give a test plan (or resume a run file)")
        if plan.method != "shaker":
            raise PlanError(f"{plan.source}: plan.method is {plan.method!r}; "
                            "this is the shaker procedure")
        self.plan, self.station = plan, station
        self.device_options = {k: dict(v) for k, v in (device_options or {}).items()}
        self.do_identify = identify
        self.confirm_attach = confirm_attach
        self.heartbeat = heartbeat
        self.geometry_report: GeometryReport = plan.check(station, strict=not partial)
        self._resolve(force_channel, shaker)
        if stored is not None:
            self._check_stored_channels(stored)
        self._check_limits()
        self.analysis = BlockAnalysis(plan, [c.name for c in self.rows], np.array(
            [c.full_scale for c in self.rows]),
            loader=lambda ids: iter_record_data(self.path, ids))
        self.frontend: AcquisitionFrontEnd | None = None
        self.drive: ShakerDrives | None = None
        self.stream: BlockStream | None = None
        self.writer: RunWriter | None = None
        self.point_index = 0
        self.frf: FRFSet | None = None
        self.measurement: Measurement | None = None
        self.result: IdentificationResult | None = None
        self.hits: list[HitRecord] = []
        self._auto: dict[int, bool] = {}
        self._t0 = time.monotonic()
        self._t_offset = 0.0

    # -- set-up ---------------------------------------------------------------------------------
    def startup(self) -> None:
        # the first spectrum loads the kernels: before the output is on and its watchdog armed
        self.analysis.warm_up()
        super().startup()

    def _resolve(self, force_choice: str | None, shaker_choice: str | None) -> None:
        st, plan = self.station, self.plan
        resp = plan.response_channels(st)
        self.ref_name = self._response_frontend()
        forces = [c for c in st.devices[self.ref_name].channels if c.quantity == "force"
                  and (force_choice is None or c.name == force_choice)]
        if not forces:
            which = f" {force_choice!r}" if force_choice else ""
            raise PlanError(f"{st.source}: no force channel{which} on front end "
                            f"{self.ref_name!r}: wire the shaker's force sensor to it (one "
                            "clock for force and responses)")
        n = plan.n_references
        shakers = [d.name for d in st.devices.values()
                   if issubclass(get_backend(d.backend), ExcitationDevice)
                   and (shaker_choice is None or d.name == shaker_choice)]
        if n > 1:  # several shakers at once: the first n force channels and shakers, in order
            if len(forces) < n or len(shakers) < n:
                raise PlanError(f"{st.source}: the plan drives {n} shakers at once; the "
                                f"station has {len(shakers)} excitation devices and "
                                f"{len(forces)} force channels on front end {self.ref_name!r}"
                                ": give each shaker its own force input")
        elif len(shakers) != 1:
            raise PlanError(f"{st.source}: " + (f"no excitation device {shaker_choice!r}"
                            if shaker_choice else f"{len(shakers)} excitation devices: "
                            "give one (shaker=...)" if shakers else
                            "no excitation device (a shaker backend such as shaker-scpi)"))
        self.force_channel = forces[0]
        self.rows: tuple[ChannelConfig, ...] = (*forces[:n], *resp)
        self.shaker_names = shakers[:n]
        self.shaker_name = shakers[0]

    def _check_limits(self) -> None:
        """Refuse (PlanError, one line) a ``[shaker]`` setting its shakers do not accept,
        before any device is opened and any run file created."""
        s, fs = self.plan.shaker, self.plan.record.fs
        # device setting -> the plan's key, its value in the device's unit, the unit
        values = {"level": ("shaker.level", s.level, "V"),
                  "f_start": ("shaker.f_start", s.f_start, "Hz"),
                  "f_stop": ("shaker.f_stop", s.f_stop, "Hz"),
                  "ramp": ("shaker.ramp", s.ramp, "s")}
        if s.waveform != "random":  # a chirp's and a burst's period is one block
            values["period"] = ("shaker.nperseg", s.nperseg / fs, "s")
        for name in self.shaker_names:
            cfg = self.station.devices[name]
            backend = get_backend(cfg.backend)
            limits = backend.setting_limits(cfg) if issubclass(backend, ExcitationDevice) \
                else {}
            for setting, (low, high) in limits.items():
                if setting not in values or low <= values[setting][1] <= high:
                    continue
                key, value, unit = values[setting]
                over = value > high
                what = (f"{key} = {s.nperseg} at record.fs = {fs:g} Hz is a {value:g} s period"
                        if setting == "period" else f"{key} {value:g} {unit} is")
                todo = ("the stored plan cannot run: start a new run" if self.resume_file
                        else f"{'lower' if over else 'raise'} {key}")
                raise PlanError(f"{self.plan.source}: {what} "
                                f"{'above' if over else 'below'} the "
                                f"{high if over else low:g} {unit} that {self.station.source} "
                                f"allows for shaker {name!r}: {todo}")

    def _open_devices(self) -> None:
        fe = create_device(self.station.devices[self.ref_name],
                           **self.device_options.get(self.ref_name, {}))
        if not isinstance(fe, AcquisitionFrontEnd):
            raise PlanError(f"{self.station.source}: {self.ref_name!r} is not a front end")
        self.frontend = fe
        fe.open()
        if fe.fs != self.plan.record.fs:
            raise PlanError(f"{self.plan.source}: record.fs is {self.plan.record.fs:g} Hz but "
                            f"front end {self.ref_name!r} runs at {fe.fs:g} Hz: make them equal")
        self.drive = ShakerDrives([])
        for name in self.shaker_names:
            cfg = self.station.devices[name]
            opts = dict(self.device_options.get(name, {}))
            if cfg.backend == "shaker-scpi":  # the worker feeds the watchdog (module doc)
                opts = {"ramp": self.plan.shaker.ramp, "heartbeat": 0.0, **opts}
            else:
                backend = get_backend(cfg.backend)
                if issubclass(backend, ExcitationDevice) and "ramp" in \
                        backend.setting_limits(cfg):  # a device that ramps: for how long
                    opts = {"ramp": self.plan.shaker.ramp, **opts}
            dev = create_device(cfg, **opts)
            if not isinstance(dev, ExcitationDevice):
                raise PlanError(f"{self.station.source}: {name!r} is not a shaker")
            heartbeat = (self.heartbeat if self.heartbeat is not None
                         else float(cfg.options.get("heartbeat", 0.5)))
            self.drive.drives.append(ShakerDrive(dev, self.plan, heartbeat))
        self.drive.should_stop = lambda: self.stop_asked
        self.drive.open()
        names = [c.name for c in fe.channels]
        self.stream = BlockStream(fe, [names.index(c.name) for c in self.rows], self.plan,
                                  self.drive.beat, samples=self._samples)

    def _samples(self, data: NDArray[np.float64]) -> None:
        self.emit_samples(data, self.plan.record.fs, [c.name for c in self.rows])

    def _open_file(self) -> None:
        s = self.plan.shaker
        if self.resume_file:
            run = read_run(self.path, with_data=False)
            self._check_stored_channels(run)
            self.writer = RunWriter.resume(self.path)
            rec = run.records
            self._keep_stored(rec)
            for i, data in iter_record_data(self.path, range(len(rec))):
                if self.stop_asked:  # a long run takes a while to read back: stop now
                    raise StopRequestedError
                self._replay_row(i, int(rec.point[i]), data, bool(rec.auto_accepted[i]),
                                 rec.override[i])
            self._t_offset = float(rec.time.max()) + 1.0 if len(rec) else 0.0
            return
        self.writer = RunWriter.create(
            self.path, plan_data=self.plan.to_dict(), station_data=station_summary(self.station),
            channels=self.rows, devices=[self.ref_name] * len(self.rows),
            geometry=self.plan.geometry(), fs=self.plan.record.fs, n_samples=s.nperseg,
            method="shaker", attrs={"waveform": s.waveform, "window": WINDOWS[s.waveform],
                                    "shaker": ",".join(self.shaker_names)})

    def _replay_row(self, i: int, point: int, data: NDArray[np.float64], stored_auto: bool,
                    override: str) -> None:
        v = self.analysis.add(i, point, data, override)
        auto = stored_auto and v is not None and v[0]
        self._auto[i] = auto
        self.analysis.set_used(i, v is not None and (override == "accept" if override else auto))

    # -- procedure ------------------------------------------------------------------------------
    def execute(self) -> None:
        assert self.stream is not None
        self.stream.start()
        while (d := self.next_to_do(
                range(len(self.plan.drives)),
                lambda d: self.analysis.n_used(d) >= self.plan.shaker.averages)) is not None:
            self._acquire_drive(d)
        self.stream.stop()
        self._complete()

    def _announce(self, points: list[ExcitationPoint]) -> None:
        """``on_next_point`` for each point driven now (shaker ``k`` at the ``k``-th)."""
        for point in points:
            self.emit("on_next_point", point)

    def _acquire_drive(self, d: int) -> None:
        """Blocks of drive ``d`` (its excitation points, one shaker each) until enough."""
        assert self.stream is not None and self.drive is not None
        points = [self.plan.excitations[j] for j in self.plan.drives[d]]
        self.point_index = d
        self._announce(points)
        if self.confirm_attach:
            where = " and ".join(p.label for p in points)
            self.pause_for(f"attach the shaker{'s' if len(points) > 1 else ''} at {where}, "
                           "then resume")
        need = self.plan.shaker.averages
        while self.analysis.n_used(d) < need:
            self.poll()
            try:
                if not self.drive.driving:
                    self.drive.on(self.stream)
                    self.stream.restart_blocks()
                block = self.stream.next_block()
                problem = self.drive.check()
            except DeviceError as err:
                self._stop_drive_quietly()
                self.pause_for(f"{err}; acquired blocks are saved. Check the devices, "
                               "then resume")
                self._announce(points)
                continue
            if problem and block is None:  # the block in progress, NaN-padded: kept, unused
                block = self.stream.take_partial()
            if block is not None:
                self._store(d, block, problem)
            if problem:
                self._stop_drive_quietly()
                self.pause_for(f"{problem}; acquired blocks are saved. Check the shaker, "
                               "then resume")
                self._announce(points)
        self.drive.off(self.stream)

    def _stop_drive_quietly(self) -> None:
        if self.drive is not None:
            self.drive.emergency_off()

    def on_pause(self) -> None:
        self._stop_drive_quietly()
        if self.stream is not None:
            self.stream.stop()

    def on_resume(self) -> None:
        self._close_devices()
        self._open_devices()
        assert self.stream is not None
        self.stream.start()

    def _close_devices(self) -> None:
        if self.drive is not None:
            self.drive.shutdown()  # output off first
            self.drive = None
        if self.frontend is not None:
            try:
                self.frontend.shutdown()
            except DeviceError as err:
                logger.warning("%s: shutdown failed: %s", self.frontend.name, err)
            self.frontend = None
        self.stream = None

    # -- blocks ---------------------------------------------------------------------------------
    def _store(self, d: int, data: NDArray[np.float64], problem: str) -> None:
        """Store, judge and average a block of drive ``d``."""
        assert self.writer is not None and self.stream is not None
        hit_id = self.writer.n_records
        v = self.analysis.add(hit_id, d, data)
        auto, reason, peak = v if v is not None else block_verdict(
            data, self.analysis.names, self.analysis.ranges, self.plan.n_references)
        if problem:
            auto, reason = False, problem
        missing = int(np.count_nonzero(np.isnan(data).any(axis=0)))
        bad = self.stream.take_bad_frames()
        t = time.monotonic() - self._t0 + self._t_offset
        self.writer.add_record(d, data, time=t, peak_force=peak, auto_accepted=auto,
                               reason=reason, bad_frames=bad, missing=missing)
        self._auto[hit_id] = auto
        self.analysis.set_used(hit_id, auto and v is not None)
        self._report(HitRecord(hit_id, d, t, peak, auto, reason, "", bad, missing,
                               data=data, fs=self.plan.record.fs))

    def _records_needed(self) -> int:
        return self.plan.shaker.averages

    def record_values(self) -> int:
        return len(self.rows) * self.plan.shaker.nperseg

    def frf_lines(self) -> int:
        return self.plan.shaker.nperseg // 2 + 1

    def _bad_frames(self) -> int:
        return self.frontend.health.bad_frames if self.frontend is not None else 0

    def apply_override(self, hit_id: int, override: str) -> None:
        if self.writer is None or not 0 <= hit_id < self.writer.n_records:
            self.emit("on_error", f"no block {hit_id} to override")
            return
        old = self.hits[hit_id] if hit_id < len(self.hits) else None
        point = old.point if old is not None else self.analysis.point_of(hit_id)
        data = next(iter(iter_record_data(self.path, [hit_id])))[1]
        if override == "accept" and not np.all(np.isfinite(data)):
            self.emit("on_error", f"block {hit_id} lost samples and cannot be used")
            return
        self.writer.set_override(hit_id, override)
        auto = self._auto.get(hit_id, False)
        self.analysis.add(hit_id, point, data, override)
        self.analysis.set_used(hit_id, override == "accept" or (not override and auto))
        if old is not None:
            self._report(HitRecord(**{**old.__dict__, "override": override}))

    def _complete(self) -> None:
        assert self.writer is not None
        self._finish_run(analysis_measurement(self.analysis, self.plan.geometry(),
                                              *self.plan.response_dofs(self.station),
                                              self.path.name))
