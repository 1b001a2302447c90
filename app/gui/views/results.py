"""Results view: the ten inertia parameters (about the CoG and O), principal moments and
axes, K and C, dynamic stiffness against frequency (article Fig. 12), measured against
synthesised FRFs (Figs. 9, 13), the physical-consistency verdict, and the bands, adjustable
with live re-identification in the background."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.gui.session import Session
from app.gui.views.modeshapes import ModeShapesWidget
from app.gui.widgets import fill_table, make_plot, set_verdict
from app.report import figures
from app.report.analysis import Analysis, message_of
from app.report.mount_system import MountSystem, mount_system
from app.report.tables import (
    SPREADS,
    contribution_lines,
    format_matrix,
    inertia_rows,
    modes_text,
    principal_rows,
    sources_line,
)

__all__ = ["ResultsView"]


def _spin(suffix: str = " Hz") -> QtWidgets.QDoubleSpinBox:
    s = QtWidgets.QDoubleSpinBox()
    s.setDecimals(2)
    s.setRange(0.0, 1e6)
    s.setSingleStep(1.0)
    s.setSuffix(suffix)
    s.setKeyboardTracking(False)
    return s


class ResultsView(QtWidgets.QWidget):
    """Identified parameters and their figures; band and method controls."""

    def __init__(self, session: Session, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.session = session
        self._filling = False
        ctl = self._build_controls()
        self._build_tables()
        self.table_tabs = self._table_tabs()
        left = self._left_panel(self.table_tabs)
        self.plot_tabs = self._plot_tabs()
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(self.plot_tabs)
        split.setSizes([520, 760])
        lay = QtWidgets.QVBoxLayout(self)
        lay.addLayout(ctl)
        lay.addWidget(split, 1)
        set_verdict(self.verdict, None, "No results yet: open FRFs or run a test")
        session.runner.busy.connect(self._busy)
        session.data_changed.connect(self._new_data)
        session.mounts_changed.connect(self._show_mount_system)
        self.excitation.valueChanged.connect(self._show_mount_system)
        self._analysis: Analysis | None = None
        self.mount_system: MountSystem | None = None

    # --- layout ----------------------------------------------------------------------------------
    def _build_controls(self) -> QtWidgets.QHBoxLayout:
        """The band, method and excitation controls, wired to re-identify after a pause; the
        row of them above the results."""
        self.auto_bands = QtWidgets.QCheckBox("automatic bands")
        self.auto_bands.setChecked(True)
        self.mass_lo, self.mass_hi = _spin(), _spin()
        self.stiff_lo, self.stiff_hi = _spin(), _spin()
        self.method = QtWidgets.QComboBox()
        self.method.addItems(["improved", "plain"])
        self.method.setToolTip("improved (default) or the article's plain method")
        self.physical = QtWidgets.QCheckBox("enforce physical consistency")
        self.excitation = _spin()
        self.excitation.setSpecialValueText("none")
        self.excitation.setToolTip("excitation frequency (e.g. idle firing order) for the "
                                   "modes' isolation margins; none: 0")
        self.status = QtWidgets.QLabel("")
        ctl = QtWidgets.QHBoxLayout()
        ctl.addWidget(QtWidgets.QLabel("Mass line:"))
        ctl.addWidget(self.mass_lo)
        ctl.addWidget(QtWidgets.QLabel("to"))
        ctl.addWidget(self.mass_hi)
        ctl.addSpacing(12)
        ctl.addWidget(QtWidgets.QLabel("Stiffness band:"))
        ctl.addWidget(self.stiff_lo)
        ctl.addWidget(QtWidgets.QLabel("to"))
        ctl.addWidget(self.stiff_hi)
        ctl.addWidget(self.auto_bands)
        ctl.addSpacing(12)
        ctl.addWidget(QtWidgets.QLabel("Method:"))
        ctl.addWidget(self.method)
        ctl.addWidget(self.physical)
        ctl.addStretch(1)
        ctl.addWidget(self.status)
        self._debounce = QtCore.QTimer(self)
        self._debounce.setSingleShot(True)
        self._debounce.setInterval(250)
        self._debounce.timeout.connect(self._reidentify)
        for s in (self.mass_lo, self.mass_hi, self.stiff_lo, self.stiff_hi):
            s.valueChanged.connect(self._band_edited)
        self.auto_bands.toggled.connect(self._changed)
        self.method.currentIndexChanged.connect(self._changed)
        self.physical.toggled.connect(self._changed)
        return ctl

    def _build_tables(self) -> None:
        """The verdict and summary labels, the result tables and the mode-shape view."""
        self.verdict = QtWidgets.QLabel()
        self.summary = QtWidgets.QLabel()
        self.summary.setWordWrap(True)
        self.uncertainty = QtWidgets.QLabel()
        self.uncertainty.setWordWrap(True)
        self.uncertainty.setTextFormat(QtCore.Qt.TextFormat.PlainText)
        self.uncertainty.hide()
        self.inertia = QtWidgets.QTableWidget()
        self.principal = QtWidgets.QTableWidget()
        self.K = QtWidgets.QTableWidget()
        self.C = QtWidgets.QTableWidget()
        self.D = QtWidgets.QTableWidget()
        for t in (self.inertia, self.principal, self.K, self.C, self.D):
            t.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.modes = QtWidgets.QTableWidget()
        self.energy = QtWidgets.QTableWidget()
        self.mount_rates = QtWidgets.QTableWidget()
        self.tra = QtWidgets.QTableWidget()
        self.mount_notes = QtWidgets.QLabel()
        self.mount_notes.setWordWrap(True)
        self.mode_shapes = ModeShapesWidget()
        for t in (self.modes, self.energy, self.mount_rates, self.tra):
            t.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)

    def _table_tabs(self) -> QtWidgets.QTabWidget:
        """The tabs of K, damping, modes, energy decoupling, and mounts and TRA."""
        tabs = QtWidgets.QTabWidget()
        tabs.addTab(self.K, "Stiffness K at O")
        self.damping_page = self._damping_page()
        tabs.addTab(self.damping_page, "Damping at O")
        self.modes_page = self._modes_page()
        tabs.addTab(self.modes_page, "Modes")
        tabs.addTab(self.energy, "Energy decoupling")
        self.mounts_page = self._mounts_page()
        tabs.addTab(self.mounts_page, "Mounts and TRA")
        return tabs

    def _damping_page(self) -> QtWidgets.QWidget:
        """Viscous C and structural D of K* = K + j w C + j D on one page, under a note naming
        the damping model chosen."""
        damping_page = QtWidgets.QWidget()
        dl = QtWidgets.QVBoxLayout(damping_page)
        dl.setContentsMargins(0, 0, 0, 0)
        self.damping_note = QtWidgets.QLabel()
        self.damping_note.setWordWrap(True)
        dl.addWidget(self.damping_note)
        dl.addWidget(QtWidgets.QLabel("<b>Viscous C</b> (N s/m, N s/rad, N m s/m, N m s/rad)"))
        dl.addWidget(self.C, 1)
        dl.addWidget(QtWidgets.QLabel("<b>Structural D</b> (units of K)"))
        dl.addWidget(self.D, 1)
        return damping_page

    def _modes_page(self) -> QtWidgets.QWidget:
        """The modes table under the excitation frequency for the isolation margins."""
        modes_page = QtWidgets.QWidget()
        mlay = QtWidgets.QVBoxLayout(modes_page)
        mlay.setContentsMargins(0, 0, 0, 0)
        erow = QtWidgets.QHBoxLayout()
        erow.addWidget(QtWidgets.QLabel("Excitation frequency (isolation margins):"))
        erow.addWidget(self.excitation)
        erow.addStretch(1)
        mlay.addLayout(erow)
        mlay.addWidget(self.modes, 1)
        return modes_page

    def _mounts_page(self) -> QtWidgets.QWidget:
        """The mount rates, their notes and the TRA table."""
        mounts_page = QtWidgets.QWidget()
        mp = QtWidgets.QVBoxLayout(mounts_page)
        mp.setContentsMargins(0, 0, 0, 0)
        mp.addWidget(self.mount_rates, 3)
        mp.addWidget(self.mount_notes)
        mp.addWidget(self.tra, 2)
        return mounts_page

    def _left_panel(self, tabs: QtWidgets.QTabWidget) -> QtWidgets.QWidget:
        """Verdict, summary, inertia and principal tables above ``tabs``, and the units."""
        left = QtWidgets.QWidget()
        ll = QtWidgets.QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        ll.addWidget(self.verdict)
        ll.addWidget(self.summary)
        ll.addWidget(self.uncertainty)
        ll.addWidget(QtWidgets.QLabel("<b>Ten inertia parameters</b> (products J_xy = ∫xy dm)"))
        ll.addWidget(self.inertia, 4)
        ll.addWidget(QtWidgets.QLabel("<b>Principal moments and axes</b> about the CoG"))
        ll.addWidget(self.principal, 2)
        ll.addWidget(tabs, 3)
        units = QtWidgets.QLabel("DOF order x, y, z, rx, ry, rz at the origin O. K, D: N/m, "
                                 "N/rad, N m/m, N m/rad; C: N s/m, N s/rad, N m s/m, N m s/rad.")
        units.setWordWrap(True)
        ll.addWidget(units)
        return left

    def _plot_tabs(self) -> QtWidgets.QTabWidget:
        """The FRF and K* plots on one tab, the mode shapes on another."""
        self.stiffness_plot = make_plot()
        self.stiffness_rot_plot = make_plot()
        self.synthesis_plot = make_plot()
        plots = QtWidgets.QWidget()
        pl = QtWidgets.QVBoxLayout(plots)
        pl.setContentsMargins(0, 0, 0, 0)
        pl.addWidget(self.synthesis_plot)
        pl.addWidget(self.stiffness_plot)
        pl.addWidget(self.stiffness_rot_plot)
        plot_tabs = QtWidgets.QTabWidget()
        plot_tabs.addTab(plots, "FRFs and K*")
        plot_tabs.addTab(self.mode_shapes, "Mode shapes")
        return plot_tabs

    # --- controls --------------------------------------------------------------------------------
    @QtCore.Slot(bool)
    def _busy(self, busy: bool) -> None:
        self.status.setText("identifying…" if busy else "")

    @QtCore.Slot(object)
    def _new_data(self, _frf: object) -> None:
        self._filling = True
        try:
            self.auto_bands.setChecked(True)
        finally:
            self._filling = False

    def _band_edited(self) -> None:
        if self._filling:
            return
        self._filling = True
        try:
            self.auto_bands.setChecked(False)
        finally:
            self._filling = False
        self._debounce.start()

    def _changed(self) -> None:
        if not self._filling:
            self._debounce.start()

    def set_bands(self, mass: tuple[float, float], stiffness: tuple[float, float]) -> None:
        """Set both bands (Hz) as the operator would; re-identifies after a short pause."""
        self.mass_lo.setValue(mass[0])
        self.mass_hi.setValue(mass[1])
        self.stiff_lo.setValue(stiffness[0])
        self.stiff_hi.setValue(stiffness[1])

    def _reidentify(self) -> None:
        auto = self.auto_bands.isChecked()
        opt = replace(
            self.session.options,
            method=self.method.currentText(),  # type: ignore[arg-type]
            physical=self.physical.isChecked(),
            mass_band=None if auto else (self.mass_lo.value(), self.mass_hi.value()),
            stiffness_band=None if auto else (self.stiff_lo.value(), self.stiff_hi.value()),
        )
        self.session.set_options(opt)

    # --- display ---------------------------------------------------------------------------------
    @QtCore.Slot(object)
    def show_analysis(self, a: Analysis) -> None:
        """Redraw for a new analysis."""
        r = a.result
        self._analysis = a
        self._show_mount_system()
        figures.draw_synthesis(self.synthesis_plot.getPlotItem(), a)
        figures.draw_dynamic_stiffness(self.stiffness_plot.getPlotItem(), a)
        figures.draw_dynamic_stiffness(self.stiffness_rot_plot.getPlotItem(), a, rotational=True)
        if r is None:
            set_verdict(self.verdict, False, f"Identification failed: {a.error}")
            self.summary.setText("Adjust the bands or check the data (see Checks).")
            for t in (self.inertia, self.principal, self.K, self.C, self.D):
                t.clear()
                t.setRowCount(0)
            self.uncertainty.hide()
            self.damping_note.clear()
            return
        self._filling = True
        try:
            self.mass_lo.setValue(r.mass_band[0])
            self.mass_hi.setValue(r.mass_band[1])
            self.stiff_lo.setValue(r.stiffness_band[0])
            self.stiff_hi.setValue(r.stiffness_band[1])
        finally:
            self._filling = False
        p = r.properties
        if p.physically_consistent:
            set_verdict(self.verdict, True,
                        f"Physically consistent inertia (J1 + J2 ≥ J3, margin "
                        f"{p.triangle_margin:+.3f})" + (" — enforced" if r.physical_enforced
                                                         else ""))
        else:
            set_verdict(self.verdict, False,
                        "NOT physically consistent: "
                        + ("not positive definite; " if not p.positive_definite else "")
                        + f"triangle margin {p.triangle_margin:+.3f}. Tick 'enforce physical "
                          "consistency' or check the data")
        u = r.uncertainty
        modes = modes_text(r.rigid_modes_hz, u)
        text = (f"{r.method} method, {r.iterations} iterations"
                f"{'' if r.converged else ' (NOT converged)'}; mass line "
                f"{r.mass_band[0]:.2f}-{r.mass_band[1]:.2f} Hz ({len(r.mass_lines)} lines), "
                f"stiffness {r.stiffness_band[0]:.2f}-{r.stiffness_band[1]:.2f} Hz "
                f"({len(r.stiffness_lines)} lines). Rigid-body modes: {modes} Hz. Damping "
                f"model: {r.damping_model}.")
        if r.warnings:
            text += " Warnings: " + "; ".join(r.warnings)
        self.summary.setText(text)
        top = contribution_lines(u)
        self.uncertainty.setText("\n".join(
            [SPREADS, sources_line(u),
             *(["Largest contributions to the variance:", *top] if top else [])]))
        self.uncertainty.setVisible(u is not None)
        fill_table(self.inertia, ("parameter", "unit", "about CoG", "about origin O"),
                   inertia_rows(p, u))
        fill_table(self.principal, ("", "moment (kg m²)", "axis x", "axis y", "axis z"),
                   principal_rows(p, u))
        dofs = figures.DOF_LABELS
        fill_table(self.K, ("K at O", *dofs),
                   [(d, *row) for d, row in zip(dofs, format_matrix(r.K, u, "stiffness"),
                                                strict=True)])
        fill_table(self.C, ("C at O", *dofs),
                   [(d, *row) for d, row in zip(dofs, format_matrix(r.C, u, "damping"),
                                                strict=True)])
        self.damping_note.setText("; ".join(["K* = K + jωC + jD", *r.fit_notes]) + ".")
        fill_table(self.D, ("D at O", *dofs),
                   [(d, *row) for d, row in zip(dofs, format_matrix(r.D), strict=True)])
        self.K.setToolTip("N/m (translation rows/columns), N/rad, N m/m, N m/rad")
        self.C.setToolTip("N s/m, N s/rad, N m s/m, N m s/rad")
        self.D.setToolTip("K* = K + j w C + j D: N/m, N/rad, N m/m, N m/rad (zero unless the "
                          "damping model holds D)")

    # --- mount system ----------------------------------------------------------------------------
    def _show_mount_system(self, _mounts: object = None) -> None:
        """Modes, decoupling, mount rates and the torque roll axis of the current analysis
        (6x6 and 21 x 3n problems: about 10 ms on the GUI thread, measured for the engine's
        three mounts on a loaded 2-core machine)."""
        a = self._analysis
        tables = (self.modes, self.energy, self.mount_rates, self.tra)
        ms = None
        f_e = self.excitation.value()
        if a is not None and a.result is not None:
            try:
                ms = mount_system(a.result, self.session.mounts, f_e if f_e > 0 else None)
            except ValueError as err:
                self.session.message.emit("error", f"mount system: {message_of(err)}")
        self.mount_system = ms
        if ms is None:
            for t in tables:
                t.clear()
                t.setRowCount(0)
            self.mode_shapes.set_system(None, np.zeros((0, 3)))
            return
        fill_table(self.modes, ms.mode_head(), ms.mode_rows())
        fill_table(self.energy, ("energy (%)", *figures.DOF_LABELS), ms.energy_rows())
        fill_table(self.mount_rates, ms.mount_head(), ms.mount_rows())
        fill_table(self.tra, ("quantity", "value"), ms.tra_rows())
        for t in tables:
            t.resizeColumnsToContents()
        self.mount_notes.setText("<br>".join([*ms.problems, *ms.mount_notes()])
                                 if ms.rates is not None else
                                 "<br>".join([*ms.problems, "Load a mounts file in the Test plan "
                                              "tab for the individual mount rates and the "
                                              "torque roll axis."]))
        assert a is not None
        self.mode_shapes.set_system(ms, np.unique(a.frf.resp_xyz, axis=0))
