"""The operator's desktop application (PySide6 + pyqtgraph).

:func:`run_gui` starts it; :class:`app.gui.main_window.MainWindow` holds one tab per view
(``app.gui.views``: station, plan, acquisition, checks, results, export). Acquisition runs
in the procedure's worker thread (``app.acquire``), identification and file loading in the
window's :class:`app.gui.worker.TaskRunner`; results reach the widgets through Qt signals.
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["run_gui"]


def run_gui(station: Path | None = None, argv: list[str] | None = None) -> int:
    """Show the main window and run the Qt event loop; returns the exit status."""
    from PySide6 import QtWidgets

    from app.gui.main_window import MainWindow
    from app.report.figures import configure

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(argv or sys.argv[:1])
    app.setOrganizationName("insitu")
    app.setApplicationName("insitu")
    configure()
    window = MainWindow(station)
    window.show()
    return int(app.exec())
