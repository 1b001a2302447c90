"""The main window: one tab per view, a message bar, the status bar and the settings.

Settings (QSettings, organisation "insitu", application "insitu"): window geometry and
state, the current tab, the last station file, the last plan file and the last data file.
"""

from __future__ import annotations

from pathlib import Path

from PySide6 import QtCore, QtGui, QtWidgets

from app.gui.session import Session
from app.gui.views.acquisition import AcquisitionView
from app.gui.views.checks import ChecksView
from app.gui.views.export import ExportView
from app.gui.views.plan import PlanView
from app.gui.views.results import ResultsView
from app.gui.views.station import StationView
from app.gui.widgets import MessageBar
from app.gui.worker import TaskRunner
from app.pipeline import SUFFIXES
from app.report.analysis import Analysis

__all__ = ["MainWindow"]

_OPEN_FILTER = (f"FRFs, time records or run ({' '.join('*' + s for s in SUFFIXES)});;"
                "UFF file of FRFs or time records (*.uff *.unv);;"
                "Run file or FRF file (*.h5 *.hdf5);;All files (*)")


class MainWindow(QtWidgets.QMainWindow):
    """The operator's window.

    Parameters
    ----------
    station : station file to use (else the last one, else the built-in mock bench)
    settings : where to remember things (default: ``QSettings()``)
    """

    def __init__(self, station: Path | None = None,
                 settings: QtCore.QSettings | None = None) -> None:
        super().__init__()
        self.setWindowTitle("insitu — inertia and mount identification")
        self.settings = settings or QtCore.QSettings()
        self.runner = TaskRunner(self)
        self.session = Session(self.runner, self)
        self.messages = MessageBar()
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.setDocumentMode(True)
        self.plan_view = PlanView(self.runner)
        self.checks_view = ChecksView()
        self.results_view = ResultsView(self.session)
        self.export_view = ExportView(self.session)
        self._add_acquisition_views(station)
        self.tabs.addTab(self.plan_view, "Test plan")
        self.tabs.addTab(self.acquisition_view, "Acquisition")
        self.tabs.addTab(self.checks_view, "Checks")
        self.tabs.addTab(self.results_view, "Results")
        self.tabs.addTab(self.export_view, "Export")
        central = QtWidgets.QWidget()
        lay = QtWidgets.QVBoxLayout(central)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(self.messages)
        lay.addWidget(self.tabs, 1)
        self.setCentralWidget(central)
        self.data_label = QtWidgets.QLabel("No data")
        self.busy_label = QtWidgets.QLabel("")
        self.statusBar().addWidget(self.data_label, 1)
        self.statusBar().addPermanentWidget(self.busy_label)
        self._menus()
        # wiring
        self.session.message.connect(self.messages.show_message)
        self.plan_view.message.connect(self.messages.show_message)
        self.session.data_changed.connect(self.plan_view.set_frf_rows)
        self.session.analysis_changed.connect(self.checks_view.show_analysis)
        self.session.analysis_changed.connect(self.results_view.show_analysis)
        self.session.analysis_changed.connect(self._show_summary)
        self.runner.busy.connect(lambda b: self.busy_label.setText("working…" if b else ""))
        self.plan_view.plan_loaded.connect(self._remember_plan)
        self.plan_view.mounts_loaded.connect(self.session.set_mounts)
        self.session.mounts_changed.connect(self.plan_view.set_mounts)
        self.station_view.start()
        self._restore()
        if self.station_view.station is None:
            mock = "" if self.station_view.mock_unavailable else "use the built-in mock bench or "
            self.messages.show_message(
                "info", f"No station yet: {mock}open a station file (Station tab), or open "
                "recorded FRFs (File > Open)")

    def _add_acquisition_views(self, station: Path | None) -> None:
        """The Station tab (first) and the Acquisition view (added after the plan)."""
        self.station_view = StationView(self.settings, self.runner, station)
        self.acquisition_view = AcquisitionView(self.station_view, self.plan_view, self.session)
        self.tabs.addTab(self.station_view, "Station")
        self.station_view.message.connect(self.messages.show_message)
        self.acquisition_view.message.connect(self.messages.show_message)
        self.station_view.station_changed.connect(self._station_changed)
        self.station_view.plan_offered.connect(self.plan_view.set_plan)

    def _station_changed(self, station: object) -> None:
        from drivers.station import StationConfig

        self.plan_view.station = station if isinstance(station, StationConfig) else None
        if self.plan_view.plan is not None:
            self.plan_view.set_plan(self.plan_view.plan, self.plan_view.plan_path)

    def _menus(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        self.open_action = QtGui.QAction("&Open FRFs or run…", self)
        self.open_action.setShortcut(QtGui.QKeySequence.StandardKey.Open)
        self.open_action.triggered.connect(self._open_dialog)
        file_menu.addAction(self.open_action)
        quit_action = QtGui.QAction("&Quit", self)
        quit_action.setShortcut(QtGui.QKeySequence.StandardKey.Quit)
        quit_action.triggered.connect(self.close)
        file_menu.addAction(quit_action)

    def _open_dialog(self) -> None:
        last = str(self.settings.value("last_data", "", str))
        name, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open FRFs or run", last,
                                                        _OPEN_FILTER)
        if name:
            self.open_file(Path(name))

    def open_file(self, path: Path) -> None:
        """Open any file the command line reads (UFF FRFs or time records, a run file, an
        FRF file) and replay it through the views."""
        self.settings.setValue("last_data", str(path))
        self.session.open_file(path)

    @QtCore.Slot(object)
    def _show_summary(self, a: Analysis) -> None:
        self.data_label.setText(a.summary())

    def _remember_plan(self, _plan: object) -> None:
        if self.plan_view.plan_path is not None:
            self.settings.setValue("last_plan", str(self.plan_view.plan_path))

    # --- settings and closing ----------------------------------------------------------------
    def _restore(self) -> None:
        s = self.settings
        geometry = s.value("window/geometry")
        if isinstance(geometry, QtCore.QByteArray):
            self.restoreGeometry(geometry)
        else:
            self.resize(1280, 820)
        state = s.value("window/state")
        if isinstance(state, QtCore.QByteArray):
            self.restoreState(state)
        tab = s.value("window/tab", 0, int)
        self.tabs.setCurrentIndex(tab if isinstance(tab, int) else 0)
        plan = str(s.value("last_plan", "", str))
        if plan and Path(plan).suffix.lower() == ".toml" and Path(plan).is_file():
            self.plan_view.load_plan_file(Path(plan))

    def save_settings(self) -> None:
        """Remember the window layout, tab, station and plan."""
        s = self.settings
        s.setValue("window/geometry", self.saveGeometry())
        s.setValue("window/state", self.saveState())
        s.setValue("window/tab", self.tabs.currentIndex())
        if self.plan_view.plan_path is not None:
            s.setValue("last_plan", str(self.plan_view.plan_path))
        self.station_view.save_settings()
        s.sync()

    def closeEvent(self, event: QtGui.QCloseEvent) -> None:
        """Stop any acquisition (the shaker output goes off), save settings, end the worker."""
        self.acquisition_view.shutdown()
        self.station_view.shutdown()
        self.save_settings()
        self.runner.shutdown()
        super().closeEvent(event)
