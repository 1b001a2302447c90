"""The plots of the Acquisition view.

Left: the live force and accelerations (:class:`app.gui.views.live.LiveTraces`, continuous
while the devices stream) and the force record of one hit or block (the latest, or the one
selected in the table: what its verdict is about). Right: the averaged FRF magnitude and
the coherence (with the 0.8 limit) of the current point, updated per hit or block.
"""

from __future__ import annotations

import queue

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from app.acquire.events import HitRecord, PointFRF, SampleBlock
from app.gui.views.live import LiveTraces
from app.gui.widgets import make_plot
from app.report.figures import COLORS

__all__ = ["AcquisitionPlots"]


class AcquisitionPlots(QtWidgets.QWidget):
    """Live traces, one record, and the current point's FRF and coherence.

    Parameters
    ----------
    samples : queue.SimpleQueue of SampleBlock
        The acquisition bridge's queue of streamed samples.
    """

    def __init__(self, samples: queue.SimpleQueue[SampleBlock],
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.live = LiveTraces(samples, parent=self)
        self.record_plot = make_plot("Force record of the latest hit", "force", "N", "time",
                                     "s")
        self._record_curve = self.record_plot.getPlotItem().plot(pen=pg.mkPen(COLORS[1]))
        self.frf_plot = make_plot("FRF magnitude of the current point (average)",
                                  "|H| ((m/s²)/N)", logy=True)
        self.coh_plot = make_plot("Coherence of the current point", "coherence")
        self.coh_plot.getPlotItem().setYRange(0, 1.05)
        self.coh_plot.getPlotItem().addItem(pg.InfiniteLine(
            pos=0.8, angle=0, pen=pg.mkPen(COLORS[1], style=QtCore.Qt.PenStyle.DashLine),
            label="0.8", labelOpts={"position": 0.03, "color": COLORS[1]}))
        self._frf_curves: list[pg.PlotDataItem] = []
        self._coh_curves: list[pg.PlotDataItem] = []
        grid = QtWidgets.QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        force, acc = self.live.widgets
        grid.addWidget(force, 0, 0, 2, 1)
        grid.addWidget(acc, 2, 0, 2, 1)
        grid.addWidget(self.record_plot, 4, 0, 2, 1)
        grid.addWidget(self.frf_plot, 0, 1, 3, 1)
        grid.addWidget(self.coh_plot, 3, 1, 3, 1)
        self.word = "hit"
        self.stop_word = "point"

    def start(self, word: str, n_forces: int = 1) -> None:
        """A run starts: ``word`` is "hit" (hammer) or "block" (shaker); the records' first
        ``n_forces`` rows are forces (two shakers driven at once: 2)."""
        self.word = word
        self.stop_word = "point" if n_forces == 1 else "drive"
        self._record_curve.setData([], [])
        self.record_plot.getPlotItem().setTitle(f"Force record of the latest {word}",
                                                size="10pt")
        for c in self._frf_curves + self._coh_curves:
            c.setData([], [])
        self.live.start(n_forces)

    def stop(self) -> None:
        self.live.stop()

    def show_record(self, hit: HitRecord, verdict: str) -> None:
        """Draw the force of ``hit`` (its data must be kept) with its verdict in the title."""
        if hit.data is None or not hit.fs:
            return
        t = np.arange(hit.data.shape[1]) / hit.fs
        self._record_curve.setData(t, hit.data[0])
        self.record_plot.getPlotItem().setTitle(
            f"Force record of {self.word} {hit.hit_id + 1} ({self.stop_word} {hit.point + 1}): "
            f"{verdict}",
            size="10pt")

    def show_frf(self, frf: PointFRF, names: list[str], where: str = "") -> None:
        """The averaged FRF and coherence of one point (lines above 0 Hz, up to fs/2.56);
        ``where`` names it in the titles (default "point N")."""
        where = where or f"point {frf.point + 1}"
        n = 0 if frf.H is None else frf.H.shape[0]
        for curves, plot in ((self._frf_curves, self.frf_plot),
                             (self._coh_curves, self.coh_plot)):
            if not curves and n and plot is self.frf_plot:
                # bottom right: below the mass line, above the anti-resonances
                plot.getPlotItem().addLegend(offset=(-5, -5), labelTextSize="7pt", colCount=4)
            while len(curves) < n:
                k = len(curves)
                curves.append(plot.getPlotItem().plot(
                    pen=pg.mkPen(COLORS[k % len(COLORS)]),
                    name=names[k] if plot is self.frf_plot and k < len(names) else None))
        # above fs / 2.56 the anti-alias filters shape the data
        keep = (frf.freq > 0) & (frf.freq <= frf.freq[-1] / 1.28) if frf.freq.size else frf.freq > 0
        for k, c in enumerate(self._frf_curves):
            if frf.H is None or k >= n:
                c.setData([], [])
            else:
                c.setData(frf.freq[keep], np.abs(frf.H[k, keep]))
        for k, c in enumerate(self._coh_curves):
            if frf.coherence is None or k >= n:
                c.setData([], [])
            else:
                c.setData(frf.freq[keep], np.nan_to_num(frf.coherence[k, keep]))
        self.frf_plot.getPlotItem().setTitle(
            f"FRF{'' if 'drive' in where else ' magnitude'}, {where} ({frf.n_averages} {self.word}"
            f"{'' if frf.n_averages == 1 else 's'} averaged)", size="10pt")
        note = f" (1 by definition with one {self.word})" if frf.n_averages == 1 else ""
        self.coh_plot.getPlotItem().setTitle(f"Coherence, {where}{note}",
                                             size="10pt")
