"""Continuous force and acceleration traces of a running acquisition.

The procedure hands every read of its streams to its listeners (``on_samples``, about ten
reads a second); :class:`app.gui.acquisition_bridge.AcquisitionBridge` queues them and a
QTimer of :class:`LiveTraces` drains the queue on the GUI thread at ``fps`` (30 by default)
into a fixed-size ring buffer (:class:`app.gui.ring.RevealRing`), then redraws with
``setData`` on existing curves (clip-to-view and peak downsampling are on in
:func:`app.gui.widgets.make_plot`).

Every sample is drawn, none is dropped; the traces run a little behind the stream (by at
most ``lag`` s, one read at most in practice) and advance by the time elapsed at every
frame, so they scroll steadily at the redraw rate instead of jumping at each read.
``frames`` counts the timer's ticks and ``frames_new`` the redraws that showed samples not
shown before.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Sequence

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6 import QtCore, QtWidgets

from app.acquire.events import SampleBlock
from app.gui.ring import RevealRing
from app.gui.widgets import make_plot
from app.report.figures import COLORS

__all__ = ["LiveTraces"]


class LiveTraces(QtCore.QObject):
    """The last ``seconds`` of the forces (the first rows) and responses, in two plots.

    Parameters
    ----------
    source : queue.SimpleQueue of SampleBlock
        Filled by the procedure's worker (through the bridge), drained here.
    seconds : float
        Length shown, s.
    fps : float
        Redraws per second.
    lag : float
        Largest delay of the traces behind the newest samples, s; beyond it they jump
        forward (a stall of the GUI thread is caught up at once).
    """

    def __init__(self, source: queue.SimpleQueue[SampleBlock], seconds: float = 5.0,
                 fps: float = 30.0, lag: float = 0.3,
                 parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.source = source
        self.seconds, self.lag = seconds, lag
        self.force_plot = make_plot(f"Force, live (last {seconds:g} s)", "force", "N",
                                    "time", "s")
        self.acc_plot = make_plot(f"Accelerations, live (last {seconds:g} s)", "acceleration",
                                  "m/s²", "time", "s")
        for w in (self.force_plot, self.acc_plot):
            w.getPlotItem().setXRange(-seconds, 0, padding=0)
        self._legend = self.acc_plot.getPlotItem().addLegend(
            offset=(-5, 5), labelTextSize="7pt", colCount=4)
        self._curves: list[pg.PlotDataItem] = []
        self._n_force_curves = 0
        self._force_legend: pg.LegendItem | None = None
        self.names: tuple[str, ...] = ()
        self.n_forces = 1
        self.fs = 0.0
        self.ring: RevealRing | None = None
        self._t: NDArray[np.float64] = np.zeros(0)
        self.frames = 0
        self.frames_new = 0
        self.latencies: list[float] = []  # read to screen, s
        self._last_tick = 0.0
        self.timer = QtCore.QTimer(self)
        self.timer.setInterval(max(1, round(1000 / fps)))
        self.timer.timeout.connect(self.update_once)

    @property
    def widgets(self) -> tuple[QtWidgets.QWidget, QtWidgets.QWidget]:
        return self.force_plot, self.acc_plot

    def start(self, n_forces: int = 1) -> None:
        """Clear the traces and the counters and start redrawing (a run starts); the first
        ``n_forces`` rows of the samples are forces."""
        self.n_forces = n_forces
        while not self.source.empty():
            self.source.get_nowait()
        self.names, self.fs, self.ring = (), 0.0, None
        self.frames = self.frames_new = 0
        self.latencies = []
        self._last_tick = time.monotonic()
        self.timer.start()

    def stop(self) -> None:
        """Draw what is queued, then stop redrawing (the run ended)."""
        self.update_once(catch_up=True)
        self.timer.stop()

    def _reset(self, names: Sequence[str], fs: float) -> None:
        """New channels: a new ring and new curves."""
        self.names, self.fs = tuple(names), fs
        self.ring = RevealRing(len(names), fs, self.seconds, self.lag)
        n = self.ring.n
        self._t = (np.arange(n) - n + 1) / fs
        nf = self.n_forces
        for k, c in enumerate(self._curves):
            (self.force_plot if k < self._n_force_curves else self.acc_plot
             ).getPlotItem().removeItem(c)
        self._legend.clear()
        if self._force_legend is not None:
            self._force_legend.clear()
        elif nf > 1:
            self._force_legend = self.force_plot.getPlotItem().addLegend(
                offset=(-5, 5), labelTextSize="7pt", colCount=nf)
        self._curves = [self.force_plot.getPlotItem().plot(
            pen=pg.mkPen(COLORS[(1 + k) % len(COLORS)]), name=name if nf > 1 else None)
            for k, name in enumerate(self.names[:nf])]
        self._n_force_curves = nf
        for k, name in enumerate(self.names[nf:]):
            self._curves.append(self.acc_plot.getPlotItem().plot(
                pen=pg.mkPen(COLORS[k % len(COLORS)]), name=name, antialias=False))

    @property
    def received(self) -> int:
        """Samples per channel received since the run started."""
        return self.ring.received if self.ring is not None else 0

    @property
    def shown(self) -> int:
        """Samples per channel drawn so far."""
        return self.ring.shown if self.ring is not None else 0

    @QtCore.Slot()
    def update_once(self, catch_up: bool = False) -> None:
        """Drain the queue and advance the traces by the time elapsed (GUI thread)."""
        now = time.monotonic()
        dt, self._last_tick = now - self._last_tick, now
        while True:
            try:
                block = self.source.get_nowait()
            except queue.Empty:
                break
            if block.names != self.names or block.fs != self.fs:
                self._reset(block.names, block.fs)
            assert self.ring is not None
            self.ring.add(block.data, block.t_read)
        if self.ring is None:
            return
        self.frames += 1
        if not self.ring.advance(dt, catch_up):
            return
        view = self.ring.view()
        for row, curve in enumerate(self._curves):
            curve.setData(self._t, view[row])
        self.frames_new += 1
        self.latencies += self.ring.latencies(now)
