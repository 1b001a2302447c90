"""The Test plan tab's planner (docs/planning.md, docs/gui.md): load an approximate model and
the candidate sensors and points, choose how many to use, the noise and the test's stated
uncertainties, and plan (:func:`app.acquire.design.plan_layout`, as ``insitu plan`` does,
on the worker thread). The candidates table's "use" boxes edit the chosen layout; every
layout is predicted again (:func:`app.acquire.design.predict_layout`) and becomes the
acquisition plan, with its ``[prediction]`` table."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.acquire.design import (
    PlanInputs,
    conditions,
    load_inputs,
    plan_data,
    plan_layout,
    predict_layout,
)
from app.acquire.plan import TestPlan, parse_plan, plan_toml
from app.gui.widgets import fill_table, set_verdict
from app.gui.worker import TaskRunner
from app.report.analysis import message_of
from app.report.tables import SPREADS, predicted_rows
from processing.montecarlo import StatedUncertainty
from processing.planning import Prediction, TestConditions, TestDesign

__all__ = ["PlannerPanel"]

_CAND_COLUMNS = ("use", "kind", "node", "x (m)", "y (m)", "z (m)", "direction")
_PRED_COLUMNS = ("parameter", "unit", "predicted std", "95 %")
_DESIGN, _PREDICT = "planner.design", "planner.predict"


def _spin(lo: float, hi: float, value: float, suffix: str, decimals: int = 2,
          step: float = 0.1) -> QtWidgets.QDoubleSpinBox:
    s = QtWidgets.QDoubleSpinBox()
    s.setRange(lo, hi)
    s.setDecimals(decimals)
    s.setSingleStep(step)
    s.setValue(value)
    s.setSuffix(suffix)
    return s


class PlannerPanel(QtWidgets.QWidget):
    """Plan a test from candidates and show the predicted standard deviations.

    Signals
    -------
    planned(object)
        The chosen (or edited) layout as an acquisition plan (:class:`TestPlan`, with its
        ``prediction``), after each successful prediction.
    candidates_changed(object, object)
        Candidate sensor positions (n, 3) and candidate point positions (m, 3), metres.
    saved(object)
        The plan was written to this path.
    message(str, str)
        (level, text) for the window's message bar.
    """

    planned = QtCore.Signal(object)
    saved = QtCore.Signal(object)
    candidates_changed = QtCore.Signal(object, object)
    message = QtCore.Signal(str, str)

    def __init__(self, runner: TaskRunner, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.runner = runner
        self.inputs: PlanInputs | None = None
        self.model_path: Path | None = None
        self.candidates_path: Path | None = None
        self.sensors: list[int] = []
        self.excitations: list[int] = []
        self.prediction: Prediction | None = None
        self.plan: TestPlan | None = None
        self._data: dict[str, Any] | None = None
        self._cond: TestConditions | None = None
        self._criterion = "D"
        self._filling = False
        runner.done.connect(self._done)
        runner.failed.connect(self._failed)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addLayout(self._file_row())
        lay.addLayout(self._settings_form())
        self.status = QtWidgets.QLabel()
        self.status.setWordWrap(True)
        lay.addWidget(self.status)
        self.candidates_table = QtWidgets.QTableWidget(0, len(_CAND_COLUMNS))
        self.candidates_table.setHorizontalHeaderLabels(list(_CAND_COLUMNS))
        self.candidates_table.itemChanged.connect(self._on_check)
        self.candidates_table.verticalHeader().setDefaultSectionSize(
            self.candidates_table.fontMetrics().height() + 6)
        self.candidates_table.setToolTip("tick or untick 'use' to add or remove a candidate: "
                                         "the layout is predicted again")
        lay.addWidget(self.candidates_table, 2)
        spreads = QtWidgets.QLabel("Predicted standard deviation of each identified number "
                                   "(the identification's own uncertainty) and its 95 % "
                                   "spread, ± 1.96 std")
        spreads.setToolTip(SPREADS)
        spreads.setWordWrap(True)
        lay.addWidget(spreads)
        self.prediction_table = QtWidgets.QTableWidget(0, len(_PRED_COLUMNS))
        self.prediction_table.setHorizontalHeaderLabels(list(_PRED_COLUMNS))
        lay.addWidget(self.prediction_table, 3)
        set_verdict(self.status, None, "Load a model and candidates, then Plan")

    def _file_row(self) -> QtWidgets.QHBoxLayout:
        row = QtWidgets.QHBoxLayout()
        self.model_button = QtWidgets.QPushButton("Model (TOML)…")
        self.model_button.setToolTip("[model] mass, cog, box or inertia_cog; [[mount]] "
                                     "position, rates (docs/planning.md)")
        self.candidates_button = QtWidgets.QPushButton("Candidates (TOML)…")
        self.candidates_button.setToolTip("[[sensor]] node, xyz; [[point]] node, xyz, "
                                          "directions (docs/planning.md)")
        self.files_label = QtWidgets.QLabel("no model, no candidates")
        self.model_button.clicked.connect(lambda: self._ask("model"))
        self.candidates_button.clicked.connect(lambda: self._ask("candidates"))
        for w in (self.model_button, self.candidates_button):
            row.addWidget(w)
        row.addWidget(self.files_label, 1)
        return row

    def _settings_form(self) -> QtWidgets.QGridLayout:
        g = QtWidgets.QGridLayout()
        self.n_sensors = QtWidgets.QSpinBox()
        self.n_sensors.setRange(3, 1000)
        self.n_sensors.setValue(4)
        self.n_points = QtWidgets.QSpinBox()
        self.n_points.setRange(6, 10000)
        self.n_points.setValue(9)
        self.noise = _spin(0.0, 50.0, 1.0, " %")
        self.location = _spin(0.0, 100.0, 0.0, " mm", 1, 0.5)
        self.angle = _spin(0.0, 30.0, 0.0, " deg", 1, 0.5)
        self.gain = _spin(0.0, 50.0, 0.0, " %", 1, 0.5)
        self.plan_button = QtWidgets.QPushButton("Plan")
        self.plan_button.setToolTip("choose the sensors and excitations (D-optimal) and "
                                    "predict the identification's standard deviations")
        self.plan_button.clicked.connect(self.start_plan)
        self.save_button = QtWidgets.QPushButton("Save plan (TOML)…")
        self.save_button.clicked.connect(self._save)
        cells = (("triaxial sensors", self.n_sensors), ("excitations", self.n_points),
                 ("noise (of RMS)", self.noise), ("location std", self.location),
                 ("angle std", self.angle), ("gain std", self.gain))
        for k, (text, w) in enumerate(cells):
            g.addWidget(QtWidgets.QLabel(text), k // 3, 2 * (k % 3))
            g.addWidget(w, k // 3, 2 * (k % 3) + 1)
        g.addWidget(self.plan_button, 0, 6)
        g.addWidget(self.save_button, 1, 6)
        return g

    # --- inputs ------------------------------------------------------------------------------
    def _ask(self, which: str) -> None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(
            self, f"Load the {which} file", "", "Planning input (*.toml);;All files (*)")
        if name:
            self.load_files(**{which: Path(name)})

    def load_files(self, model: Path | None = None, candidates: Path | None = None) -> bool:
        """Use a model and/or a candidates file (TOML); False (with a message) when the pair
        cannot be read. The candidates are shown once both files are given."""
        m = model or self.model_path
        c = candidates or self.candidates_path
        if m is None or c is None:
            self.model_path, self.candidates_path = m, c
            self._show_files()
            return True
        try:
            inputs = load_inputs(m, c)
        except (ValueError, OSError) as err:
            self.message.emit("error", f"cannot plan from these files: {message_of(err)}")
            return False
        self.model_path, self.candidates_path, self.inputs = m, c, inputs
        self._show_files()
        self.sensors, self.excitations, self.prediction = [], [], None
        self._fill_candidates()
        self._show_prediction()
        cand = inputs.candidates
        self.candidates_changed.emit(cand.sensor_xyz, cand.point_xyz)
        set_verdict(self.status, None, f"{cand.sensor_nodes.size} candidate sensors, "
                    f"{cand.exc_point.size} candidate excitations: press Plan")
        return True

    def _show_files(self) -> None:
        self.files_label.setText(
            f"model: {self.model_path.name if self.model_path else '—'}; candidates: "
            f"{self.candidates_path.name if self.candidates_path else '—'}")

    def _fill_candidates(self) -> None:
        assert self.inputs is not None
        c = self.inputs.candidates
        rows = [("sensor", int(n), x, "x, y, z") for n, x in zip(c.sensor_nodes, c.sensor_xyz,
                                                                   strict=True)]
        rows += [("excitation", int(n), x, ", ".join(f"{v:+.2f}" for v in d))
                 for n, x, d in zip(c.exc_nodes, c.exc_xyz, c.exc_dirs, strict=True)]
        self._filling = True
        try:
            t = self.candidates_table
            t.setRowCount(len(rows))
            for i, (kind, node, xyz, d) in enumerate(rows):
                use = QtWidgets.QTableWidgetItem()
                use.setFlags(QtCore.Qt.ItemFlag.ItemIsUserCheckable
                             | QtCore.Qt.ItemFlag.ItemIsEnabled)
                use.setCheckState(QtCore.Qt.CheckState.Unchecked)
                t.setItem(i, 0, use)
                for j, text in enumerate((kind, str(node), *(f"{v:.3f}" for v in xyz), d)):
                    item = QtWidgets.QTableWidgetItem(text)
                    item.setFlags(item.flags() & ~QtCore.Qt.ItemFlag.ItemIsEditable)
                    t.setItem(i, j + 1, item)
            t.resizeColumnsToContents()
        finally:
            self._filling = False

    def _check_boxes(self) -> None:
        """Tick the chosen candidates."""
        assert self.inputs is not None
        n_s = self.inputs.candidates.sensor_nodes.size
        chosen = set(self.sensors) | {n_s + i for i in self.excitations}
        self._filling = True
        try:
            for i in range(self.candidates_table.rowCount()):
                item = self.candidates_table.item(i, 0)
                if item is not None:
                    item.setCheckState(QtCore.Qt.CheckState.Checked if i in chosen
                                       else QtCore.Qt.CheckState.Unchecked)
        finally:
            self._filling = False

    # --- planning and prediction -------------------------------------------------------------
    def _conditions(self) -> TestConditions | None:
        if self.inputs is None:
            self.message.emit("error", "cannot plan: load a model file and a candidates file "
                              "first")
            return None
        try:
            stated = StatedUncertainty(location=self.location.value() / 1000,
                                       angle=float(np.deg2rad(self.angle.value())),
                                       gain=self.gain.value() / 100)
            return conditions(self.inputs, self.noise.value() / 100, None, stated)
        except ValueError as err:
            self.message.emit("error", f"cannot plan: {message_of(err)}")
            return None

    def start_plan(self) -> bool:
        """Choose the layout on the worker thread (False, with a message, when it cannot
        start)."""
        cond = self._conditions()
        if cond is None:
            return False
        inputs, n_s, n_p = self.inputs, self.n_sensors.value(), self.n_points.value()
        assert inputs is not None
        self._cond, self._criterion = cond, "D"
        set_verdict(self.status, None, f"planning {n_s} sensors and {n_p} excitations…")
        self.runner.submit(_DESIGN, lambda: plan_layout(inputs, n_s, n_p, cond))
        return True

    def _on_check(self, item: QtWidgets.QTableWidgetItem) -> None:
        if self._filling or item.column() != 0 or self.inputs is None:
            return
        n_s = self.inputs.candidates.sensor_nodes.size
        rows = [i for i in range(self.candidates_table.rowCount())
                if (it := self.candidates_table.item(i, 0)) is not None
                and it.checkState() == QtCore.Qt.CheckState.Checked]
        self.set_layout([i for i in rows if i < n_s], [i - n_s for i in rows if i >= n_s])

    def set_layout(self, sensors: list[int], excitations: list[int]) -> None:
        """Use these candidate sensors and excitations (indices) and predict them again on
        the worker thread."""
        cond = self._cond or self._conditions()
        if cond is None or self.inputs is None:
            return
        inputs = self.inputs
        self._cond, self._criterion = cond, "edited by the operator"
        self.sensors, self.excitations = list(sensors), list(excitations)
        self._check_boxes()
        set_verdict(self.status, None, f"predicting {len(sensors)} sensors and "
                    f"{len(excitations)} excitations…")
        self.runner.submit(_PREDICT, lambda: predict_layout(inputs, sensors, excitations, cond))

    @QtCore.Slot(str, object)
    def _done(self, key: str, result: object) -> None:
        if key == _DESIGN and isinstance(result, TestDesign):
            self.sensors = list(result.layout.sensors)
            self.excitations = list(result.layout.excitations)
            self._check_boxes()
            self._use(result.prediction)
        elif key == _PREDICT and isinstance(result, Prediction):
            self._use(result)

    @QtCore.Slot(str, str)
    def _failed(self, key: str, message: str) -> None:
        if key not in (_DESIGN, _PREDICT):
            return
        self.prediction = None
        self._show_prediction()
        set_verdict(self.status, False, f"No prediction for this layout: {message}")
        self.message.emit("error", f"cannot {'plan' if key == _DESIGN else 'predict'} this "
                          f"layout: {message}")

    def _use(self, prediction: Prediction | None) -> None:
        """Show ``prediction`` and hand the layout on as the acquisition plan."""
        assert self.inputs is not None and self._cond is not None
        self.prediction = prediction
        self._show_prediction()
        data = plan_data(self.inputs, self.sensors, self.excitations, prediction, self._cond,
                         self._criterion)
        try:
            plan = parse_plan(data, "planner")
        except ValueError as err:
            self.message.emit("error", f"the planned layout is no acquisition plan: "
                              f"{message_of(err)}")
            return
        self._data, self.plan = data, plan
        g = prediction.geometry if prediction is not None else None
        set_verdict(self.status, True,
                    f"{len(self.sensors)} sensors, {len(self.excitations)} excitations"
                    + (f"; cond(E) {g.cond_E:.1f}, cond(T) {g.cond_T:.1f}" if g else "")
                    + "; this layout is the acquisition plan")
        self.planned.emit(plan)

    def _show_prediction(self) -> None:
        rows = predicted_rows(self.prediction.std) if self.prediction is not None else []
        fill_table(self.prediction_table, _PRED_COLUMNS, rows)

    def predicted_text(self, row: int) -> str:
        """The predicted std shown in the prediction table's ``row`` ("" when empty)."""
        item = self.prediction_table.item(row, 2)
        return item.text() if item is not None else ""

    # --- saving ------------------------------------------------------------------------------
    def _save(self) -> None:
        if self._data is None:
            self.message.emit("warning", "no planned layout yet: press Plan first")
            return
        name, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Save the plan", "plan.toml",
                                                        "Test plan (*.toml)")
        if name:
            self.save_plan(Path(name))

    def save_plan(self, path: Path) -> bool:
        """Write the planned layout as a plan TOML (``insitu acquire`` reads it)."""
        if self._data is None:
            return False
        header = ("written by the insitu GUI's planner;\n[prediction] holds the predicted "
                  "standard deviations (SI) the report shows beside the achieved ones")
        try:
            path.write_text(plan_toml(self._data, header), encoding="utf-8")
        except OSError as err:
            self.message.emit("error", f"cannot save the plan: {err.strerror or err}")
            return False
        self.message.emit("info", f"plan saved to {path.name}")
        self.saved.emit(path)
        return True
