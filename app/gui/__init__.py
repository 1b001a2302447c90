"""The operator's desktop application (PySide6 + pyqtgraph).

:func:`run_gui` starts it; :class:`app.gui.main_window.MainWindow` holds one tab per view
(``app.gui.views``: station, plan, acquisition, checks, results, export). Acquisition runs
in the procedure's worker thread (``app.acquire``), identification and file loading in the
window's :class:`app.gui.worker.TaskRunner`; results reach the widgets through Qt signals.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from PySide6 import QtCore, QtWidgets

__all__ = ["close_on_sigint", "run_gui"]

#: how often, ms, the Qt event loop hands the interpreter control so that it sees a signal
#: (Python runs its signal handlers between bytecodes, never inside Qt's C++ loop)
SIGNAL_POLL_MS = 200


def close_on_sigint(window: QtWidgets.QWidget) -> QtCore.QTimer:
    """Make Ctrl-C in the terminal (SIGINT) close ``window`` through its own close path (a
    running acquisition is stopped, its run file kept; the settings saved): the handler
    closes the window, and a timer wakes the interpreter every :data:`SIGNAL_POLL_MS` ms
    so that the handler runs at all. Returns the timer (stop it, and restore the previous
    handler, with :func:`signal.signal`, when the loop ends)."""
    from PySide6 import QtCore

    def on_sigint(signum: int, frame: object) -> None:
        window.close()

    signal.signal(signal.SIGINT, on_sigint)
    timer = QtCore.QTimer(window)
    timer.timeout.connect(lambda: None)  # a Python slot: the interpreter runs, and its handlers
    timer.start(SIGNAL_POLL_MS)
    return timer


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
    previous = signal.getsignal(signal.SIGINT)
    timer = close_on_sigint(window)
    try:
        return int(app.exec())
    finally:
        timer.stop()
        signal.signal(signal.SIGINT, previous)
