"""Export view: the run file (HDF5), the FRFs as UFF, the result as JSON and the report as
HTML (figures embedded as PNG) — each to a file the operator names."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from app.gui.session import Session
from app.io.uff import write_frf_uff
from app.pipeline import RUN_FILE
from app.report.analysis import Analysis
from app.report.html import build_report
from app.report.mount_system import mount_system

__all__ = ["ExportView"]


class ExportView(QtWidgets.QWidget):
    """Buttons for each export and a log of what was written where."""

    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self.run_button = QtWidgets.QPushButton("Save run file (HDF5)…")
        self.uff_button = QtWidgets.QPushButton("Export FRFs (UFF)…")
        self.json_button = QtWidgets.QPushButton("Export results (JSON)…")
        self.html_button = QtWidgets.QPushButton("Export report (HTML)…")
        self.run_button.setToolTip("Copy the run file of this test: raw records, verdicts, "
                                   "settings, FRFs and result")
        self.uff_button.setToolTip("FRFs with geometry (UFF 164, 2411, 58), as pyuff and "
                                   "'insitu identify' read them")
        self.json_button.setToolTip("The identification result (the result JSON of "
                                    "docs/conventions.md)")
        self.html_button.setToolTip("One self-contained HTML page with tables and figures")
        self.run_button.clicked.connect(self._save_run)
        self.uff_button.clicked.connect(self._export_uff)
        self.json_button.clicked.connect(self._export_json)
        self.html_button.clicked.connect(self._export_html)
        self.state = QtWidgets.QLabel()
        self.state.setWordWrap(True)
        self.log = QtWidgets.QListWidget()
        grid = QtWidgets.QGridLayout()
        for i, b in enumerate((self.run_button, self.uff_button, self.json_button,
                               self.html_button)):
            b.setFixedWidth(260)
            grid.addWidget(b, i, 0)
            grid.addWidget(QtWidgets.QLabel(b.toolTip()), i, 1)
        grid.setColumnStretch(1, 1)
        lay = QtWidgets.QVBoxLayout(self)
        lay.addWidget(self.state)
        lay.addLayout(grid)
        lay.addWidget(QtWidgets.QLabel("Written in this session:"))
        lay.addWidget(self.log, 1)
        self.written: list[Path] = []
        session.data_changed.connect(self._update)
        session.analysis_changed.connect(self._update)
        self._update()

    @QtCore.Slot()
    def _update(self, *_: object) -> None:
        s = self.session
        run = s.path is not None and s.format == RUN_FILE
        a = s.analysis
        self.run_button.setEnabled(run)
        self.uff_button.setEnabled(s.frf is not None)
        self.json_button.setEnabled(a is not None and a.result is not None)
        self.html_button.setEnabled(a is not None)
        if s.frf is None:
            self.state.setText("Nothing to export yet: open FRFs or a run, or run a test.")
        else:
            self.state.setText(
                f"Data: {s.source}. " + ("" if run else "No run file (the data came from a "
                                         "UFF file): the HDF5 export needs a recorded run. ")
                + ("" if a is None or a.result is not None
                   else "No identification result: the JSON export needs one."))

    def _ask(self, title: str, default: str, pattern: str) -> Path | None:
        name, _ = QtWidgets.QFileDialog.getSaveFileName(self, title, default, pattern)
        return Path(name) if name else None

    def _stem(self) -> str:
        return Path(self.session.source or "insitu").stem

    def _done(self, path: Path, what: str) -> None:
        self.written.append(path)
        self.log.addItem(f"{what}: {path}")
        self.session.message.emit("info", f"{what} written to {path}")

    def _fail(self, what: str, err: Exception) -> None:
        self.session.message.emit("error", f"cannot write the {what}: {err}")

    def _save_run(self) -> None:
        src = self.session.path
        if src is None:
            return
        path = self._ask("Save run file", f"{self._stem()}.h5", "HDF5 run file (*.h5)")
        if path is None:
            return
        try:
            if path.resolve() != src.resolve():
                shutil.copyfile(src, path)
        except OSError as err:
            self._fail("run file", err)
        else:
            self._done(path, "run file")

    def _export_uff(self) -> None:
        frf = self.session.frf
        if frf is None:
            return
        path = self._ask("Export FRFs", f"{self._stem()}-frf.uff", "UFF (*.uff)")
        if path is None:
            return
        try:
            write_frf_uff(path, frf)
        except (OSError, ValueError) as err:
            self._fail("UFF file", err)
        else:
            self._done(path, "FRFs (UFF)")

    def _export_json(self) -> None:
        a = self.session.analysis
        if a is None or a.result is None:
            return
        path = self._ask("Export results", f"{self._stem()}-result.json", "JSON (*.json)")
        if path is None:
            return
        try:
            out = a.result.to_json()
            try:  # modes with isolation, and with a mounts file its rates and the TRA
                out.update(mount_system(a.result, self.session.mounts).to_json())
            except ValueError as err:
                self.session.message.emit("warning", f"mount system left out: {err}")
            path.write_text(json.dumps(out, indent=2))
        except OSError as err:
            self._fail("result JSON", err)
        else:
            self._done(path, "result (JSON)")

    def write_report(self, a: Analysis, path: Path) -> None:
        """Write the HTML report of ``a`` to ``path`` (GUI thread: it draws figures)."""
        path.write_text(build_report(a, mounts=self.session.mounts), encoding="utf-8")

    def _export_html(self) -> None:
        a = self.session.analysis
        if a is None:
            return
        path = self._ask("Export report", f"{self._stem()}-report.html", "HTML (*.html)")
        if path is None:
            return
        QtWidgets.QApplication.setOverrideCursor(QtCore.Qt.CursorShape.WaitCursor)
        try:
            self.write_report(a, path)
        except OSError as err:
            self._fail("report", err)
        else:
            self._done(path, "report (HTML)")
        finally:
            QtWidgets.QApplication.restoreOverrideCursor()
