"""Acquisition view: run the plan on the station, hit by hit (hammer) or block by block
(shaker), as the plan's method says.

The next point is named and highlighted; each hit or block appears with its automatic
verdict (accepted, double hit, overload, output off, ...) and can be accepted or rejected
by the operator; the live force and accelerations scroll continuously while the devices
stream; the force record of the latest (or selected) hit or block and the current point's
averaged FRF magnitude and coherence update with each; the plan's progress shows; pause,
resume and stop. Stop, a device error and closing the window stop the shaker's output at
once (the procedure turns it off and shuts the devices down); everything acquired stays in
the run file.
"""

from __future__ import annotations

import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6 import QtCore, QtWidgets

from app.acquire.analysis import anti_aliased
from app.acquire.events import HitRecord, PointFRF, Progress, RunState
from app.acquire.hammer import HammerProcedure
from app.acquire.plan import TestPlan
from app.acquire.shaker import ShakerProcedure
from app.gui.acquisition_bridge import AcquisitionBridge
from app.gui.session import Session
from app.gui.views.acq_plots import AcquisitionPlots
from app.gui.views.plan import PlanView
from app.gui.views.projections import ProjectionsWidget
from app.gui.views.station import StationView
from app.gui.widgets import verdict_color
from app.io.runfile import RunFileError, write_mounts
from app.pipeline import RUN_FILE
from app.report.analysis import message_of
from processing.identify import IdentificationResult
from processing.measurement import Measurement

if TYPE_CHECKING:
    from app.mockbench.simulated import SimulatedStation

__all__ = ["AcquisitionView"]

#: the long automatic verdict last, so "used" and the override stay in view
_HIT_COLUMNS = ("hit", "point", "time (s)", "peak force (N)", "used", "operator",
                "automatic verdict")
_USED = 4
_OPERATOR_PAUSE = "paused by the operator"
#: an SG-1's watchdog, s: its output goes off when the run's worker has not fed it for this long
SHAKER_HEARTBEAT = 0.5
#: the simulated bench's watchdog, s: its devices run in this process and share its interpreter
#: with the worker and the plots, which stall the worker's reads for 0.5 s on a loaded machine
MOCK_HEARTBEAT = 2.0


class AcquisitionView(QtWidgets.QWidget):
    """Start, follow and steer an acquisition run."""

    message = QtCore.Signal(str, str)

    def __init__(self, station_view: StationView, plan_view: PlanView, session: Session,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.station_view, self.plan_view, self.session = station_view, plan_view, session
        self.procedure: HammerProcedure | ShakerProcedure | None = None
        self.word = "hit"  # "block" in a shaker run
        self.hits: list[HitRecord] = []
        self._shown: Measurement | None = None  # the run's measurement, once shown
        self.state: RunState = RunState.IDLE
        self._pause_asked = False
        #: a station file's [simulation]: its simulated vendor APIs and operator, for one run
        self._simulated: SimulatedStation | None = None
        top = self._run_controls()
        left = self._progress_panel()
        self.bridge = AcquisitionBridge(self)
        self.plots = AcquisitionPlots(self.bridge.samples)
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(self.plots)
        split.setSizes([520, 760])
        lay = QtWidgets.QVBoxLayout(self)
        lay.addLayout(top)
        lay.addWidget(split, 1)
        self._connect_bridge()
        plan_view.rows_changed.connect(self.projections.set_rows)
        self._set_state(RunState.IDLE)

    # --- layout ----------------------------------------------------------------------------------
    def _run_controls(self) -> QtWidgets.QHBoxLayout:
        """The row of the run file, the simulated operator and the run buttons."""
        self.run_path = QtWidgets.QLineEdit()
        self.run_path.setPlaceholderText("run file (HDF5) to write")
        browse = QtWidgets.QPushButton("Browse…")
        browse.clicked.connect(self._browse)
        self.operator_box = QtWidgets.QCheckBox("simulated operator (mock bench)")
        self.operator_box.setToolTip("On the mock bench, a simulated operator hits where the "
                                     "plan asks, or moves the shaker to each point")
        self.operator_box.setChecked(True)
        self.start_button = QtWidgets.QPushButton("Start")
        self.pause_button = QtWidgets.QPushButton("Pause")
        self.resume_button = QtWidgets.QPushButton("Resume")
        self.stop_button = QtWidgets.QPushButton("Stop")
        self.stop_button.setStyleSheet("font-weight:bold; color:#7a1a00;")
        self.start_button.clicked.connect(self.start)
        self.pause_button.clicked.connect(self.pause)
        self.resume_button.clicked.connect(lambda: self.procedure and self.procedure.resume())
        self.stop_button.clicked.connect(self.stop)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("Run file:"))
        top.addWidget(self.run_path, 1)
        top.addWidget(browse)
        top.addWidget(self.operator_box)
        for b in (self.start_button, self.pause_button, self.resume_button, self.stop_button):
            top.addWidget(b)
        return top

    def _progress_panel(self) -> QtWidgets.QWidget:
        """The next point and the progress above the hits (with their overrides) and the
        projections."""
        self.next_label = QtWidgets.QLabel("Not running")
        self.next_label.setStyleSheet("font-size:15pt; font-weight:bold;")
        self.progress_bar = QtWidgets.QProgressBar()
        self.progress_bar.setFormat("%v of %m points")
        self.progress_label = QtWidgets.QLabel("")
        self.projections = ProjectionsWidget()
        left = QtWidgets.QWidget()
        ll = QtWidgets.QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        ll.addWidget(self.next_label)
        ll.addWidget(self.progress_bar)
        ll.addWidget(self.progress_label)
        vsplit = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        vsplit.addWidget(self._hits_box())
        vsplit.addWidget(self.projections)
        vsplit.setSizes([330, 420])
        ll.addWidget(vsplit, 1)
        return left

    def _hits_box(self) -> QtWidgets.QWidget:
        """The table of hits (or blocks) and the buttons that override their verdicts."""
        self.hits_table = QtWidgets.QTableWidget(0, len(_HIT_COLUMNS))
        self.hits_table.setHorizontalHeaderLabels(list(_HIT_COLUMNS))
        self.hits_table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.hits_table.setSelectionBehavior(
            QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.hits_table.horizontalHeader().setStretchLastSection(True)
        self.hits_table.itemSelectionChanged.connect(self._selected)
        self.accept_button = QtWidgets.QPushButton("Accept selected hit")
        self.reject_button = QtWidgets.QPushButton("Reject selected hit")
        self.clear_button = QtWidgets.QPushButton("Automatic verdict")
        self.accept_button.clicked.connect(lambda: self._override("accept"))
        self.reject_button.clicked.connect(lambda: self._override("reject"))
        self.clear_button.clicked.connect(lambda: self._override(""))
        overrides = QtWidgets.QHBoxLayout()
        for b in (self.accept_button, self.reject_button, self.clear_button):
            overrides.addWidget(b)
        hits_box = QtWidgets.QWidget()
        hl = QtWidgets.QVBoxLayout(hits_box)
        hl.setContentsMargins(0, 0, 0, 0)
        hl.addWidget(self.hits_table, 1)
        hl.addLayout(overrides)
        return hits_box

    def _connect_bridge(self) -> None:
        """Show what the acquisition reports, through the bridge to the GUI thread."""
        self.bridge.next_point.connect(self._next_point)
        self.bridge.hit.connect(self._hit)
        self.bridge.frf.connect(self._frf)
        self.bridge.progress.connect(self._progress)
        self.bridge.paused.connect(self._paused)
        self.bridge.resumed.connect(lambda: self._set_state(RunState.RUNNING))
        self.bridge.error.connect(lambda m: self.message.emit("error", f"acquisition: {m}"))
        self.bridge.result.connect(self._result)
        self.bridge.finished.connect(self._finished)

    # --- controls --------------------------------------------------------------------------------
    def _browse(self) -> None:
        name, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Run file", self.run_path.text(),
                                                        "HDF5 run file (*.h5)")
        if name:
            self.run_path.setText(name)

    def _default_path(self) -> Path:
        base = Path(str(self.station_view.settings.value(
            "run_dir", str(Path.home() / "insitu-runs"), str)))
        stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
        return base / f"run-{stamp}.h5"

    def start(self) -> bool:
        """Start the plan on the station; False (with a message) when it cannot start.

        A hammer plan runs :class:`HammerProcedure`, a shaker plan :class:`ShakerProcedure`
        (on the mock bench with the simulated operator, the mock shaker is moved to each
        point; on a real station the run pauses at each point until the shaker is attached
        and the operator resumes). A plan whose geometry cannot identify all six DOFs runs
        as a partial run (FRFs only), with a warning.
        """
        station, plan = self.station_view.station, self.plan_view.plan
        if self.procedure is not None and self.procedure.running:
            return False
        mock = self.station_view.mock
        if (mock is not None and plan is not None and plan.method == "shaker"
                and plan.n_references != len(mock.shakers)):
            # the simulated bench gets as many shakers as the plan drives at once
            self.station_view.use_mock(mock.bench.name, plan.n_references, offer_plan=False)
            station = self.station_view.station
        if station is None:
            self.message.emit("error", "no station: choose the mock bench or a station file "
                              "in the Station tab")
            return False
        if plan is None:
            self.message.emit("error", "no acquisition plan: import a plan (TOML) in the Test "
                              "plan tab (or use the mock bench's)")
            return False
        path = Path(self.run_path.text()) if self.run_path.text() else self._default_path()
        self.station_view.stop_monitor()
        listeners: list[Any] = [self.bridge]
        mock = self.station_view.mock
        simulated = mock is not None and self.operator_box.isChecked()
        shaker = plan.method == "shaker"
        if simulated and mock is not None:
            listeners.append(mock.shaker_operator if shaker else mock.operator)
        options = None
        self._end_simulation()
        if mock is None and station.simulation:  # a station file simulating its vendor APIs
            from app.mockbench.simulated import SimulatedStation, SimulationError

            try:
                self._simulated = SimulatedStation(station)
            except SimulationError as err:
                self.message.emit("error", f"cannot start: {err}")
                return False
            operator = self._simulated.shaker_operator if shaker else self._simulated.operator
            if self.operator_box.isChecked() and operator is not None:
                listeners.append(operator)
                simulated = True
            options = self._simulated.device_options
        try:
            partial = not plan.check(station, strict=False).ok
            path.parent.mkdir(parents=True, exist_ok=True)
            if shaker:
                self.procedure = ShakerProcedure(
                    plan, station, path, listeners=listeners, partial=partial,
                    confirm_attach=not simulated, device_options=options,
                    heartbeat=MOCK_HEARTBEAT if mock is not None else SHAKER_HEARTBEAT)
            else:
                self.procedure = HammerProcedure(plan, station, path, listeners=listeners,
                                                 partial=partial, device_options=options)
        except (ValueError, OSError) as err:
            self._end_simulation()
            self.message.emit("error", f"cannot start: {message_of(err)}")
            return False
        self._show_new_run(plan, path)
        self.procedure.start()
        self._set_state(RunState.RUNNING)
        self.message.emit("info" if not partial else "warning", _started(
            plan, path, partial, "; ".join(self.procedure.geometry_report.messages)))
        return True

    def _show_new_run(self, plan: TestPlan, path: Path) -> None:
        """The view made ready for a new run of ``plan`` into ``path``: its words (hit or
        block), an empty table, the progress bar counting the plan's stops, clear plots."""
        self.word = "block" if plan.method == "shaker" else "hit"
        self._shown = None
        self.run_path.setText(str(path))
        self.hits = []
        self.hits_table.setRowCount(0)
        self.hits_table.setHorizontalHeaderLabels(
            [self.word, plan.stop_word, *_HIT_COLUMNS[2:]])
        w = self.word.capitalize()
        self.accept_button.setText(f"Accept selected {self.word}")
        self.reject_button.setText(f"Reject selected {self.word}")
        self.accept_button.setToolTip(f"{w} used although the automatic verdict rejected it")
        self.reject_button.setToolTip(f"{w} not used although the automatic verdict "
                                      "accepted it")
        self.clear_button.setToolTip(f"Back to the automatic verdict of the selected {self.word}")
        # the bar counts the run's stops: points, or the pairs two shakers drive together
        self.progress_bar.setRange(0, len(plan.drives))
        self.progress_bar.setFormat(f"%v of %m {plan.stop_word}s")
        self.progress_bar.setValue(0)
        self.progress_label.setText("")
        self.plots.start(self.word, plan.n_references)
        self._pause_asked = False

    def pause(self) -> None:
        """Pause after the current hit or block (devices stopped, the shaker output off)."""
        if self.procedure is not None and self.procedure.running:
            self._pause_asked = True
            self.procedure.pause(_OPERATOR_PAUSE)

    def stop(self) -> None:
        """End the run now (devices shut down, the shaker output off); data stay saved."""
        if self.procedure is not None and self.procedure.running:
            self.procedure.stop()

    def _override(self, what: str) -> None:
        row = self.hits_table.currentRow()
        if self.procedure is None or not 0 <= row < len(self.hits):
            self.message.emit("warning", f"select a {self.word} in the table first")
            return
        if not self.procedure.running:
            self.message.emit("warning", "the run has ended: overrides apply while it runs")
            return
        hit_id = self.hits[row].hit_id
        {"accept": self.procedure.accept_hit, "reject": self.procedure.reject_hit,
         "": self.procedure.clear_override}[what](hit_id)

    def _set_state(self, state: RunState) -> None:
        self.state = state
        running = state in (RunState.RUNNING, RunState.PAUSED)
        self.start_button.setEnabled(not running)
        self.pause_button.setEnabled(state is RunState.RUNNING)
        self.resume_button.setEnabled(state is RunState.PAUSED)
        self.stop_button.setEnabled(running)
        for b in (self.accept_button, self.reject_button, self.clear_button):
            b.setEnabled(running)

    # --- procedure events (GUI thread, via the bridge) -------------------------------------------
    @QtCore.Slot(object)
    def _next_point(self, point: Any) -> None:
        plan = self.plan_view.plan
        n = len(plan.excitations) if plan is not None else 0
        d = " ".join(f"{v:+.2f}" for v in point.direction)
        what = "Shaker at" if self.word == "block" else "Hit"
        self.next_label.setText(f"{what} point {point.index + 1} of {n}: node {point.node}, "
                                f"direction ({d})")
        self.projections.highlight(point.xyz)
        self.plan_view.projections.highlight(point.xyz)

    @QtCore.Slot(object)
    def _hit(self, hit: HitRecord) -> None:
        if hit.hit_id < len(self.hits):
            # an override's report carries no samples: keep the recorded ones
            if hit.data is None:
                hit = HitRecord(**{**hit.__dict__, "data": self.hits[hit.hit_id].data,
                                   "fs": self.hits[hit.hit_id].fs})
            self.hits[hit.hit_id] = hit
        else:
            self.hits.append(hit)
            self.hits_table.setRowCount(len(self.hits))
        cells = (str(hit.hit_id + 1), str(hit.point + 1), f"{hit.time:.1f}",
                 f"{hit.peak_force:.1f}", "yes" if hit.accepted else "no",
                 hit.override or "-", _auto(hit))
        for j, text in enumerate(cells):
            item = QtWidgets.QTableWidgetItem(text)
            if j == _USED:
                item.setBackground(verdict_color(hit.accepted))
                item.setForeground(QtCore.Qt.GlobalColor.white)
            self.hits_table.setItem(hit.hit_id, j, item)
        self.hits_table.resizeColumnsToContents()
        if not hit.override and hit.hit_id == len(self.hits) - 1:
            self.hits_table.scrollToBottom()
            if not self.hits_table.selectedItems():
                self.plots.show_record(hit, _verdict(hit))
        elif self.hits_table.currentRow() == hit.hit_id:
            self.plots.show_record(hit, _verdict(hit))

    def _selected(self) -> None:
        """Show the record of the selected hit or block."""
        row = self.hits_table.currentRow()
        if 0 <= row < len(self.hits) and self.hits_table.selectedItems():
            self.plots.show_record(self.hits[row], _verdict(self.hits[row]))

    @QtCore.Slot(object)
    def _frf(self, frf: PointFRF) -> None:
        plan = self.plan_view.plan
        where = f"point {frf.point + 1}"
        if plan is not None and plan.n_references > 1:  # the drive's first shaker's column
            where = f"drive {frf.point + 1}, point {plan.drives[frf.point][0] + 1}"
        self.plots.show_frf(frf, self._response_names(), where)

    def _n_forces(self) -> int:
        plan = self.plan_view.plan
        return plan.n_references if plan is not None else 1

    def _response_names(self) -> list[str]:
        """Channel names of the responses (rows after the forces) of the running plan."""
        rows = getattr(self.procedure, "rows", ())
        return [c.name for c in rows[self._n_forces():]]

    @QtCore.Slot(object)
    def _progress(self, p: Progress) -> None:
        self.progress_bar.setValue(p.points_done)
        w = self.word
        done = "averaged" if w == "block" else "accepted"
        plan = self.plan_view.plan
        stop = "point" if plan is None else plan.stop_word
        self.progress_label.setText(
            f"{stop} {p.point + 1}: {p.point_accepted} of {p.point_needed} {w}s {done}; "
            f"{p.hits} {w}s in all, {p.accepted} accepted; {p.bad_frames} bad frames; "
            f"{p.elapsed:.0f} s")

    @QtCore.Slot(str)
    def _paused(self, reason: str) -> None:
        self._set_state(RunState.PAUSED)
        self.next_label.setText(f"Paused: {reason}")
        asked, self._pause_asked = self._pause_asked and reason == _OPERATOR_PAUSE, False
        if asked:
            self.message.emit("warning", f"acquisition paused: {reason}")
        elif reason.startswith("attach the shaker"):
            self.message.emit("warning", f"{reason[0].upper()}{reason[1:]}")
        else:  # a device failed: the shaker output is off already
            self.message.emit("error", f"acquisition paused, device problem: {reason}")

    @QtCore.Slot(object, object, bool)
    def _result(self, measurement: Measurement, result: IdentificationResult,
                final: bool) -> None:
        """The run's identification: shown as soon as the points are done (the bootstrap
        over hits then runs in the worker), then its final (stored) form, without fitting
        again: the same numbers as the run file's."""
        proc = self.procedure
        if proc is None:
            return
        if self._shown is not measurement:
            # the run's own measurement, cut as the pipeline opens the run file: the same
            # numbers as the stored result and every view of the file
            self._shown = measurement
            self.session.set_measurement(measurement, proc.path.name, proc.path, RUN_FILE,
                                         result=result)
            if not final:
                self.message.emit("info", f"result of the {len(self.hits)} {self.word}s; "
                                  "their bootstrap is running")
        elif self.session.measurement is measurement:
            self.session.set_result(result)

    @QtCore.Slot(object)
    def _end_simulation(self) -> None:
        """Close the simulated vendor APIs of the last run's station, if any."""
        sim, self._simulated = self._simulated, None
        if sim is not None:
            sim.shutdown()

    def _finished(self, state: RunState) -> None:
        self._end_simulation()  # the procedure has released its devices
        self.plots.stop()
        self._set_state(state)
        self.projections.highlight(None)
        self.plan_view.projections.highlight(None)
        proc = self.procedure
        path = proc.path if proc is not None else None
        n = len(self.hits)
        things = f"{n} {self.word}{'' if n == 1 else 's'}"
        if state is RunState.FINISHED and proc is not None and proc.measurement is not None:
            self.next_label.setText("Finished: every point done")
            self.progress_bar.setValue(self.progress_bar.maximum())
            self.message.emit("info", f"acquisition finished: {things} saved in {path}")
            if path is not None and self.session.mounts is not None:
                try:
                    write_mounts(path, self.session.mounts)
                except RunFileError as err:
                    self.message.emit("error", f"the mounts table was not saved: {err}")
            if self._shown is None:  # no identification (a partial plan, a failed fit)
                self.session.set_measurement(anti_aliased(proc.measurement),
                                             path.name if path else "acquisition", path,
                                             RUN_FILE)
        else:
            why = proc.message if proc is not None and proc.message else state.value
            self.next_label.setText(f"Ended ({state.value}): {why}")
            self.message.emit("warning" if state is RunState.STOPPED else "error",
                              f"acquisition {state.value}: {why}; the {things} acquired "
                              f"{'is' if n == 1 else 'are'} saved in {path}")

    def shutdown(self, timeout: float = 10.0) -> None:
        """Stop the run and wait for the devices to shut down (window closing)."""
        if self.procedure is not None and self.procedure.running:
            self.procedure.stop()
            self.procedure.wait(timeout)
        self._end_simulation()
        self.plots.live.timer.stop()


def _auto(hit: HitRecord) -> str:
    return "accepted" if hit.auto_accepted else (hit.reason or "rejected")


def _verdict(hit: HitRecord) -> str:
    """The verdict in force, in words."""
    if hit.override:
        return f"{'accepted' if hit.accepted else 'rejected'} by the operator"
    return _auto(hit)


def _started(plan: TestPlan, path: Path, partial: bool, why: str) -> str:
    """The message when a run starts."""
    n = len(plan.excitations)
    if plan.method == "shaker":
        s = plan.shaker
        each = f"{s.averages} block(s) of {s.nperseg / plan.record.fs:g} s each, {s.waveform}"
    else:
        each = f"{plan.hits} accepted hit(s) each"
    text = f"acquisition started: {n} points, {each}, writing {path.name}"
    if partial:
        text += f". Partial run (FRFs only, no identification): {why}"
    return text
