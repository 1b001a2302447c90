"""Checks view: every check with its verdict at a glance, coherence per FRF against the
threshold, coherence against frequency, and the rigidity check against frequency."""

from __future__ import annotations

from PySide6 import QtCore, QtWidgets

from app.gui.widgets import make_plot, set_verdict, verdict_color
from app.report import figures
from app.report.analysis import Analysis
from app.report.tables import CheckRow, check_rows

__all__ = ["ChecksView"]


class ChecksView(QtWidgets.QWidget):
    """Pass/fail of each check and the figures behind them."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.overall = QtWidgets.QLabel()
        self.table = QtWidgets.QTableWidget(0, 3)
        self.table.setHorizontalHeaderLabels(["check", "verdict", "figures"])
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setWordWrap(True)
        self.coherence_bars = make_plot(bottom="FRF number", bottom_units=None)
        self.coherence_freq = make_plot()
        self.rigidity = make_plot()
        grid = QtWidgets.QGridLayout()
        grid.addWidget(self.coherence_bars, 0, 0)
        grid.addWidget(self.coherence_freq, 0, 1)
        grid.addWidget(self.rigidity, 1, 0, 1, 2)
        lay = QtWidgets.QVBoxLayout(self)
        lay.addWidget(self.overall)
        lay.addWidget(self.table)
        lay.addLayout(grid, 1)
        self.rows: list[CheckRow] = []
        set_verdict(self.overall, None, "No data: open a file or run a test")

    @QtCore.Slot(object)
    def show_analysis(self, a: Analysis) -> None:
        """Redraw for a new analysis."""
        self.rows = check_rows(a)
        self.table.setRowCount(len(self.rows))
        for i, c in enumerate(self.rows):
            verdict = QtWidgets.QTableWidgetItem(c.verdict)
            verdict.setBackground(verdict_color(c.passed))
            verdict.setForeground(QtCore.Qt.GlobalColor.white)
            verdict.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
            self.table.setItem(i, 0, QtWidgets.QTableWidgetItem(c.name))
            self.table.setItem(i, 1, verdict)
            detail = QtWidgets.QTableWidgetItem(c.detail)
            detail.setToolTip(c.detail)
            self.table.setItem(i, 2, detail)
        self.table.resizeColumnToContents(0)
        self.table.resizeRowsToContents()
        failed = [c.name for c in self.rows if c.passed is False]
        unchecked = [c.name for c in self.rows if c.passed is None]
        if failed:
            set_verdict(self.overall, False, "FAIL: " + ", ".join(failed))
        elif unchecked:
            set_verdict(self.overall, None, "No check fails; not checked: "
                        + ", ".join(unchecked))
        else:
            set_verdict(self.overall, True, "All checks pass")
        figures.draw_coherence_bars(self.coherence_bars.getPlotItem(), a)
        figures.draw_coherence_freq(self.coherence_freq.getPlotItem(), a)
        figures.draw_rigidity(self.rigidity.getPlotItem(), a)

    def verdicts(self) -> dict[str, bool | None]:
        """Check name -> verdict, as shown."""
        return {c.name: c.passed for c in self.rows}
