"""The figures of the views and of the report, drawn with pyqtgraph.

Each ``draw_*`` function clears a :class:`pyqtgraph.PlotItem` and draws one figure on it
with labelled axes (units), a legend and, where the method has one, the pass/fail limit.
The GUI's views call them on their live plots; :func:`render_png` draws them off screen
for the HTML report. Everything here must run on the Qt GUI thread.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6 import QtCore, QtGui

from app.report.analysis import Analysis

__all__ = [
    "COLORS",
    "DOF_LABELS",
    "configure",
    "draw_coherence_bars",
    "draw_coherence_freq",
    "draw_dynamic_stiffness",
    "draw_rigidity",
    "draw_synthesis",
    "render_png",
]

#: distinguishable line colours (Okabe-Ito), readable on a white background
COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")
DOF_LABELS = ("x", "y", "z", "rx", "ry", "rz")
_PASS, _FAIL = "#009E73", "#D55E00"
_NA = "#888888"  # a check that could not fail


def configure() -> None:
    """Global pyqtgraph look of the application and the report: dark lines on white."""
    pg.setConfigOptions(background="w", foreground="k", antialias=True)


def _prepare(plot: pg.PlotItem, title: str, left: tuple[str, str | None],
             bottom: tuple[str, str | None], *, logy: bool = False) -> None:
    plot.clear()
    if plot.legend is not None:
        plot.legend.clear()
    else:
        plot.addLegend(offset=(-10, 10), labelTextSize="8pt", colCount=2,
                       brush=pg.mkBrush(255, 255, 255, 225), pen=pg.mkPen("#999999"))
    plot.setTitle(title, size="10pt")
    plot.setLabel("left", left[0], units=left[1])
    plot.setLabel("bottom", bottom[0], units=bottom[1])
    plot.showGrid(x=True, y=True, alpha=0.25)
    plot.setLogMode(x=False, y=logy)
    # SI prefixes on a log axis would rescale the exponent labels: keep plain units there
    plot.getAxis("left").enableAutoSIPrefix(not logy)
    plot.getAxis("bottom").enableAutoSIPrefix(False)


def _limit(plot: pg.PlotItem, y: float, label: str) -> None:
    pen = pg.mkPen(_FAIL, width=1.5, style=QtCore.Qt.PenStyle.DashLine)
    line = pg.InfiniteLine(pos=y, angle=0, pen=pen, label=label,
                           labelOpts={"position": 0.05, "color": _FAIL,
                                      "anchors": [(0, 1), (0, 1)]})
    plot.addItem(line)


def _band(plot: pg.PlotItem, band: tuple[float, float], color: str, name: str) -> None:
    fill = QtGui.QColor(color)
    fill.setAlpha(45)
    region = pg.LinearRegionItem(values=band, movable=False, brush=pg.mkBrush(fill),
                                 pen=pg.mkPen(fill))
    region.setZValue(-10)
    plot.addItem(region)
    # a legend entry for the shaded band
    plot.plot([], [], pen=None, symbol="s", symbolSize=12, symbolBrush=pg.mkBrush(fill),
              symbolPen=None, name=name)


def draw_coherence_bars(plot: pg.PlotItem, a: Analysis) -> None:
    """Minimum coherence of each FRF over the identification's lines against the threshold."""
    thr = a.options.coherence_threshold
    _prepare(plot, f"Minimum coherence per FRF (pass ≥ {thr:g})", ("coherence", None),
             ("FRF number (response-major)", None))
    if a.frf.coherence is None:
        plot.setTitle("No coherence in these data (FRFs without coherence records)", size="10pt")
        return
    coh = a.frf.coherence[..., a.frf.freq > 0]
    f = a.positive_freq
    if a.result is not None:
        coh = coh[..., f <= max(a.result.mass_band[1], a.result.stiffness_band[1])]
    worst = coh.min(axis=-1).ravel()
    x = np.arange(1, worst.size + 1)
    ok = worst >= thr
    kinds: tuple[tuple[NDArray[np.bool_], str, str], ...] = (
        (ok, _PASS, "pass"), (~ok, _FAIL, "below threshold"))
    if a.result is not None and not a.result.coherence_checked:  # 1 by definition
        plot.setTitle(f"Minimum coherence per FRF: not checked ({a.result.coherence_unchecked})",
                      size="10pt")
        kinds = ((np.ones_like(ok), _NA, "not checked"),)
    for mask, color, name in kinds:
        if np.any(mask):
            plot.addItem(pg.BarGraphItem(x=x[mask], height=worst[mask], width=0.8,
                                         brush=color, pen=None))
            plot.plot([], [], pen=None, symbol="s", symbolBrush=color, symbolPen=None, name=name)
    _limit(plot, thr, f"threshold {thr:g}")
    plot.setYRange(0, 1.02)


def draw_coherence_freq(plot: pg.PlotItem, a: Analysis) -> None:
    """Coherence against frequency: the worst FRF and the median over FRFs per line."""
    thr = a.options.coherence_threshold
    _prepare(plot, "Coherence against frequency", ("coherence", None), ("frequency", "Hz"))
    if a.frf.coherence is None:
        plot.setTitle("No coherence in these data", size="10pt")
        return
    flat = a.frf.coherence.reshape(-1, a.frf.freq.size)
    plot.plot(a.frf.freq, np.median(flat, axis=0), pen=pg.mkPen(COLORS[0], width=1.5),
              name="median over FRFs")
    plot.plot(a.frf.freq, flat.min(axis=0), pen=pg.mkPen(COLORS[1], width=1.5),
              name="worst FRF")
    _limit(plot, thr, f"threshold {thr:g}")
    plot.setYRange(0, 1.02)


def draw_rigidity(plot: pg.PlotItem, a: Analysis) -> None:
    """Rigidity check: each accelerometer predicted from the others, error against frequency."""
    _prepare(plot, "Rigidity check: prediction error of each accelerometer",
             ("relative error", "%"), ("frequency", "Hz"), logy=True)
    rig = a.rigidity
    if rig is None:
        plot.setTitle(f"Rigidity check not possible: {a.rigidity_error}", size="9pt")
        return
    if rig.band is not None:
        _band(plot, rig.band, _PASS, f"rigid {rig.band[0]:.1f}-{rig.band[1]:.1f} Hz")
    sel = rig.freq > 0
    for k, node in enumerate(rig.nodes):
        e = np.clip(rig.error[k, sel] * 100, 1e-6, None)
        plot.plot(rig.freq[sel], e, pen=pg.mkPen(COLORS[k % len(COLORS)], width=1.2),
                  name=f"node {node}")
    _limit(plot, float(np.log10(rig.threshold * 100)), f"limit {rig.threshold:.0%}")


def draw_dynamic_stiffness(plot: pg.PlotItem, a: Analysis, rotational: bool = False) -> None:
    """|K*(f)| of the diagonal terms per line (article Fig. 12) and the fitted
    |g(f) (K + j D) + j w C| (D zero unless the damping model holds it; g the mounts'
    stiffening, 1 for a constant K)."""
    kind = "rotational" if rotational else "translational"
    unit = "N m/rad" if rotational else "N/m"
    _prepare(plot, f"Dynamic stiffness at O, {kind} (cf. article Fig. 12)",
             ("|K*|", unit), ("frequency", "Hz"))
    r = a.result
    if r is None or r.stiffness_per_line is None:
        plot.setTitle(f"No identification: {a.error}", size="9pt")
        return
    f = a.stiffness_freq()
    w = 2 * np.pi * f
    for n, i in enumerate(range(3, 6) if rotational else range(3)):
        color = COLORS[n]
        plot.plot(f, np.abs(r.stiffness_per_line[:, i, i]), pen=None, symbol="o", symbolSize=4,
                  symbolBrush=color, symbolPen=None, name=f"{DOF_LABELS[i]} per line")
        g = 1.0 if r.stiffening is None else r.stiffening.factor(w)
        fit = np.abs(g * (r.K[i, i] + 1j * r.D[i, i]) + 1j * w * r.C[i, i])
        label = {"viscous": "K+jωC", "hysteretic": "K+jD"}.get(r.damping_model, "K+jωC+jD")
        if r.stiffening is not None:
            label = label.replace("K", "K(f)")
        plot.plot(f, fit, pen=pg.mkPen(color, width=2, style=QtCore.Qt.PenStyle.DashLine),
                  name=f"{DOF_LABELS[i]} fit {label}")


def draw_synthesis(plot: pg.PlotItem, a: Analysis) -> None:
    """Modulus of the sum of all FRFs, measured and synthesised (article Figs. 9, 13)."""
    _prepare(plot, "Sum of all FRFs: measured and synthesised (cf. article Figs. 9, 13)",
             ("|ΣH| ((m/s²)/N)", None), ("frequency", "Hz"), logy=True)
    r = a.result
    if r is None:
        plot.setTitle(f"No identification: {a.error}", size="9pt")
        return
    f = a.positive_freq
    _band(plot, r.mass_band, COLORS[5], f"mass line {r.mass_band[0]:.1f}-{r.mass_band[1]:.1f} Hz")
    plot.plot(f, r.synthesis.sum_measured, pen=pg.mkPen(COLORS[0], width=1.5), name="measured")
    plot.plot(f, r.synthesis.sum_synthesised,
              pen=pg.mkPen(COLORS[1], width=2, style=QtCore.Qt.PenStyle.DashLine),
              name=f"synthesised (error {r.synthesis.overall:.1%})")


def render_png(draw: Callable[[pg.PlotItem], None], width: int = 900, height: int = 380) -> bytes:
    """Draw one figure off screen and return it as PNG bytes (needs a QApplication)."""
    widget = pg.PlotWidget(background="w")
    try:
        widget.resize(width, height)
        draw(widget.getPlotItem())
        widget.getPlotItem().vb.autoRange()
        image = widget.grab().toImage()
        buf = QtCore.QBuffer()
        buf.open(QtCore.QIODevice.OpenModeFlag.WriteOnly)
        image.save(buf, "PNG")
        return bytes(buf.data().data())
    finally:
        widget.deleteLater()
