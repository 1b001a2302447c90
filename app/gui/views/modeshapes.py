"""Mode shapes as arrows in the three plan projections (top, front, side).

Each arrow starts at a point of the body (the response points, the mounts, the CoG) and
shows its displacement ``u(p) = u_O + theta x p`` in the chosen rigid-body mode, scaled so
the longest arrow is a quarter of the drawing's size. The torque roll axis and the mounts'
elastic axis are drawn as lines through the view when known.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6 import QtWidgets

from app.gui.views.projections import VIEWS, projection_plot
from app.report.figures import COLORS
from app.report.mount_system import MountSystem

__all__ = ["ModeShapesWidget"]



class ModeShapesWidget(QtWidgets.QWidget):
    """A mode selector and three projections of the selected mode's displacements."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.mode = QtWidgets.QComboBox()
        self.mode.currentIndexChanged.connect(self._draw)
        self.caption = QtWidgets.QLabel(
            f"<span style='color:{COLORS[0]}'>●</span> body points "
            f"<span style='color:{COLORS[2]}'>■</span> mounts, "
            "<b>+</b> centre of gravity; black arrows: each point's displacement in the mode "
            "(scaled, from the point to the dot); "
            f"<span style='color:{COLORS[1]}'>—</span> torque roll axis, "
            f"<span style='color:{COLORS[3]}'>- -</span> elastic axis")
        self.caption.setWordWrap(True)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("Mode:"))
        top.addWidget(self.mode, 1)
        grid = QtWidgets.QGridLayout()
        self.plots: list[pg.PlotWidget] = []
        for k, (title, i, j) in enumerate(VIEWS):
            w = projection_plot(title, i, j)
            self.plots.append(w)
            grid.addWidget(w, k // 2, k % 2)
        grid.addWidget(self.caption, 1, 1)
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addLayout(top)
        lay.addLayout(grid, 1)
        self._ms: MountSystem | None = None
        self._points = np.zeros((0, 3))

    def set_system(self, ms: MountSystem | None, points: NDArray[np.float64]) -> None:
        """Show the modes of ``ms`` at ``points`` (n, 3), m (plus its mounts and CoG)."""
        self._ms, self._points = ms, np.asarray(points, dtype=float).reshape(-1, 3)
        current = self.mode.currentIndex()
        self.mode.blockSignals(True)
        self.mode.clear()
        if ms is not None and ms.modes is not None:
            for r, (f, dom) in enumerate(zip(ms.modes.frequency_hz, ms.modes.dominant(),
                                             strict=True)):
                self.mode.addItem(f"mode {r + 1}: {f:.2f} Hz, mostly {dom}")
            self.mode.setCurrentIndex(max(current, 0))
        self.mode.blockSignals(False)
        self._draw()

    def arrows(self, mode: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(start points (n, 3), displacements (n, 3)) drawn for ``mode`` (unscaled)."""
        ms = self._ms
        assert ms is not None and ms.modes is not None
        pts = [self._points]
        if ms.mounts is not None:
            pts.append(np.array([m.position for m in ms.mounts.mounts]))
        pts.append(ms.cog[None, :])
        P = np.vstack(pts)
        phi = ms.modes.shapes[:, mode]
        return P, phi[:3] + np.cross(phi[3:], P)

    def _draw(self) -> None:
        for w in self.plots:
            w.getPlotItem().clear()
        ms = self._ms
        r = self.mode.currentIndex()
        if ms is None or ms.modes is None or r < 0:
            return
        P, U = self.arrows(r)
        span = float(np.ptp(P, axis=0).max()) if len(P) > 1 else 1.0
        scale = 0.25 * max(span, 1e-3) / max(float(np.abs(U).max()), 1e-300)
        tips = P + scale * U
        seg = np.empty((2 * len(P), 3))
        seg[0::2], seg[1::2] = P, tips
        n_pts = len(self._points)
        mounts = np.array([m.position for m in ms.mounts.mounts]) if ms.mounts else None
        for k, (_, i, j) in enumerate(VIEWS):
            p = self.plots[k].getPlotItem()
            p.plot(seg[:, i], seg[:, j], pen=pg.mkPen("#333333", width=2), connect="pairs")
            p.addItem(pg.ScatterPlotItem(tips[:, i], tips[:, j], symbol="o", size=5,
                                         brush="#333333", pen=None))
            p.addItem(pg.ScatterPlotItem(P[:n_pts, i], P[:n_pts, j], symbol="o", size=8,
                                         brush=COLORS[0], pen=None))
            if mounts is not None:
                p.addItem(pg.ScatterPlotItem(mounts[:, i], mounts[:, j], symbol="s", size=11,
                                             brush=COLORS[2], pen=None))
            p.addItem(pg.ScatterPlotItem([ms.cog[i]], [ms.cog[j]], symbol="+", size=16,
                                         brush="k", pen=pg.mkPen("k", width=2)))
            t = ms.tra
            if t is not None:
                self._line(p, t.point, t.direction, span, i, j, pg.mkPen(COLORS[1], width=2))
                ea = t.elastic_axis
                if ea is not None:
                    self._line(p, ea.point, ea.direction, span, i, j,
                               pg.mkPen(COLORS[3], width=2, style=pg.QtCore.Qt.PenStyle.DashLine))
            p.vb.enableAutoRange(x=True, y=True)

    @staticmethod
    def _line(p: pg.PlotItem, point: NDArray[np.float64], d: NDArray[np.float64], span: float,
              i: int, j: int, pen: object) -> None:
        a, b = point - 0.7 * span * d, point + 0.7 * span * d
        p.plot([a[i], b[i]], [a[j], b[j]], pen=pen)
