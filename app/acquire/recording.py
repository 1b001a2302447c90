"""What the hammer and shaker procedures share: a run file, its notes and its last step.

:class:`RecordingProcedure` is a :class:`~app.acquire.procedure.Procedure` that writes
one run file (:class:`app.io.runfile.RunWriter`). Subclasses open their devices in
:meth:`_open_devices` and the file in :meth:`_open_file`, close their devices in
:meth:`_close_devices`, say how many records a point needs and how many frames went bad,
report each record with :meth:`_report`, and call :meth:`_finish_run` with the run's FRFs
when every point is done. They also say what one record holds (:meth:`record_values`) and
how many lines their FRFs have (:meth:`frf_lines`): the run's start refuses a run whose file
cannot fit on its disk (:func:`app.acquire.space.check_disk_space`).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from app.acquire.analysis import RecordAnalysis, anti_aliased
from app.acquire.events import HitRecord, PointFRF, Progress
from app.acquire.plan import PlanError, TestPlan, parse_plan, plan_differences
from app.acquire.procedure import Procedure
from app.acquire.space import check_disk_space
from app.io.runfile import RecordTable, RunData, RunWriter
from drivers.base import ChannelConfig
from drivers.station import StationConfig
from processing.data import FRFSet, InputError
from processing.geometry import GeometryError, GeometryReport
from processing.identify import IdentificationResult, fit
from processing.measurement import Measurement

__all__ = ["RecordingProcedure", "resumed_plan"]

logger = logging.getLogger(__name__)


def resumed_plan(run: RunData, plan: TestPlan | None, name: str | None = None,
                 fix: str = "resume with the stored plan") -> TestPlan:
    """The plan stored in ``run`` (a run file to resume); ``plan``, when given, must not
    differ from it (:func:`~app.acquire.plan.plan_differences`), or :class:`PlanError`
    says where, in one line ending with ``fix`` (how to resume). ``name`` is the run file's
    name in it (default its path). A stored plan that no longer parses is refused too."""
    path = Path(run.path)
    try:
        stored = parse_plan(run.plan_data, f"{path}:/plan")
    except PlanError as err:
        raise PlanError(f"{path} cannot be resumed (start a new run): its stored plan is "
                        f"refused: {err}") from err
    if plan is None:
        return stored
    diff = plan_differences(stored, plan, name or str(path), Path(plan.source).name)
    if diff:
        raise PlanError(f"{'; '.join(diff)}: {fix} or start a new run")
    return stored
    diff = plan_differences(stored, plan, name or str(path), Path(plan.source).name)
    if diff:
        raise PlanError(f"{'; '.join(diff)}: resume with the stored plan or start a new run")
    return stored


class RecordingProcedure(Procedure):
    """A procedure that records into a run file (see the module docstring)."""

    #: what one record is called in messages: "hit" (hammer) or "block" (shaker)
    record_word = "hit"

    plan: TestPlan
    station: StationConfig
    path: Path  # the run file
    resume_file: bool  # continue the run in it
    analysis: RecordAnalysis  # RunAnalysis (hammer) or BlockAnalysis (shaker)
    ref_name: str  # the front end of the responses
    rows: tuple[ChannelConfig, ...]  # the channels of every record: forces, then responses
    hits: list[HitRecord]
    point_index: int
    writer: RunWriter | None
    frf: FRFSet | None
    #: the run's measurement once every point is done (all lines; the fit cuts at fs / 2.56)
    measurement: Measurement | None
    result: IdentificationResult | None
    do_identify: bool
    geometry_report: GeometryReport
    _t0: float
    _t_offset: float

    def _open_devices(self) -> None:
        """Create, open and configure the devices; subclasses own their devices."""
        raise NotImplementedError

    def _open_file(self) -> None:
        """Create (or reopen, to resume) the run file."""
        raise NotImplementedError

    def _close_devices(self) -> None:
        """Shut every device down (idempotent)."""
        raise NotImplementedError

    def _records_needed(self) -> int:
        """Accepted records each point needs."""
        raise NotImplementedError

    def _bad_frames(self) -> int:
        """Corrupted frames seen so far."""
        raise NotImplementedError

    def record_values(self) -> int:
        """Values (float64) stored for one record: every row's samples, and the hammer's own
        force or the common channel when the run keeps them."""
        raise NotImplementedError

    def frf_lines(self) -> int:
        """Frequency lines of the FRFs stored when the run finishes."""
        raise NotImplementedError

    def records_needed(self) -> int:
        """Accepted records each point (or drive) needs."""
        return self._records_needed()

    def startup(self) -> None:
        check_disk_space(self)  # before any device opens or the file is created
        self._open_devices()
        self._open_file()
        self._t0 = time.monotonic()
        # the counters as the run starts (a resumed run's points done before it included)
        need = self._records_needed()
        self.point_index = next((d for d in range(len(self.plan.drives))
                                 if self.analysis.n_used(d) < need), self.point_index)
        self._emit_progress()

    def _check_stored_channels(self, run: RunData) -> None:
        """A run resumes on the channels its records hold (PlanError before any device
        opens, naming the station the run was acquired with)."""
        stored = tuple(c.name for c in run.channels)
        rows = tuple(c.name for c in self.rows)
        if stored != rows:
            where = run.station_data.get("source") or run.station_data.get("name") or "?"
            raise PlanError(f"{run.path}: recorded channels {', '.join(stored)} differ from "
                            f"the station's {', '.join(rows)}: resume on the station the run "
                            f"was acquired with ({where})")

    def _keep_stored(self, records: RecordTable) -> None:
        """The hits (blocks) of a resumed run's file, without samples, as :attr:`hits`."""
        need, fs = self._records_needed(), self.plan.record.fs
        self.hits = [HitRecord(i, int(records.point[i]), float(records.time[i]),
                               float(records.peak_force[i]), bool(records.auto_accepted[i]),
                               records.reason[i], records.override[i],
                               int(records.bad_frames[i]), int(records.missing[i]),
                               point_needed=need, fs=fs) for i in range(len(records))]

    def _response_frontend(self) -> str:
        """Name of the one device that records every response of the plan."""
        st, plan = self.station, self.plan
        owner = {c.name: d.name for d in st.devices.values() for c in d.channels}
        names = sorted({owner[c.name] for c in plan.response_channels(st)})
        if len(names) != 1:
            raise PlanError(f"{plan.source}: the responses are on devices {', '.join(names)};"
                            " put them on one front end")
        return names[0]

    def _report(self, hit: HitRecord) -> None:
        """Keep ``hit`` (new, or a re-judged one) without its samples (they are in the run
        file), then send on_hit (with the samples), the point's FRF and the progress."""
        hit = HitRecord(**{**hit.__dict__, "point_accepted": self.analysis.n_used(hit.point),
                           "point_needed": self._records_needed()})
        kept = HitRecord(**{**hit.__dict__, "data": None})  # the samples are in the run file
        if hit.hit_id < len(self.hits):
            self.hits[hit.hit_id] = kept
        else:
            self.hits.append(kept)
        if not hit.accepted:
            logger.info("%s %d at %s rejected: %s", self.record_word, hit.hit_id, hit.point,
                        hit.reason)
        self.emit("on_hit", hit)
        res = self.analysis.point(hit.point)
        self.emit("on_frf", PointFRF(
            hit.point, res.freq if res is not None else np.zeros(0),
            None if res is None or res.H is None else res.H[:, 0, :],
            None if res is None or res.coherence is None else res.coherence[:, 0, :],
            0 if res is None else res.n_accepted))
        self._emit_progress()

    def _emit_progress(self) -> None:
        """``on_progress`` with the counters of the whole run file."""
        need = self._records_needed()
        done = sum(self.analysis.n_used(d) >= need for d in range(len(self.plan.drives)))
        self.emit("on_progress", Progress(
            self.point_index, len(self.plan.drives), self.analysis.n_used(self.point_index),
            need, len(self.hits), sum(h.accepted for h in self.hits), self._bad_frames(),
            time.monotonic() - self._t0, done))

    def shutdown(self) -> None:
        """Devices off, then the file closed with the run's state unless it is complete."""
        self._close_devices()
        if self.writer is not None:
            state = self.state.value if self.state.value != "running" else "failed"
            if self.frf is None:
                self.writer.finish(state, self.message)
            self.writer = None

    def apply_note(self, text: str) -> None:
        if self.writer is not None:
            self.writer.add_note(text, time.monotonic() - self._t0 + self._t_offset)

    def _finish_run(self, measurement: Measurement) -> None:
        """Store the FRFs and, when the plan allows, the identification (the fit every view
        makes of the run file: :func:`processing.identify.fit` of its lines up to fs / 2.56);
        the run is done."""
        assert self.writer is not None
        message, result_json, result = "", None, None
        if self.do_identify and self.geometry_report.ok:
            try:
                cut = anti_aliased(measurement)
                result = fit(cut, preliminary=lambda r: self.emit("on_result", cut, r, False))
                result_json = result.to_json()
            except (InputError, GeometryError) as err:
                message = f"identification failed: {err}"
                self.message = message  # the run finishes, with why it has no result
                self.emit("on_error", message)
        # a run is done once its FRFs are on the disk (a full disk fails it: shutdown then
        # finds no FRFs and the writer says why)
        self.writer.finish("finished", message, measurement, result_json)
        self.measurement, self.frf, self.result = measurement, measurement.frf, result
        self.writer = None
        if result is not None:
            self.emit("on_result", cut, result, True)
