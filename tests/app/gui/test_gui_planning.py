"""The Test plan tab's planner: load a model and candidates, plan on the worker thread, see
the predicted std, edit the layout and see the prediction change; the layout becomes the
acquisition plan; bad files and rank-deficient layouts are one-line messages (screenshot
``plan_planner`` into docs/screenshots with ``INSITU_SCREENSHOTS=1``)."""

from __future__ import annotations

import os
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from app.gui.main_window import MainWindow
from tests.app.test_cli_plan import MODEL, _candidates

DOC_SHOTS = Path(__file__).resolve().parents[3] / "docs" / "screenshots"


def _uncheck(window: MainWindow, row: int) -> None:
    item = window.plan_view.planner.candidates_table.item(row, 0)
    assert item is not None and item.checkState() == QtCore.Qt.CheckState.Checked
    item.setCheckState(QtCore.Qt.CheckState.Unchecked)


def test_planner_plans_edits_and_refuses(qtbot, make_window, tmp_path: Path) -> None:
    (tmp_path / "model.toml").write_text(MODEL)
    (tmp_path / "cand.toml").write_text(_candidates())
    window: MainWindow = make_window()
    pv = window.plan_view
    planner = pv.planner
    window.tabs.setCurrentWidget(pv)
    pv.sides.setCurrentWidget(planner)
    assert planner.load_files(tmp_path / "model.toml", tmp_path / "cand.toml")
    assert planner.candidates_table.rowCount() == 12 + 24  # sensors, point directions
    planner.n_sensors.setValue(3)
    planner.n_points.setValue(7)
    planner.location.setValue(1.0)
    with qtbot.waitSignal(planner.planned, timeout=30000):
        planner.plan_button.click()
    assert len(planner.sensors) == 3 and len(planner.excitations) == 7
    ticked = [i for i in range(planner.candidates_table.rowCount())
              if planner.candidates_table.item(i, 0).checkState()
              == QtCore.Qt.CheckState.Checked]
    assert len(ticked) == 10
    before = [planner.predicted_text(r) for r in range(planner.prediction_table.rowCount())]
    assert planner.prediction_table.rowCount() == 16  # mass, CoG, six J, K diagonal
    assert float(before[0]) > 0 and planner.prediction_table.item(0, 3).text().startswith("± ")
    # the layout is the acquisition plan, with its prediction
    plan = pv.plan
    assert plan is planner.plan and plan is not None and plan.prediction is not None
    assert len(plan.responses) == 3 and len(plan.excitations) == 7
    assert sum(r.role == "excitation" for r in pv.rows()) == 7
    QtWidgets.QApplication.processEvents()
    folder = DOC_SHOTS if os.environ.get("INSITU_SCREENSHOTS") == "1" else tmp_path / "shots"
    folder.mkdir(parents=True, exist_ok=True)
    assert window.grab().save(str(folder / "plan_planner.png"))
    # the operator removes a chosen excitation: predicted again, a new acquisition plan
    with qtbot.waitSignal(planner.planned, timeout=30000):
        _uncheck(window, 12 + planner.excitations[0])
    assert len(planner.excitations) == 6 and len(pv.plan.excitations) == 6
    after = [planner.predicted_text(r) for r in range(planner.prediction_table.rowCount())]
    assert after != before and all(float(x) > 0 for x in after)
    assert planner.save_plan(tmp_path / "p.toml") and pv.plan_path == tmp_path / "p.toml"
    # a sensor removed: two triaxial sensors cannot see six DOFs, a one-line message
    with qtbot.waitSignal(window.runner.failed, timeout=30000):
        _uncheck(window, planner.sensors[0])
    text = window.messages.text
    assert text.startswith("cannot predict this layout:") and "\n" not in text
    assert planner.prediction_table.rowCount() == 0
    assert len(pv.plan.responses) == 3  # the acquisition plan is the last predicted layout
    # a bad candidates file
    (tmp_path / "bad.toml").write_text('[[sensor]]\nnode = "one"\nxyz = [0, 0, 0]\n')
    assert not planner.load_files(candidates=tmp_path / "bad.toml")
    text = window.messages.text
    assert text.startswith("cannot plan from these files:") and "bad.toml: point:" in text
    assert "\n" not in text and "Traceback" not in text
