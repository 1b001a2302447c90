"""Acquisition view: run the plan on the station, hit by hit.

The next point is named and highlighted; each hit appears with its automatic verdict
(accepted, double hit, overload, ...) and can be accepted or rejected by the operator; the
recorded force and accelerations of the latest hit, and the current point's averaged FRF
magnitude and coherence, update per hit; the plan's progress shows; pause, resume and stop.
Stop, an error and closing the window end the procedure at once (devices shut down, the
shaker output off); everything acquired stays in the run file.
"""

from __future__ import annotations

import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from app.acquire.events import HitRecord, PointFRF, Progress, RunState
from app.acquire.hammer import HammerProcedure
from app.gui.acquisition_bridge import AcquisitionBridge
from app.gui.session import Session
from app.gui.views.plan import PlanView
from app.gui.views.projections import ProjectionsWidget
from app.gui.views.station import StationView
from app.gui.widgets import make_plot, verdict_color
from app.report.analysis import message_of
from app.report.figures import COLORS
from app.report.runs import usable_lines

__all__ = ["AcquisitionView"]

_HIT_COLUMNS = ("hit", "point", "time (s)", "peak force (N)", "automatic verdict", "operator",
                "used")


class AcquisitionView(QtWidgets.QWidget):
    """Start, follow and steer an acquisition run."""

    message = QtCore.Signal(str, str)

    def __init__(self, station_view: StationView, plan_view: PlanView, session: Session,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.station_view, self.plan_view, self.session = station_view, plan_view, session
        self.procedure: HammerProcedure | None = None
        self.hits: list[HitRecord] = []
        self.state: RunState = RunState.IDLE
        self.run_path = QtWidgets.QLineEdit()
        self.run_path.setPlaceholderText("run file (HDF5) to write")
        browse = QtWidgets.QPushButton("Browse…")
        browse.clicked.connect(self._browse)
        self.operator_box = QtWidgets.QCheckBox("simulated operator hits (mock bench)")
        self.operator_box.setChecked(True)
        self.start_button = QtWidgets.QPushButton("Start")
        self.pause_button = QtWidgets.QPushButton("Pause")
        self.resume_button = QtWidgets.QPushButton("Resume")
        self.stop_button = QtWidgets.QPushButton("Stop")
        self.stop_button.setStyleSheet("font-weight:bold; color:#7a1a00;")
        self.start_button.clicked.connect(self.start)
        self.pause_button.clicked.connect(lambda: self.procedure and self.procedure.pause())
        self.resume_button.clicked.connect(lambda: self.procedure and self.procedure.resume())
        self.stop_button.clicked.connect(self.stop)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("Run file:"))
        top.addWidget(self.run_path, 1)
        top.addWidget(browse)
        top.addWidget(self.operator_box)
        for b in (self.start_button, self.pause_button, self.resume_button, self.stop_button):
            top.addWidget(b)
        self.next_label = QtWidgets.QLabel("Not running")
        self.next_label.setStyleSheet("font-size:15pt; font-weight:bold;")
        self.progress_bar = QtWidgets.QProgressBar()
        self.progress_bar.setFormat("%v of %m points")
        self.progress_label = QtWidgets.QLabel("")
        self.hits_table = QtWidgets.QTableWidget(0, len(_HIT_COLUMNS))
        self.hits_table.setHorizontalHeaderLabels(list(_HIT_COLUMNS))
        self.hits_table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.hits_table.setSelectionBehavior(
            QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.hits_table.horizontalHeader().setStretchLastSection(True)
        self.accept_button = QtWidgets.QPushButton("Accept selected hit")
        self.reject_button = QtWidgets.QPushButton("Reject selected hit")
        self.clear_button = QtWidgets.QPushButton("Automatic verdict")
        self.accept_button.clicked.connect(lambda: self._override("accept"))
        self.reject_button.clicked.connect(lambda: self._override("reject"))
        self.clear_button.clicked.connect(lambda: self._override(""))
        overrides = QtWidgets.QHBoxLayout()
        for b in (self.accept_button, self.reject_button, self.clear_button):
            overrides.addWidget(b)
        self.projections = ProjectionsWidget()
        left = QtWidgets.QWidget()
        ll = QtWidgets.QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        ll.addWidget(self.next_label)
        ll.addWidget(self.progress_bar)
        ll.addWidget(self.progress_label)
        hits_box = QtWidgets.QWidget()
        hl = QtWidgets.QVBoxLayout(hits_box)
        hl.setContentsMargins(0, 0, 0, 0)
        hl.addWidget(self.hits_table, 1)
        hl.addLayout(overrides)
        vsplit = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        vsplit.addWidget(hits_box)
        vsplit.addWidget(self.projections)
        vsplit.setSizes([330, 420])
        ll.addWidget(vsplit, 1)
        self.force_plot = make_plot("Force of the latest hit", "force", "N", "time", "s")
        self.acc_plot = make_plot("Accelerations of the latest hit", "acceleration", "m/s²",
                                  "time", "s")
        self.frf_plot = make_plot("FRF magnitude of the current point (average)",
                                  "|H| ((m/s²)/N)", logy=True)
        self.coh_plot = make_plot("Coherence of the current point", "coherence")
        self.coh_plot.getPlotItem().setYRange(0, 1.05)
        self.coh_plot.getPlotItem().addItem(pg.InfiniteLine(
            pos=0.8, angle=0, pen=pg.mkPen(COLORS[1], style=QtCore.Qt.PenStyle.DashLine),
            label="0.8", labelOpts={"position": 0.03, "color": COLORS[1]}))
        self._force_curve = self.force_plot.getPlotItem().plot(pen=pg.mkPen(COLORS[1]))
        self._acc_curves: list[pg.PlotDataItem] = []
        self._frf_curves: list[pg.PlotDataItem] = []
        self._coh_curves: list[pg.PlotDataItem] = []
        plots = QtWidgets.QWidget()
        pl = QtWidgets.QGridLayout(plots)
        pl.setContentsMargins(0, 0, 0, 0)
        pl.addWidget(self.force_plot, 0, 0)
        pl.addWidget(self.acc_plot, 1, 0)
        pl.addWidget(self.frf_plot, 0, 1)
        pl.addWidget(self.coh_plot, 1, 1)
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(plots)
        split.setSizes([520, 760])
        lay = QtWidgets.QVBoxLayout(self)
        lay.addLayout(top)
        lay.addWidget(split, 1)
        self.bridge = AcquisitionBridge(self)
        self.bridge.next_point.connect(self._next_point)
        self.bridge.hit.connect(self._hit)
        self.bridge.frf.connect(self._frf)
        self.bridge.progress.connect(self._progress)
        self.bridge.paused.connect(self._paused)
        self.bridge.resumed.connect(lambda: self._set_state(RunState.RUNNING))
        self.bridge.error.connect(lambda m: self.message.emit("error", f"acquisition: {m}"))
        self.bridge.finished.connect(self._finished)
        plan_view.rows_changed.connect(self.projections.set_rows)
        self._set_state(RunState.IDLE)

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
        """Start the plan on the station; False (with a message) when it cannot start."""
        station, plan = self.station_view.station, self.plan_view.plan
        if self.procedure is not None and self.procedure.running:
            return False
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
        if mock is not None and self.operator_box.isChecked():
            listeners.append(mock.operator)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.procedure = HammerProcedure(plan, station, path, listeners=listeners)
        except (ValueError, OSError) as err:
            self.message.emit("error", f"cannot start: {message_of(err)}")
            return False
        self.run_path.setText(str(path))
        self.hits = []
        self.hits_table.setRowCount(0)
        self.progress_bar.setRange(0, len(plan.excitations))
        self.progress_bar.setValue(0)
        self.procedure.start()
        self._set_state(RunState.RUNNING)
        self.message.emit("info", f"acquisition started: {len(plan.excitations)} points, "
                          f"{plan.hits} accepted hit(s) each, writing {path.name}")
        return True

    def stop(self) -> None:
        """End the run now (devices shut down, the shaker output off); data stay saved."""
        if self.procedure is not None and self.procedure.running:
            self.procedure.stop()

    def _override(self, what: str) -> None:
        row = self.hits_table.currentRow()
        if self.procedure is None or not 0 <= row < len(self.hits):
            self.message.emit("warning", "select a hit in the table first")
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
        self.next_label.setText(f"Hit point {point.index + 1} of {n}: node {point.node}, "
                                f"direction ({d})")
        self.projections.highlight(point.xyz)
        self.plan_view.projections.highlight(point.xyz)
        self._frf_point = point.index

    @QtCore.Slot(object)
    def _hit(self, hit: HitRecord) -> None:
        if hit.hit_id < len(self.hits):
            self.hits[hit.hit_id] = hit
        else:
            self.hits.append(hit)
            self.hits_table.setRowCount(len(self.hits))
        auto = "accepted" if hit.auto_accepted else (hit.reason or "rejected")
        cells = (str(hit.hit_id + 1), str(hit.point + 1), f"{hit.time:.1f}",
                 f"{hit.peak_force:.1f}", auto, hit.override or "-",
                 "yes" if hit.accepted else "no")
        for j, text in enumerate(cells):
            item = QtWidgets.QTableWidgetItem(text)
            if j == 6:
                item.setBackground(verdict_color(hit.accepted))
                item.setForeground(QtCore.Qt.GlobalColor.white)
            self.hits_table.setItem(hit.hit_id, j, item)
        self.hits_table.resizeColumnsToContents()
        self.hits_table.scrollToBottom()
        if hit.data is not None and not hit.override:
            self._traces(hit)

    def _traces(self, hit: HitRecord) -> None:
        assert hit.data is not None
        t = np.arange(hit.data.shape[1]) / hit.fs
        self._force_curve.setData(t, hit.data[0])
        acc = hit.data[1:]
        plot = self.acc_plot.getPlotItem()
        if not self._acc_curves:
            plot.addLegend(offset=(-5, 5), labelTextSize="7pt", colCount=4)
        names = self._response_names()
        while len(self._acc_curves) < acc.shape[0]:
            k = len(self._acc_curves)
            self._acc_curves.append(plot.plot(pen=pg.mkPen(COLORS[k % len(COLORS)]),
                                              name=names[k] if k < len(names) else None))
        for c, y in zip(self._acc_curves, acc, strict=False):
            c.setData(t, y)

    @QtCore.Slot(object)
    def _frf(self, frf: PointFRF) -> None:
        names = self._response_names()
        for curves, plot in ((self._frf_curves, self.frf_plot), (self._coh_curves, self.coh_plot)):
            n = 0 if frf.H is None else frf.H.shape[0]
            if not curves and n and plot is self.frf_plot:
                plot.getPlotItem().addLegend(offset=(-5, 5), labelTextSize="7pt", colCount=4)
            while len(curves) < n:
                k = len(curves)
                curves.append(plot.getPlotItem().plot(
                    pen=pg.mkPen(COLORS[k % len(COLORS)]),
                    name=names[k] if plot is self.frf_plot and k < len(names) else None))
        # lines above 0 Hz and up to fs / 2.56: above, the anti-alias filters shape the data
        keep = (frf.freq > 0) & (frf.freq <= frf.freq[-1] / 1.28) if frf.freq.size else frf.freq > 0
        for k, c in enumerate(self._frf_curves):
            if frf.H is None:
                c.setData([], [])
            else:
                c.setData(frf.freq[keep], np.abs(frf.H[k, keep]))
        for k, c in enumerate(self._coh_curves):
            if frf.coherence is None:
                c.setData([], [])
            else:
                c.setData(frf.freq[keep], np.nan_to_num(frf.coherence[k, keep]))
        self.frf_plot.getPlotItem().setTitle(
            f"FRF magnitude, point {frf.point + 1} ({frf.n_averages} hit(s) averaged)",
            size="10pt")

    def _response_names(self) -> list[str]:
        """Channel names of the responses (rows after the force) of the running plan."""
        proc = self.procedure
        rows = getattr(proc, "rows", ())
        return [c.name for c in rows[1:]]

    @QtCore.Slot(object)
    def _progress(self, p: Progress) -> None:
        self.progress_bar.setValue(p.points_done)
        self.progress_label.setText(
            f"point {p.point + 1}: {p.point_accepted} of {p.point_needed} hits accepted; "
            f"{p.hits} hits in all, {p.accepted} accepted; {p.bad_frames} bad frames; "
            f"{p.elapsed:.0f} s")

    @QtCore.Slot(str)
    def _paused(self, reason: str) -> None:
        self._set_state(RunState.PAUSED)
        self.next_label.setText(f"Paused: {reason}")
        self.message.emit("warning", f"acquisition paused: {reason}")

    @QtCore.Slot(object)
    def _finished(self, state: RunState) -> None:
        self._set_state(state)
        self.projections.highlight(None)
        self.plan_view.projections.highlight(None)
        proc = self.procedure
        path = proc.path if proc is not None else None
        n = len(self.hits)
        if state is RunState.FINISHED and proc is not None and proc.frf is not None:
            self.next_label.setText("Finished: every point done")
            self.progress_bar.setValue(self.progress_bar.maximum())
            self.message.emit("info", f"acquisition finished: {n} hits saved in {path}")
            self.session.set_frf(usable_lines(proc.frf), path.name if path else "acquisition",
                                 path)
        else:
            why = proc.message if proc is not None and proc.message else state.value
            self.next_label.setText(f"Ended ({state.value}): {why}")
            self.message.emit("warning" if state is RunState.STOPPED else "error",
                              f"acquisition {state.value}: {why}; the {n} hits acquired are "
                              f"saved in {path}")

    def shutdown(self, timeout: float = 10.0) -> None:
        """Stop the run and wait for the devices to shut down (window closing)."""
        if self.procedure is not None and self.procedure.running:
            self.procedure.stop()
            self.procedure.wait(timeout)
