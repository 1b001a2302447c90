"""Small widgets shared by the views: the message bar, plots, tables, verdict labels."""

from __future__ import annotations

from collections.abc import Sequence

import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

__all__ = ["MessageBar", "fill_table", "make_plot", "set_verdict", "verdict_color"]

_LEVEL_STYLE = {
    "info": "background:#e8f1fb; color:#0b3d6b; border:1px solid #9cc3e6;",
    "warning": "background:#fff4e0; color:#6b4000; border:1px solid #e6b35c;",
    "error": "background:#fde8e4; color:#7a1a00; border:1px solid #e08a70;",
}


class MessageBar(QtWidgets.QFrame):
    """A one-line message at the top of the window: what happened, in plain words.

    Errors stay until dismissed or replaced; info messages fade after a few seconds.
    """

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.label = QtWidgets.QLabel()
        self.label.setWordWrap(True)
        self.label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        close = QtWidgets.QToolButton()
        close.setText("✕")
        close.setToolTip("Dismiss this message")
        close.clicked.connect(self.hide)
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(8, 4, 4, 4)
        lay.addWidget(self.label, 1)
        lay.addWidget(close)
        self.level = ""
        self._timer = QtCore.QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.timeout.connect(self.hide)
        self.hide()

    @QtCore.Slot(str, str)
    def show_message(self, level: str, text: str) -> None:
        """Show ``text``; ``level`` is "info", "warning" or "error"."""
        self.level = level
        self.label.setText(text)
        self.setStyleSheet(f"MessageBar {{{_LEVEL_STYLE.get(level, _LEVEL_STYLE['info'])}}}")
        self.label.setStyleSheet("border:none; background:transparent;")
        self.show()
        if level == "info":
            self._timer.start(6000)
        else:
            self._timer.stop()

    @property
    def text(self) -> str:
        return self.label.text() if self.isVisible() else ""


def make_plot(title: str = "", left: str = "", left_units: str | None = None,
              bottom: str = "frequency", bottom_units: str | None = "Hz", *,
              logy: bool = False) -> pg.PlotWidget:
    """A plot with labelled axes, a grid and clip-to-view/auto-downsampling for live data."""
    w = pg.PlotWidget()
    p = w.getPlotItem()
    if logy:
        p.setLogMode(y=True)
        p.getAxis("left").enableAutoSIPrefix(False)
    if title:
        p.setTitle(title, size="10pt")
    p.setLabel("left", left, units=left_units)
    p.setLabel("bottom", bottom, units=bottom_units)
    p.showGrid(x=True, y=True, alpha=0.25)
    p.setClipToView(True)
    p.setDownsampling(auto=True, mode="peak")
    w.setMinimumHeight(160)
    return w


def fill_table(table: QtWidgets.QTableWidget, head: Sequence[str],
               rows: Sequence[Sequence[str]], vertical: Sequence[str] | None = None) -> None:
    """Replace a read-only table's contents with text cells."""
    table.clear()
    table.setColumnCount(len(head))
    table.setRowCount(len(rows))
    table.setHorizontalHeaderLabels(list(head))
    if vertical is not None:
        table.setVerticalHeaderLabels(list(vertical))
    table.verticalHeader().setDefaultSectionSize(table.fontMetrics().height() + 6)
    for i, row in enumerate(rows):
        for j, text in enumerate(row):
            item = QtWidgets.QTableWidgetItem(text)
            item.setFlags(item.flags() & ~QtCore.Qt.ItemFlag.ItemIsEditable)
            if j > 0 and _numeric(text):
                item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignRight
                                      | QtCore.Qt.AlignmentFlag.AlignVCenter)
            table.setItem(i, j, item)
    table.resizeColumnsToContents()


def _numeric(text: str) -> bool:
    """A number, alone or followed by its 95 % spread (``"1.5 ± 0.2"``, ``"1.5 [1.2, 1.9]"``)."""
    try:
        float(text.split(" ± ")[0].split(" [")[0])
    except ValueError:
        return False
    return True


def verdict_color(passed: bool | None) -> QtGui.QColor:
    """Green for pass, orange-red for fail, grey when no verdict."""
    return QtGui.QColor({True: "#009E73", False: "#D55E00", None: "#888888"}[passed])


def set_verdict(label: QtWidgets.QLabel, passed: bool | None, text: str) -> None:
    """A bold coloured verdict label (white on green/red/grey)."""
    label.setText(text)
    label.setStyleSheet(f"background:{verdict_color(passed).name()}; color:white; "
                        "font-weight:bold; padding:4px 8px; border-radius:3px;")
