"""Live level meters and traces of streaming channels (Station view, GUI benchmark).

Bars give each channel's peak over the last half second as a percentage of its full scale
(green below 80 %, orange below 100 %, red at overload, latched until reset); the traces
show the last seconds of every channel. A QTimer drains the stream's queue (every block is
used, none dropped) and redraws with ``setData``.
"""

from __future__ import annotations

import time

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from app.gui.streaming import StreamThread
from app.gui.widgets import make_plot
from app.report.figures import COLORS

__all__ = ["LevelsWidget"]

_GREEN, _ORANGE, _RED = "#009E73", "#E69F00", "#D55E00"


class LevelsWidget(QtWidgets.QWidget):
    """Level bars and traces fed by a :class:`StreamThread`.

    Parameters
    ----------
    fps : redraws per second
    seconds : length of the traces, s
    """

    def __init__(self, fps: float = 25.0, seconds: float = 2.0,
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.seconds = seconds
        self.bars_plot = make_plot("Peak level per channel (last 0.5 s)", "% of full scale",
                                   None, "channel", None)
        self.bars_plot.getPlotItem().setYRange(0, 110)
        self.bars_plot.getPlotItem().addItem(pg.InfiniteLine(
            pos=100, angle=0, pen=pg.mkPen(_RED, style=QtCore.Qt.PenStyle.DashLine),
            label="overload", labelOpts={"position": 0.02, "color": _RED,
                                         "anchors": [(0, 1), (0, 1)]}))
        self.bars = pg.BarGraphItem(x=[], height=[], width=0.8)
        self.bars_plot.getPlotItem().addItem(self.bars)
        self.traces_plot = make_plot("Live signals (each as % of its full scale)",
                                     "% of full scale", None, "time", "s")
        self.traces_plot.getPlotItem().addLegend(offset=(-5, 5), labelTextSize="7pt",
                                                 colCount=4)
        # grid lines over the whole view cost more to paint than the 25 curves: none here
        for w in (self.bars_plot, self.traces_plot):
            w.getPlotItem().showGrid(x=False, y=False)
        self.overload_label = QtWidgets.QLabel("")
        self.overload_label.setWordWrap(True)
        self.reset_button = QtWidgets.QPushButton("Reset overloads")
        self.reset_button.clicked.connect(self.reset_overloads)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.overload_label, 1)
        row.addWidget(self.reset_button)
        lay.addLayout(row)
        lay.addWidget(self.bars_plot, 1)
        lay.addWidget(self.traces_plot, 2)
        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(int(1000 / fps))
        self.timer.timeout.connect(self.update_once)
        self.stream: StreamThread | None = None
        self.frames = 0
        self.samples = 0
        self.latencies: list[float] = []
        self._curves: list[pg.PlotDataItem] = []
        self._ring = np.zeros((0, 0))
        self._peak_ring = np.zeros((0, 0))
        self._latched = np.zeros(0, bool)

    def attach(self, stream: StreamThread) -> None:
        """Show ``stream`` (already created, started by the caller)."""
        src = stream.source
        n_ch = len(src.names)
        self.stream = stream
        self._names = src.names
        self._fs = src.fs
        self._full = np.where(src.full_scale > 0, src.full_scale, 1.0)
        self._ring = np.zeros((n_ch, max(2, int(self.seconds * src.fs))))
        self._latched = np.zeros(n_ch, bool)
        plot = self.traces_plot.getPlotItem()
        for c in self._curves:
            plot.removeItem(c)
        t = np.arange(self._ring.shape[1]) / src.fs - self.seconds
        self._t = t
        # live curves: no antialiasing, no finite check (NaN only where samples were lost)
        self._curves = [plot.plot(t, self._ring[k], name=name, antialias=False,
                                  skipFiniteCheck=True,
                                  pen=pg.mkPen(COLORS[k % len(COLORS)], width=1))
                        for k, name in enumerate(src.names)]
        self.bars_plot.getPlotItem().setXRange(-0.5, n_ch - 0.5)
        ax = self.bars_plot.getPlotItem().getAxis("bottom")
        step = max(1, n_ch // 16)
        ax.setTicks([[(k, src.names[k]) for k in range(0, n_ch, step)]])
        self.frames = 0
        self.samples = 0
        self.latencies = []
        self.timer.start()

    def detach(self) -> None:
        """Stop redrawing (the caller stops the stream)."""
        self.timer.stop()
        self.stream = None

    def reset_overloads(self) -> None:
        self._latched[:] = False
        self.overload_label.setText("")

    @QtCore.Slot()
    def update_once(self) -> None:
        """Drain the queue and redraw (GUI thread)."""
        if self.stream is None:
            return
        blocks = self.stream.drain()
        if not blocks:
            return
        data = np.hstack([b.data for b in blocks])
        over = np.any([b.overloaded for b in blocks], axis=0)
        n = data.shape[1]
        self.samples += n
        ring = self._ring
        if n >= ring.shape[1]:
            ring[:] = data[:, -ring.shape[1]:]
        else:
            ring[:, :-n] = ring[:, n:]
            ring[:, -n:] = data
        recent = ring[:, -max(1, int(0.5 * self._fs)):]
        with np.errstate(invalid="ignore"):
            pct = np.nan_to_num(np.nanmax(np.abs(recent), axis=1)) / self._full * 100
        self._latched |= over | (pct >= 100)
        brushes = [_RED if self._latched[k] else _ORANGE if p >= 80 else _GREEN
                   for k, p in enumerate(pct)]
        self.bars.setOpts(x=np.arange(pct.size), height=np.minimum(pct, 110), width=0.8,
                          brushes=brushes, pen=None)
        scaled = ring / self._full[:, None] * 100
        for k, c in enumerate(self._curves):
            c.setData(self._t, scaled[k])
        if np.any(self._latched):
            names = [self._names[k] for k in np.flatnonzero(self._latched)]
            self.overload_label.setText("OVERLOAD on " + ", ".join(names)
                                        + ": lower the gain or hit softer, then reset")
            self.overload_label.setStyleSheet(f"color:{_RED}; font-weight:bold;")
        now = time.monotonic()
        self.latencies.append(now - blocks[0].t_read)
        self.frames += 1

    def peak_percent(self) -> np.ndarray:
        """Peak of the last half second per channel, % of full scale (as drawn)."""
        recent = self._ring[:, -max(1, int(0.5 * self._fs)):]
        return np.asarray(np.nanmax(np.abs(recent), axis=1) / self._full * 100)
