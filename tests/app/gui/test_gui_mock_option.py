"""The GUI offers the mock bench only where it runs (POSIX: its serial devices are
pseudo-terminals)."""

from __future__ import annotations

import pytest

import app.gui.views.station as station_module
from app.gui.main_window import MainWindow

WHY = "the mock bench needs pseudo-terminals (test)"


def test_mock_bench_offered_where_it_runs(qtbot, make_window) -> None:
    window: MainWindow = make_window()
    station = window.station_view
    assert station.mock_unavailable == "" and station.mock_button.isEnabled()


def test_mock_bench_not_offered_where_it_cannot_run(qtbot, make_window,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(station_module, "unavailable", lambda: WHY)
    window: MainWindow = make_window()
    station = window.station_view
    for w in (station.mock_button, station.bench_combo, station.method_combo):
        assert not w.isEnabled() and w.toolTip() == WHY
    assert window.messages.text.startswith("No station yet: open a station file")
    assert station.name_label.text() == "No station: open a station file"
    with qtbot.waitSignal(station.message, timeout=60000) as blocker:
        station.use_mock("engine-rigid")  # e.g. the last session's station was the mock
    assert blocker.args == ["error", WHY]
    assert station.mock is None and station.station is None


def test_last_mock_station_not_restarted_where_it_cannot_run(
        qtbot, make_window, monkeypatch: pytest.MonkeyPatch) -> None:
    first: MainWindow = make_window()
    first.station_view.use_mock("engine-rigid")
    assert first.station_view.mock is not None
    first.close()
    monkeypatch.setattr(station_module, "unavailable", lambda: WHY)
    again: MainWindow = make_window()
    again.station_view.start()
    assert again.station_view.mock is None
