"""The plan's points and directions in three orthographic projections (top, front, side).

pyqtgraph's 3-D view needs PyOpenGL and an OpenGL context, neither available on an
off-screen or remote test-cell PC; three linked 2-D projections show the same and work
everywhere.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyqtgraph as pg
from PySide6 import QtWidgets

from app.gui.plan_rows import PlanRow
from app.report.figures import COLORS

__all__ = ["ProjectionsWidget"]

VIEWS = (("top view (X-Y)", 0, 1), ("front view (X-Z)", 0, 2), ("side view (Y-Z)", 1, 2))
_AXES = "XYZ"


def projection_plot(title: str, i: int, j: int) -> pg.PlotWidget:
    """An empty orthographic view: global axis ``i`` across, ``j`` up, metres, equal scales."""
    w = pg.PlotWidget()
    p = w.getPlotItem()
    p.setTitle(title, size="9pt")
    p.setLabel("bottom", _AXES[i], units="m")
    p.setLabel("left", _AXES[j], units="m")
    p.showGrid(x=True, y=True, alpha=0.2)
    p.setAspectLocked(True)
    return w


class ProjectionsWidget(QtWidgets.QWidget):
    """Response points (blue circles), excitation points (red triangles), their directions
    (short lines from each point), node labels, and the next point highlighted (yellow star)."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        lay = QtWidgets.QGridLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        self.plots: list[pg.PlotWidget] = []
        self._resp: list[pg.ScatterPlotItem] = []
        self._exc: list[pg.ScatterPlotItem] = []
        self._arrows: list[pg.PlotDataItem] = []
        self._next: list[pg.ScatterPlotItem] = []
        self._labels: list[list[pg.TextItem]] = []
        self._mounts: list[pg.ScatterPlotItem] = []
        self._mount_axes: list[pg.PlotDataItem] = []
        self._cand: list[tuple[pg.ScatterPlotItem, pg.ScatterPlotItem]] = []
        for k, (title, i, j) in enumerate(VIEWS):
            w = projection_plot(title, i, j)
            p = w.getPlotItem()
            arrows = p.plot([], [], pen=pg.mkPen("#555555", width=1.5), connect="pairs")
            resp = pg.ScatterPlotItem(symbol="o", size=9, brush=COLORS[0], pen=None)
            exc = pg.ScatterPlotItem(symbol="t", size=10, brush=COLORS[1], pen=None)
            nxt = pg.ScatterPlotItem(symbol="star", size=22, brush="#F0E442", pen=pg.mkPen("k"))
            mnt = pg.ScatterPlotItem(symbol="s", size=12, brush=COLORS[2], pen=None)
            mnt_axes = p.plot([], [], pen=pg.mkPen(COLORS[2], width=2), connect="pairs")
            cand = (pg.ScatterPlotItem(symbol="o", size=13, brush=None,
                                       pen=pg.mkPen("#999999", width=1.2)),
                    pg.ScatterPlotItem(symbol="t", size=14, brush=None,
                                       pen=pg.mkPen("#999999", width=1.2)))
            for c in cand:
                p.addItem(c)
            self._cand.append(cand)
            self._mounts.append(mnt)
            self._mount_axes.append(mnt_axes)
            for item in (resp, exc, nxt, mnt):
                p.addItem(item)
            self.plots.append(w)
            self._resp.append(resp)
            self._exc.append(exc)
            self._arrows.append(arrows)
            self._next.append(nxt)
            self._labels.append([])
            lay.addWidget(w, k // 2, k % 2)
        self.help = QtWidgets.QLabel(
            f"<b>Legend</b><br><span style='color:{COLORS[0]}; font-size:14pt'>●</span> "
            f"response DOF (accelerometer)<br><span style='color:{COLORS[1]}; "
            "font-size:14pt'>▼</span> excitation DOF (hit or shaker)<br>"
            "<span style='color:#555555; font-size:14pt'>—</span> measured or excited "
            "direction, from the point<br><span style='color:#C8B400; font-size:14pt'>★</span>"
            " next point to excite<br>"
            f"<span style='color:{COLORS[2]}; font-size:14pt'>■</span> mount, with its u, v, w "
            "axes<br><span style='color:#999999; font-size:14pt'>○</span> candidate sensor "
            "or point (planner); filled: chosen<br>numbers: node ids. Drag to pan, wheel to zoom.")
        self.help.setWordWrap(True)
        lay.addWidget(self.help, 1, 1)

    def set_rows(self, rows: Sequence[PlanRow]) -> None:
        """Draw the plan's rows."""
        resp = np.array([r.xyz for r in rows if r.role == "response"]).reshape(-1, 3)
        exc = np.array([r.xyz for r in rows if r.role == "excitation"]).reshape(-1, 3)
        pts = np.array([r.xyz for r in rows]).reshape(-1, 3)
        dirs = np.array([r.direction for r in rows]).reshape(-1, 3)
        span = float(np.ptp(pts, axis=0).max()) if len(pts) else 1.0
        tips = pts + 0.08 * max(span, 1e-3) * dirs
        seg = np.empty((2 * len(pts), 3))
        seg[0::2], seg[1::2] = pts, tips
        nodes: dict[int, tuple[float, float, float]] = {}
        for r in rows:
            nodes.setdefault(r.node, r.xyz)
        for k, (_, i, j) in enumerate(VIEWS):
            self._resp[k].setData(resp[:, i], resp[:, j])
            self._exc[k].setData(exc[:, i], exc[:, j])
            self._arrows[k].setData(seg[:, i], seg[:, j])
            plot = self.plots[k].getPlotItem()
            for t in self._labels[k]:
                plot.removeItem(t)
            self._labels[k] = []
            for node, xyz in nodes.items():
                t = pg.TextItem(str(node), color="#333333", anchor=(0, 1))
                t.setPos(xyz[i], xyz[j])
                plot.addItem(t)
                self._labels[k].append(t)
            plot.vb.enableAutoRange(x=True, y=True)

    def set_mounts(self, positions: np.ndarray, axes: np.ndarray, length: float = 0.05) -> None:
        """Draw mounts at ``positions`` (n, 3), m, with their axes (n, 3, 3) rows u, v, w."""
        P = np.asarray(positions, dtype=float).reshape(-1, 3)
        A = np.asarray(axes, dtype=float).reshape(-1, 3, 3)
        seg = np.empty((6 * len(P), 3))
        seg[0::2] = np.repeat(P, 3, axis=0)
        seg[1::2] = (P[:, None, :] + length * A).reshape(-1, 3)
        for k, (_, i, j) in enumerate(VIEWS):
            self._mounts[k].setData(P[:, i], P[:, j])
            self._mount_axes[k].setData(seg[:, i], seg[:, j])
            self.plots[k].getPlotItem().vb.enableAutoRange(x=True, y=True)

    def set_candidates(self, sensors: np.ndarray, points: np.ndarray) -> None:
        """Draw candidate sensor positions (n, 3) and candidate points (m, 3), metres, as
        grey outlines under the plan's own (chosen) points."""
        S = np.asarray(sensors, dtype=float).reshape(-1, 3)
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        for k, (_, i, j) in enumerate(VIEWS):
            self._cand[k][0].setData(S[:, i], S[:, j])
            self._cand[k][1].setData(P[:, i], P[:, j])
            self.plots[k].getPlotItem().vb.enableAutoRange(x=True, y=True)

    def show_candidates(self, visible: bool) -> None:
        """Show or hide the candidates (drawn by :meth:`set_candidates`)."""
        for pair in self._cand:
            for c in pair:
                c.setVisible(visible)

    def highlight(self, xyz: Sequence[float] | None) -> None:
        """Mark the next point to excite (None clears the mark)."""
        for k, (_, i, j) in enumerate(VIEWS):
            if xyz is None:
                self._next[k].setData([], [])
            else:
                self._next[k].setData([xyz[i]], [xyz[j]])
