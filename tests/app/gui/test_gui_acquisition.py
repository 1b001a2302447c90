"""The whole test on the mock bench through the GUI's own controls: station, plan, start,
hits with accept/reject overrides, next points, identification, exports, settings; and a
screenshot of every main view (into docs/screenshots with ``INSITU_SCREENSHOTS=1``, to
refresh the docs; else into the test's temporary folder, so a test run leaves the tree as
it was)."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PySide6 import QtWidgets

from app.acquire.events import RunState
from app.cli.main import main
from app.gui.main_window import MainWindow
from app.io.runfile import read_run
from app.mockbench.bench import plan_for_bench
from hardware_mocks.benches import get_bench

DOC_SHOTS = Path(__file__).resolve().parents[3] / "docs" / "screenshots"
#: six excitations at six points that span the six rigid-body DOFs (cond T about 11)
POINTS = [0, 4, 8, 9, 13, 17]


def _value(text: str) -> float:
    """The number of a table cell, without its spread (``± h`` or ``[lo, hi]``)."""
    return float(text.split(" ")[0])


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def _write_plan(path: Path) -> None:
    """The bench's plan, reduced to POINTS, as the TOML file an engineer would write."""
    data = plan_for_bench("engine-rigid", points=POINTS, length=2.0).to_dict()
    out = []
    for table in ("plan", "record"):
        out.append(f"[{table}]")
        out += [f"{k} = {_toml_value(v)}" for k, v in data[table].items()]
    for name in ("excitation", "response"):
        for item in data[name]:
            out.append(f"[[{name}]]")
            out += [f"{k} = {_toml_value(v)}" for k, v in item.items()]
    path.write_text("\n".join(out) + "\n")


def _screenshot(window: MainWindow, view: QtWidgets.QWidget, name: str, tmp: Path) -> None:
    window.tabs.setCurrentWidget(view)
    QtWidgets.QApplication.processEvents()
    folder = DOC_SHOTS if os.environ.get("INSITU_SCREENSHOTS") == "1" else tmp / "screenshots"
    folder.mkdir(parents=True, exist_ok=True)
    assert window.grab().save(str(folder / f"{name}.png"))


def _text(table: QtWidgets.QTableWidget, row: int, col: int) -> str:
    item = table.item(row, col)
    return item.text() if item is not None else ""


def _verdict_cells(window: MainWindow, row: int) -> tuple[str, str, str]:
    """(automatic verdict, operator's override, used) of a row of the hits table."""
    t = window.acquisition_view.hits_table
    return _text(t, row, 6), _text(t, row, 5), _text(t, row, 4)


@pytest.mark.slow
def test_whole_test_on_the_mock_bench(qtbot, make_window: Callable[..., MainWindow],
                                      choose_file: Callable[..., None],
                                      tmp_path: Path) -> None:
    model = get_bench("engine-rigid").model
    window = make_window()
    station = window.station_view
    # Station: the built-in mock bench, its devices answer, live levels move on a hit
    station.bench_combo.setCurrentText("engine-rigid")
    station.mock_button.click()
    assert station.station is not None
    n_channels = sum(len(d.channels) for d in station.station.devices.values())
    assert n_channels >= 13 and station.channels.rowCount() == n_channels
    with qtbot.waitSignal(window.runner.done, timeout=120000):
        station.check_button.click()
    qtbot.waitUntil(lambda: _text(station.devices, 0, 4) == "OK", timeout=120000)
    station.monitor_button.click()
    assert station.stream is not None
    try:  # a stream that stopped says why in the message bar
        qtbot.waitUntil(lambda: station.levels.frames_new > 3, timeout=120000)
    except qtbot.TimeoutError:
        pytest.fail(f"{station.levels.frames_new} live frames: {window.messages.text}")
    station.tap_button.click()
    force = list(station.stream.source.names).index("F")  # the hammer
    qtbot.waitUntil(lambda: station.levels.peak_percent()[force] > 1.0, timeout=120000)
    qtbot.wait(300)  # let the response ring in the traces (the bars: the last 0.5 s)
    _screenshot(window, station, "station", tmp_path)

    # Test plan: imported from TOML; the geometry check passes before any hit
    plan_file = tmp_path / "engine-6.toml"
    _write_plan(plan_file)
    choose_file(plan_file)
    window.plan_view.import_plan_button.click()
    assert window.plan_view.plan is not None and len(window.plan_view.plan.excitations) == 6
    assert window.plan_view.geometry_text().startswith("Geometry OK")
    _screenshot(window, window.plan_view, "plan", tmp_path)

    # Acquisition: the simulated operator double-hits on the second hit
    assert station.mock is not None
    station.mock.operator.faults[1] = "double"
    acq = window.acquisition_view
    run = tmp_path / "run.h5"
    acq.run_path.setText(str(run))
    acq.start_button.click()
    assert station.stream is None  # live levels released the devices
    assert not acq.start_button.isEnabled() and acq.stop_button.isEnabled()
    table = acq.hits_table
    qtbot.waitUntil(lambda: table.rowCount() >= 3, timeout=120000)
    assert _verdict_cells(window, 1)[0].startswith("double hit")
    assert _verdict_cells(window, 2) == ("accepted", "-", "yes")
    # the operator tries the overrides: keep the double hit and reject the repeat ...
    table.selectRow(1)
    acq.accept_button.click()
    table.selectRow(2)
    acq.reject_button.click()
    qtbot.waitUntil(lambda: _verdict_cells(window, 2)[1] == "reject", timeout=120000)
    assert _verdict_cells(window, 1)[1:] == ("accept", "yes")
    assert _verdict_cells(window, 2)[2] == "no"
    # ... then thinks better of it and goes back to the automatic verdicts: the clean repeat
    # is used, the double hit is not (its FRF would be sound, its force window spans the
    # rebound, but the rebound's force spectrum dips every 83 Hz; the repeat's does not)
    # (the repeat's reject first: cleared the other way round, point 1 has no used hit
    # between the two clicks, and a run whose last point ends then goes back to it)
    for row in (2, 1):
        table.selectRow(row)
        acq.clear_button.click()
    qtbot.waitUntil(lambda: _verdict_cells(window, 1)[1] == "-"
                    and _verdict_cells(window, 2)[1] == "-", timeout=120000)
    assert _verdict_cells(window, 1)[2] == "no" and _verdict_cells(window, 2)[2] == "yes"
    qtbot.waitUntil(lambda: acq.state is not RunState.RUNNING, timeout=120000)
    assert acq.state is RunState.FINISHED, (acq.next_label.text(), window.messages.text)
    qtbot.waitUntil(lambda: window.session.analysis is not None
                    and window.session.path == run, timeout=120000)
    assert acq.progress_bar.value() == 6
    n_hits = table.rowCount()  # 7, or more if the loaded machine made a hit arrive late
    assert n_hits >= 7
    # the simulated operator took none of the re-reported (overridden) hits for new ones
    operator = station.mock.operator
    assert operator.hits_made == n_hits, (operator.points, operator.repeats)
    assert acq.next_label.text().startswith("Finished")
    _screenshot(window, acq, "acquisition", tmp_path)

    # the run file holds every hit and the overrides
    stored = read_run(run, with_data=False)
    assert stored.state == "finished" and len(stored.records) == n_hits
    assert stored.records.override[:3] == ("", "", "")
    assert list(stored.records.accepted[:3]) == [True, False, True]
    assert int(np.sum(stored.records.accepted)) == 6  # one per point

    # identification against the model's truth
    r = window.session.analysis.result
    assert r is not None
    p = r.properties
    assert p.mass == pytest.approx(model.mass, rel=0.01)
    np.testing.assert_allclose(p.cog, model.cog, atol=2e-3)
    np.testing.assert_allclose(np.diag(r.K), np.diag(model.K), rtol=0.02)
    assert abs(_value(_text(window.results_view.inertia, 0, 2)) - model.mass) < 1.1
    _screenshot(window, window.checks_view, "checks", tmp_path)
    _screenshot(window, window.results_view, "results", tmp_path)

    # exports: the run file, the result JSON, the report
    export = window.export_view
    assert export.run_button.isEnabled()
    for button, name in ((export.run_button, "copy.h5"), (export.json_button, "r.json"),
                         (export.html_button, "r.html")):
        choose_file(tmp_path / name, save=True)
        button.click()
    assert read_run(tmp_path / "copy.h5", with_data=False).state == "finished"
    assert json.loads((tmp_path / "r.json").read_text())["mass"] == pytest.approx(p.mass)
    assert "data:image/png;base64," in (tmp_path / "r.html").read_text()
    _screenshot(window, export, "export", tmp_path)

    # settings: the next session comes back with this station, plan and tab
    window.tabs.setCurrentWidget(window.results_view)
    window.close()
    again = make_window()
    assert again.station_view.mock is not None
    assert again.station_view.bench_combo.currentText() == "engine-rigid"
    assert again.plan_view.plan_path == plan_file
    assert again.plan_view.plan is not None and len(again.plan_view.plan.excitations) == 6
    assert again.tabs.currentWidget() is again.results_view

    # replay: the recorded run opens through File > Open into the same views
    choose_file(tmp_path / "copy.h5")
    with qtbot.waitSignal(again.session.analysis_changed, timeout=120000) as blocker:
        again.open_action.trigger()
    replayed = blocker.args[0]
    assert replayed.result is not None and replayed.frf.H.shape == (12, 6, 800)
    assert replayed.result.properties.mass == pytest.approx(p.mass, rel=1e-9)
    assert again.export_view.run_button.isEnabled()
    # one hit a point: the coherence is 1 by definition, a check that cannot fail
    assert again.checks_view.overall.text() == "No check fails; not checked: coherence ≥ 0.8"

    # and the same report without a GUI
    assert main(["report", str(tmp_path / "copy.h5"), "--out", str(tmp_path / "cli.html")]) == 0
    text = (tmp_path / "cli.html").read_text()
    assert text.count("data:image/png;base64,") == 6 and f"{p.mass:.3f}" in text


def test_pause_resume_stop_keeps_the_hits(qtbot, make_window, tmp_path: Path) -> None:
    window = make_window()
    window.station_view.use_mock("engine-rigid")
    acq = window.acquisition_view
    acq.run_path.setText(str(tmp_path / "stopped.h5"))
    acq.start_button.click()
    qtbot.waitUntil(lambda: acq.hits_table.rowCount() >= 1, timeout=120000)
    # an override and its undo ("Automatic verdict") while the run goes on
    acq.hits_table.selectRow(0)
    acq.reject_button.click()
    qtbot.waitUntil(lambda: _verdict_cells(window, 0)[1:] == ("reject", "no"), timeout=120000)
    acq.hits_table.selectRow(0)
    acq.clear_button.click()
    qtbot.waitUntil(lambda: _verdict_cells(window, 0)[1:] == ("-", "yes"), timeout=120000)
    acq.pause_button.click()
    qtbot.waitUntil(lambda: acq.state is RunState.PAUSED, timeout=120000)
    assert acq.resume_button.isEnabled() and not acq.pause_button.isEnabled()
    assert acq.next_label.text().startswith("Paused: paused by the operator")
    acq.resume_button.click()
    qtbot.waitUntil(lambda: acq.state is RunState.RUNNING, timeout=120000)
    with qtbot.waitSignal(acq.bridge.finished, timeout=120000):
        acq.stop_button.click()
    assert acq.state is RunState.STOPPED
    assert window.messages.level == "warning" and "saved in" in window.messages.text
    stored = read_run(tmp_path / "stopped.h5", with_data=False)
    assert stored.state == "stopped" and len(stored.records) == acq.hits_table.rowCount()
    assert acq.start_button.isEnabled() and not acq.stop_button.isEnabled()
