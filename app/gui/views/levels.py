"""Live level meters and traces of streaming channels (Station view, GUI benchmark).

Bars give each channel's peak over the last half second as a percentage of its full scale
(green below 80 %, orange below 100 %, red at overload, latched until reset); the traces
show the last seconds of every channel. A QTimer (30 Hz) drains the stream's queue into a
:class:`app.gui.ring.RevealRing` (every block is used, none dropped) and redraws with
``setData``, revealing the samples by the time elapsed since the last redraw: the traces
scroll at the timer's rate, whatever the stream's reads a second, at most 0.3 s behind the
newest sample. ``frames`` counts the timer's ticks and ``frames_new`` the redraws that
showed new samples.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from app.gui.ring import RevealRing
from app.gui.streaming import StreamThread
from app.gui.widgets import make_plot
from app.report.figures import COLORS

__all__ = ["LevelsWidget"]

_GREEN, _ORANGE, _RED = "#009E73", "#E69F00", "#D55E00"


class LevelsWidget(QtWidgets.QWidget):
    """Level bars and traces fed by a :class:`StreamThread`.

    Parameters
    ----------
    fps : redraws per second (at most: a tick with no new block draws nothing)
    seconds : length of the traces, s
    """

    def __init__(self, fps: float = 30.0, seconds: float = 2.0,
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
        self.frames_new = 0
        self.samples = 0
        self.latencies: list[float] = []
        self._curves: list[pg.PlotDataItem] = []
        self.ring: RevealRing | None = None
        self._last_tick = 0.0
        self._latched = np.zeros(0, bool)

    def attach(self, stream: StreamThread) -> None:
        """Show ``stream`` (already created, started by the caller)."""
        src = stream.source
        n_ch = len(src.names)
        self.stream = stream
        self._names = src.names
        self._fs = src.fs
        self._half = max(1, int(0.5 * src.fs))
        self._full = np.where(src.full_scale > 0, src.full_scale, 1.0)
        self.ring = RevealRing(n_ch, src.fs, self.seconds)
        self._latched = np.zeros(n_ch, bool)
        plot = self.traces_plot.getPlotItem()
        for c in self._curves:
            plot.removeItem(c)
        n = self.ring.n
        self._t = (np.arange(n) - n + 1) / src.fs
        # live curves: no antialiasing (NaN before the first samples and where samples
        # were lost: the finite check stays on)
        self._curves = [plot.plot(name=name, antialias=False,
                                  pen=pg.mkPen(COLORS[k % len(COLORS)], width=1))
                        for k, name in enumerate(src.names)]
        plot.setXRange(-self.seconds, 0, padding=0)
        self.bars_plot.getPlotItem().setXRange(-0.5, n_ch - 0.5)
        ax = self.bars_plot.getPlotItem().getAxis("bottom")
        step = max(1, n_ch // 16)
        ax.setTicks([[(k, src.names[k]) for k in range(0, n_ch, step)]])
        self.frames = self.frames_new = 0
        self.samples = 0
        self.latencies = []
        self._last_tick = time.monotonic()
        self.timer.start()

    def detach(self) -> None:
        """Stop redrawing (the caller stops the stream)."""
        self.timer.stop()
        self.stream = None

    def reset_overloads(self) -> None:
        self._latched[:] = False
        self.overload_label.setText("")

    @QtCore.Slot()
    def update_once(self, catch_up: bool = False) -> None:
        """Drain the queue and redraw what is due (everything with ``catch_up``; GUI thread)."""
        if self.stream is None or self.ring is None:
            return
        now = time.monotonic()
        dt, self._last_tick = now - self._last_tick, now
        self.frames += 1
        blocks = self.stream.drain()
        for b in blocks:
            self.ring.add(b.data, b.t_read)
            self.samples += b.data.shape[1]
            self._latched |= b.overloaded
        if not self.ring.advance(dt, catch_up):
            return
        ring = self.ring.view()
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN before the first block
            pct = np.nan_to_num(np.nanmax(np.abs(ring[:, -self._half:]), axis=1)) / self._full * 100
        self._latched |= pct >= 100
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
        self.latencies += self.ring.latencies(now)
        self.frames_new += 1

    def peak_percent(self) -> np.ndarray:
        """Peak of the last half second per channel, % of full scale (as drawn)."""
        if self.ring is None:
            return np.zeros(0)
        recent = self.ring.view()[:, -self._half:]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.asarray(np.nan_to_num(np.nanmax(np.abs(recent), axis=1))
                              / self._full * 100)
