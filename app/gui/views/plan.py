"""Test plan view: the table of response and excitation DOFs, three projections of the
points and directions, and the geometry check (rank and condition of E and T)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.acquire.plan import TestPlan, load_plan
from app.gui.plan_rows import (
    PlanRow,
    check_rows_geometry,
    read_csv_rows,
    rows_from_frf,
    rows_from_plan,
    write_csv_rows,
)
from app.gui.views.planner import PlannerPanel
from app.gui.views.projections import ProjectionsWidget
from app.gui.widgets import fill_table, set_verdict
from app.gui.worker import TaskRunner
from app.io.mounts import MountsFile, MountsFileError, load_mounts
from app.io.uff import read_frf_uff
from app.report.analysis import message_of
from drivers.station import StationConfig
from processing.mounts import check_mounts

__all__ = ["PlanView"]

_COLUMNS = ("role", "node", "x (m)", "y (m)", "z (m)", "dir x", "dir y", "dir z", "label")
_MOUNT_COLUMNS = ("mount", "x (m)", "y (m)", "z (m)", "u axis", "v axis", "w axis")


class PlanView(QtWidgets.QWidget):
    """Edit and check the plan ("Rows"), or plan it from candidates ("Planner",
    :class:`~app.gui.views.planner.PlannerPanel`, its jobs on ``runner``).

    Signals
    -------
    rows_changed(list)
        The plan's rows after an import or an edit.
    plan_loaded(object)
        An acquisition plan (:class:`~app.acquire.plan.TestPlan`) was imported from TOML.
    mounts_loaded(object)
        A mounts file (:class:`~app.io.mounts.MountsFile`) was loaded.
    message(str, str)
        (level, text) for the window's message bar.
    """

    rows_changed = QtCore.Signal(object)
    plan_loaded = QtCore.Signal(object)
    mounts_loaded = QtCore.Signal(object)
    message = QtCore.Signal(str, str)

    def __init__(self, runner: TaskRunner, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.station: StationConfig | None = None
        self.plan: TestPlan | None = None
        self.plan_path: Path | None = None
        self._filling = False
        buttons = QtWidgets.QHBoxLayout()
        self.import_plan_button = QtWidgets.QPushButton("Import plan (TOML)…")
        self.import_csv_button = QtWidgets.QPushButton("Import CSV…")
        self.import_uff_button = QtWidgets.QPushButton("Import UFF…")
        self.save_csv_button = QtWidgets.QPushButton("Save CSV…")
        self.add_button = QtWidgets.QPushButton("Add row")
        self.remove_button = QtWidgets.QPushButton("Remove row")
        self.mounts_button = QtWidgets.QPushButton("Load mounts (TOML)…")
        self.mounts_button.setToolTip("mounts file: crank_axis and [[mount]] name, position, "
                                      "axes (for the mount rates and the torque roll axis)")
        for b in (self.import_plan_button, self.import_csv_button, self.import_uff_button,
                  self.save_csv_button, self.add_button, self.remove_button,
                  self.mounts_button):
            buttons.addWidget(b)
        buttons.addStretch(1)
        self.import_plan_button.clicked.connect(self._import_plan)
        self.import_csv_button.clicked.connect(self._import_csv)
        self.import_uff_button.clicked.connect(self._import_uff)
        self.save_csv_button.clicked.connect(self._save_csv)
        self.add_button.clicked.connect(self._add_row)
        self.remove_button.clicked.connect(self._remove_row)
        self.mounts_button.clicked.connect(self._load_mounts)
        self.mounts: MountsFile | None = None
        self.mounts_table = QtWidgets.QTableWidget(0, len(_MOUNT_COLUMNS))
        self.mounts_table.setHorizontalHeaderLabels(list(_MOUNT_COLUMNS))
        self.mounts_table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.mounts_label = QtWidgets.QLabel("No mounts file: load one for the individual mount "
                                             "rates and the torque roll axis")
        self.mounts_label.setWordWrap(True)
        self.table = QtWidgets.QTableWidget(0, len(_COLUMNS))
        self.table.setHorizontalHeaderLabels(list(_COLUMNS))
        self.table.itemChanged.connect(self._on_edit)
        self.geometry_label = QtWidgets.QLabel()
        self.geometry_label.setWordWrap(True)
        self.geometry_details = QtWidgets.QLabel()
        self.geometry_details.setWordWrap(True)
        self.projections = ProjectionsWidget()
        left = QtWidgets.QWidget()
        ll = QtWidgets.QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        ll.addLayout(buttons)
        ll.addWidget(self.table, 3)
        ll.addWidget(self.geometry_label)
        ll.addWidget(self.geometry_details)
        ll.addWidget(self.mounts_label)
        ll.addWidget(self.mounts_table, 1)
        self.planner = PlannerPanel(runner)
        self.planner.message.connect(self.message)
        self.planner.planned.connect(self._planned)
        self.planner.saved.connect(self._plan_saved)
        self.planner.candidates_changed.connect(self.projections.set_candidates)
        self.sides = QtWidgets.QTabWidget()
        self.sides.addTab(left, "Rows")
        self.sides.addTab(self.planner, "Planner")
        self.sides.currentChanged.connect(
            lambda i: self.projections.show_candidates(self.sides.widget(i) is self.planner))
        self.projections.show_candidates(False)
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        split.addWidget(self.sides)
        split.addWidget(self.projections)
        split.setSizes([620, 700])
        lay = QtWidgets.QVBoxLayout(self)
        lay.addWidget(split)
        self._rows: list[PlanRow] = []
        set_verdict(self.geometry_label, None, "No plan yet: import one or add rows")

    # --- rows ----------------------------------------------------------------------------------
    def rows(self) -> list[PlanRow]:
        """The plan's rows as last checked."""
        return list(self._rows)

    def set_rows(self, rows: Sequence[PlanRow]) -> None:
        """Show ``rows`` in the table and the projections, and check the geometry."""
        self._filling = True
        try:
            self.table.setRowCount(len(rows))
            for i, r in enumerate(rows):
                cells = (r.role, str(r.node), *(f"{v:.4f}" for v in r.xyz),
                         *(f"{v:.4f}" for v in r.direction), r.label)
                for j, text in enumerate(cells):
                    self.table.setItem(i, j, QtWidgets.QTableWidgetItem(text))
            self.table.resizeColumnsToContents()
        finally:
            self._filling = False
        self._apply(list(rows))

    def set_frf_rows(self, frf: object) -> None:
        """Show the DOFs of loaded FRFs (replay)."""
        from processing.data import FRFSet

        if isinstance(frf, FRFSet):
            self.set_rows(rows_from_frf(frf))

    def _apply(self, rows: list[PlanRow]) -> None:
        self._rows = rows
        self.projections.set_rows(rows)
        self._check()
        self.rows_changed.emit(rows)

    def _check(self) -> None:
        try:
            rep = check_rows_geometry(self._rows)
        except ValueError as err:
            set_verdict(self.geometry_label, False, f"Geometry: {message_of(err)}")
            self.geometry_details.setText("")
            return
        n_r = sum(r.role == "response" for r in self._rows)
        n_e = len(self._rows) - n_r
        self.geometry_details.setText(
            f"{n_r} response DOFs, {n_e} excitation DOFs. rank E = {rep.rank_E}, "
            f"cond E = {rep.cond_E:.1f}; rank T = {rep.rank_T}, cond T = {rep.cond_T:.1f} "
            "(the article asks cond T < 20; rotations scaled by the size of the point cloud)")
        if not rep.ok:
            set_verdict(self.geometry_label, False,
                        "Geometry cannot identify all six DOFs: " + "; ".join(rep.messages))
        elif rep.messages:
            set_verdict(self.geometry_label, False, "Geometry warning: " + "; ".join(rep.messages))
        else:
            set_verdict(self.geometry_label, True, "Geometry OK: E and T span all six DOFs")

    def geometry_text(self) -> str:
        """The geometry verdict as shown."""
        return self.geometry_label.text()

    def _on_edit(self, item: QtWidgets.QTableWidgetItem) -> None:
        if self._filling:
            return
        rows: list[PlanRow] = []
        for i in range(self.table.rowCount()):
            cells = [_text(self.table.item(i, j)) for j in range(len(_COLUMNS))]
            try:
                role = cells[0].lower()
                if role not in ("response", "excitation"):
                    raise ValueError("role must be response or excitation")
                xyz = tuple(float(c) for c in cells[2:5])
                d = tuple(float(c) for c in cells[5:8])
                norm = sum(v * v for v in d) ** 0.5
                if norm == 0:
                    raise ValueError("the direction must not be zero")
                rows.append(PlanRow(role, int(cells[1]), xyz,  # type: ignore[arg-type]
                                    tuple(v / norm for v in d), cells[8]))
            except ValueError as err:
                set_verdict(self.geometry_label, False,
                            f"Row {i + 1}: {message_of(err)} (node an integer, x..dir z numbers)")
                return
        self._apply(rows)

    def _add_row(self) -> None:
        last = self._rows[-1] if self._rows else PlanRow("excitation", 1, (0, 0, 0), (0, 0, 1))
        self.set_rows([*self._rows, PlanRow(last.role, last.node + 1, last.xyz, last.direction)])

    def _remove_row(self) -> None:
        i = self.table.currentRow()
        if 0 <= i < len(self._rows):
            self.set_rows([r for k, r in enumerate(self._rows) if k != i])

    # --- files ---------------------------------------------------------------------------------
    def _ask_open(self, title: str, pattern: str) -> Path | None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(self, title, "", pattern)
        return Path(name) if name else None

    def _import_plan(self) -> None:
        path = self._ask_open("Import test plan", "Test plan (*.toml);;All files (*)")
        if path is not None:
            self.load_plan_file(path)

    def load_plan_file(self, path: Path) -> bool:
        """Import an acquisition plan (TOML); returns False (with a message) on failure."""
        try:
            plan = load_plan(path)
            rows = rows_from_plan(plan, self.station)
        except (ValueError, OSError) as err:
            self.message.emit("error", f"cannot import the plan: {message_of(err)}")
            return False
        self.plan, self.plan_path = plan, path
        self.set_rows(rows)
        self.plan_loaded.emit(plan)
        self.message.emit("info", f"plan {plan.name!r} imported from {path.name}: "
                          f"{len(plan.excitations)} excitation points")
        return True

    def _planned(self, plan: TestPlan) -> None:
        """The planner's layout becomes the acquisition plan, as an imported plan does."""
        self.plan, self.plan_path = plan, None
        self.set_rows(rows_from_plan(plan, self.station))
        self.plan_loaded.emit(plan)

    def _plan_saved(self, path: Path) -> None:
        if self.plan is self.planner.plan:
            self.plan_path = path
            self.plan_loaded.emit(self.plan)

    def _load_mounts(self) -> None:
        path = self._ask_open("Load mounts file", "Mounts (*.toml);;All files (*)")
        if path is not None:
            self.load_mounts_file(path)

    def load_mounts_file(self, path: Path) -> bool:
        """Read a mounts file (TOML); returns False (with a message) on failure."""
        try:
            mounts = load_mounts(path)
            check_mounts(mounts.mounts)
        except (MountsFileError, ValueError) as err:
            self.message.emit("error", f"cannot use the mounts file: {message_of(err)}")
            return False
        self.set_mounts(mounts)
        self.message.emit("info", f"{len(mounts.mounts)} mounts loaded from {path.name}")
        return True

    def set_mounts(self, mounts: MountsFile | None) -> None:
        """Show ``mounts`` in the table and the projections and pass them on."""
        if mounts is self.mounts:
            return
        self.mounts = mounts
        if mounts is None:
            fill_table(self.mounts_table, _MOUNT_COLUMNS, [])
            self.projections.set_mounts(np.zeros((0, 3)), np.zeros((0, 3, 3)))
        else:
            def vec(v: np.ndarray) -> str:
                return ", ".join(f"{x:+.3f}" for x in v)
            fill_table(self.mounts_table, _MOUNT_COLUMNS, [
                (m.name, *(f"{x:.4f}" for x in m.position), *(vec(a) for a in m.axes))
                for m in mounts.mounts])
            self.mounts_table.resizeColumnsToContents()
            rank, ident = check_mounts(mounts.mounts)
            t = mounts.crank_axis
            self.mounts_label.setText(
                f"<b>Mounts</b> ({len(mounts.mounts)}, crank axis [{t[0]:.3f}, {t[1]:.3f}, "
                f"{t[2]:.3f}]): this geometry determines {int(ident.sum())} of "
                f"{ident.size} rates (design rank {rank})")
            self.projections.set_mounts(np.array([m.position for m in mounts.mounts]),
                                        np.array([m.axes for m in mounts.mounts]))
        self.mounts_loaded.emit(mounts)

    def set_plan(self, plan: TestPlan, path: Path | None = None) -> None:
        """Show an acquisition plan given by the program (the mock bench's)."""
        self.plan, self.plan_path = plan, path
        self.set_rows(rows_from_plan(plan, self.station))

    def _import_csv(self) -> None:
        path = self._ask_open("Import plan CSV", "CSV (*.csv);;All files (*)")
        if path is None:
            return
        try:
            self.set_rows(read_csv_rows(path))
        except (ValueError, OSError) as err:
            self.message.emit("error", f"cannot import the CSV: {message_of(err)}")
        else:
            self.plan_path = path
            self.message.emit("info", f"{len(self._rows)} rows imported from {path.name}")

    def _import_uff(self) -> None:
        path = self._ask_open("Import DOFs from a UFF FRF file", "UFF (*.uff *.unv);;All (*)")
        if path is None:
            return
        try:
            self.set_rows(rows_from_frf(read_frf_uff(path)))
        except (ValueError, OSError) as err:
            self.message.emit("error", f"cannot import the UFF file: {message_of(err)}")
        else:
            self.plan_path = path
            self.message.emit("info", f"{len(self._rows)} DOFs imported from {path.name}")

    def _save_csv(self) -> None:
        if not self._rows:
            self.message.emit("warning", "the plan is empty: nothing to save")
            return
        name, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Save plan CSV", "plan.csv",
                                                        "CSV (*.csv)")
        if not name:
            return
        try:
            write_csv_rows(name, self._rows)
        except OSError as err:
            self.message.emit("error", f"cannot save the CSV: {message_of(err)}")
        else:
            self.message.emit("info", f"plan saved to {Path(name).name}")


def _text(item: QtWidgets.QTableWidgetItem | None) -> str:
    return item.text().strip() if item is not None else ""
