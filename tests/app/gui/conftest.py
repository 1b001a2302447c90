"""GUI tests: off screen, settings in a temporary directory, windows closed after each test."""

from __future__ import annotations

import os

os.environ["QT_QPA_PLATFORM"] = "offscreen"  # before Qt is imported anywhere

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from PySide6 import QtCore, QtWidgets

from app.gui.main_window import MainWindow
from app.report.figures import configure


@pytest.fixture
def settings_path(tmp_path: Path) -> Path:
    """An INI file for QSettings, so tests never touch the user's settings."""
    return tmp_path / "settings" / "insitu.ini"


@pytest.fixture
def make_window(qtbot, settings_path: Path) -> Iterator[Callable[..., MainWindow]]:
    """Build main windows on the temporary settings; all are closed at the end."""
    QtCore.QSettings.setDefaultFormat(QtCore.QSettings.Format.IniFormat)
    QtCore.QSettings.setPath(QtCore.QSettings.Format.IniFormat,
                             QtCore.QSettings.Scope.UserScope, str(settings_path.parent))
    configure()
    made: list[MainWindow] = []

    def make(station: Path | None = None) -> MainWindow:
        w = MainWindow(station, QtCore.QSettings(str(settings_path),
                                                 QtCore.QSettings.Format.IniFormat))
        qtbot.addWidget(w)
        w.resize(1400, 900)
        w.show()
        made.append(w)
        return w

    yield make
    for w in made:
        if w.isVisible():
            w.close()
    QtWidgets.QApplication.processEvents()


@pytest.fixture
def choose_file(monkeypatch: pytest.MonkeyPatch) -> Callable[..., None]:
    """``choose_file(path, save=False)``: the next file dialog answers ``path``, as if the
    operator picked it."""

    def choose(path: Path, save: bool = False) -> None:
        name = "getSaveFileName" if save else "getOpenFileName"
        monkeypatch.setattr(QtWidgets.QFileDialog, name,
                            staticmethod(lambda *a, **k: (str(path), "")))

    return choose
