"""The mount system in the GUI (plan view's mounts, results' modes, decoupling, mount rates,
mode-shape arrows) and in the HTML report; screenshots into docs/screenshots with
``INSITU_SCREENSHOTS=1``."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtWidgets

from app.cli.main import main
from app.gui.main_window import MainWindow
from app.io.uff import write_frf_uff
from hardware_mocks.benches import get_bench

DOC_SHOTS = Path(__file__).resolve().parents[3] / "docs" / "screenshots"


def _files(tmp_path: Path) -> tuple[Path, Path]:
    bench = get_bench("engine-rigid")
    uff = tmp_path / "engine.uff"
    write_frf_uff(uff, bench.frfset())
    lines = ["crank_axis = [1.0, 0.0, 0.0]"]
    for i, m in enumerate(bench.model.mounts):
        axes = ", ".join("[" + ", ".join(repr(float(x)) for x in a) + "]" for a in m.axes.T)
        lines += ["[[mount]]", f'name = "mount {i + 1}"',
                  "position = [" + ", ".join(repr(float(x)) for x in m.position) + "]",
                  f"axes = [{axes}]"]
    toml = tmp_path / "mounts.toml"
    toml.write_text("\n".join(lines) + "\n")
    return uff, toml


def _shot(window: MainWindow, name: str, tmp: Path) -> None:
    QtWidgets.QApplication.processEvents()
    folder = DOC_SHOTS if os.environ.get("INSITU_SCREENSHOTS") == "1" else tmp / "screenshots"
    folder.mkdir(parents=True, exist_ok=True)
    assert window.grab().save(str(folder / f"{name}.png"))


def _col(table: QtWidgets.QTableWidget, col: int) -> list[str]:
    return [table.item(r, col).text() if table.item(r, col) else ""
            for r in range(table.rowCount())]


def test_mounts_in_plan_and_results(qtbot, make_window, choose_file, tmp_path: Path) -> None:
    uff, toml = _files(tmp_path)
    model = get_bench("engine-rigid").model
    window: MainWindow = make_window()
    plan = window.plan_view
    # a bad mounts file: one line in the message bar, nothing loaded
    bad = tmp_path / "bad.toml"
    bad.write_text("crank_axis = [1, 0, 0]\n")
    choose_file(bad)
    plan.mounts_button.click()
    assert window.messages.level == "error" and "no [[mount]]" in window.messages.text
    assert window.session.mounts is None
    choose_file(toml)
    plan.mounts_button.click()
    assert window.session.mounts is not None
    assert _col(plan.mounts_table, 0) == ["mount 1", "mount 2", "mount 3"]
    assert "determines 9 of 9 rates" in plan.mounts_label.text()
    # open the FRFs: the results show the modes, decoupling, rates and arrows
    choose_file(uff)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000):
        window.open_action.trigger()
    res = window.results_view
    ms = res.mount_system
    assert ms is not None and ms.rates is not None
    # the bench's dampers are viscous: the data choose C, D is shown as zeros
    assert "Damping model: viscous" in res.summary.text()
    assert "damping viscous (K + jwC)" in res.damping_note.text()
    assert res.D.rowCount() == 6 and ms.rates.structural is None
    assert "loss factor at" in ms.mount_head()[4]
    f = [float(x) for x in _col(res.modes, 1)]
    np.testing.assert_allclose(f, model.rigid_modes().frequency, rtol=2e-3)
    assert res.energy.rowCount() == 6 and res.energy.columnCount() == 7
    rates = [float(x) for x in _col(res.mount_rates, 2)]
    np.testing.assert_allclose(rates, np.concatenate([m.stiffness for m in model.mounts]),
                               rtol=0.01)
    assert set(_col(res.mount_rates, 6)) == {"yes"}
    assert res.tra.rowCount() >= 5
    P, U = res.mode_shapes.arrows(0)
    assert P.shape == U.shape and len(P) == 4 + 3 + 1  # 4 response points, 3 mounts, CoG
    window.tabs.setCurrentWidget(plan)
    _shot(window, "mounts_plan", tmp_path)
    window.tabs.setCurrentWidget(res)
    res.excitation.setValue(25.0)  # the isolation columns appear
    assert res.modes.columnCount() == 7 and "NOT isolated" in " ".join(_col(res.modes, 5))
    res.table_tabs.setCurrentWidget(res.modes_page)
    res.plot_tabs.setCurrentWidget(res.mode_shapes)
    res.mode_shapes.mode.setCurrentIndex(2)
    _shot(window, "results_modes", tmp_path)
    res.table_tabs.setCurrentWidget(res.mounts_page)
    _shot(window, "results_mounts", tmp_path)
    res.table_tabs.setCurrentWidget(res.energy)
    _shot(window, "results_energy", tmp_path)
    # the exported result JSON and report carry the mount system
    out = tmp_path / "export.json"
    choose_file(out, save=True)
    window.export_view.json_button.click()
    js = json.loads(out.read_text())
    assert len(js["modes"]) == 6 and len(js["mounts"]) == 3 and "torque_roll_axis" in js
    report = tmp_path / "export.html"
    choose_file(report, save=True)
    window.export_view.html_button.click()
    assert "<h2>Individual mount rates</h2>" in report.read_text()


def test_report_with_mounts(tmp_path: Path, qapp, capsys: pytest.CaptureFixture[str]) -> None:
    uff, toml = _files(tmp_path)
    out = tmp_path / "r.html"
    assert main(["report", str(uff), "--mounts", str(toml), "--excitation-hz", "25",
                 "--out", str(out)]) == 0
    html = out.read_text()
    for h in ("Rigid-body modes", "Individual mount rates", "Torque roll axis"):
        assert f"<h2>{h}</h2>" in html
    assert len(re.findall(r"<td class=\"l\">mount \d</td>", html)) == 3
    assert "NOT isolated" in html  # 25 Hz is within sqrt(2) of the upper modes
    bad = tmp_path / "bad.toml"
    bad.write_text("crank_axis = [1, 0]\n")
    assert main(["report", str(uff), "--mounts", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "crank_axis" in err


@pytest.mark.slow
def test_run_file_mounts_are_loaded_with_the_run(qtbot, make_window, choose_file,
                                                 tmp_path: Path) -> None:
    """A run file that carries a mounts table brings it into the plan view and the results."""
    from app.acquire import HammerProcedure, RunState
    from app.io.mounts import load_mounts
    from app.io.runfile import write_mounts
    from app.mockbench.bench import InProcessBench, plan_for_bench

    _, toml = _files(tmp_path)
    # six well-conditioned excitations (the GUI acquisition test's)
    plan = plan_for_bench("engine-rigid", points=[0, 4, 8, 9, 13, 17])
    path = tmp_path / "run.h5"
    # a run file is opened from its records (always recomputed): a run recorded on the bench
    with InProcessBench("engine-rigid") as bench:
        proc = HammerProcedure(plan, bench.station, path, listeners=[bench.operator])
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
    write_mounts(path, load_mounts(toml))
    window: MainWindow = make_window()
    choose_file(path)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000):
        window.open_action.trigger()
    assert window.session.mounts is not None
    assert _col(window.plan_view.mounts_table, 0) == ["mount 1", "mount 2", "mount 3"]
    ms = window.results_view.mount_system
    assert ms is not None and ms.rates is not None and ms.rates.stiffness.identifiable.all()


def test_rubber_mounts_in_results(qtbot, make_window, choose_file, tmp_path: Path) -> None:
    """Hysteretic (rubber) mounts of the independent reference model: the data choose the
    structural damping D, the D tab holds it and each mount's loss factor is d / k (the
    model's own, noise-free: to the table's 3 decimals)."""
    from hardware_mocks.reference.mounts import mounts_toml
    from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
    from processing.data import FRFSet, Geometry

    sc = build_scenario(ScenarioSpec(seed=2, shape="engine", n_sensors=4, n_forces=12,
                                     n_mounts=4, elastic_ratio=None, damping="hysteretic"))
    ids, xyz = sc.geometry()
    uff, toml = tmp_path / "rubber.uff", tmp_path / "rubber.toml"
    write_frf_uff(uff, FRFSet(freq=sc.freq, H=sc.H, resp_nodes=sc.sensors.ids,
                              resp_dirs=sc.sensors.reported_dirs, exc_nodes=sc.forces.ids,
                              exc_dirs=sc.forces.reported_dirs, geometry=Geometry(ids, xyz)),
                  binary=True)
    toml.write_text(mounts_toml(sc.mounts))
    window: MainWindow = make_window()
    choose_file(toml)
    window.plan_view.mounts_button.click()
    choose_file(uff)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000):
        window.open_action.trigger()
    res = window.results_view
    ms = res.mount_system
    assert ms is not None and ms.rates is not None and ms.rates.structural is not None
    assert "Damping model: hysteretic" in res.summary.text()
    assert "damping structural (K + jD)" in res.damping_note.text()
    assert ms.mount_head()[4] == "loss factor d/k"
    eta = [float(x) for x in _col(res.mount_rates, 4)]
    np.testing.assert_allclose(eta, np.concatenate([m.loss_factors for m in sc.mounts]),
                               rtol=0, atol=5.01e-4)
    window.tabs.setCurrentWidget(res)
    res.table_tabs.setCurrentWidget(res.mounts_page)
    _shot(window, "results_mounts_rubber", tmp_path)
    res.table_tabs.setCurrentWidget(res.damping_page)
    _shot(window, "results_damping", tmp_path)


def _opened_with_cli(qtbot, make_window, choose_file, uff: Path,
                     tmp: Path) -> tuple[MainWindow, str, dict]:
    """The window with ``uff`` opened and analysed, its results' damping note, and the
    command line's result JSON of the same file."""
    window: MainWindow = make_window()
    choose_file(uff)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000):
        window.open_action.trigger()
    out = tmp / "r.json"
    assert main(["identify", str(uff), "--no-uncertainty", "--out", str(out)]) == 0
    return window, window.results_view.damping_note.text(), json.loads(out.read_text())


def test_stiffening_mounts_in_the_results(qtbot, make_window, choose_file,
                                          tmp_path: Path) -> None:
    """FRFs of mounts stiffening 30 % a decade (the independent reference model): the
    results' damping page says the stiffness rises, at which frequency K holds and how it
    was chosen, as the command line's result does."""
    from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
    from processing.data import FRFSet, Geometry

    sc = build_scenario(ScenarioSpec(seed=8107, shape="engine", n_forces=12, n_lines=800,
                                     elastic_ratio=None, stiffening=0.3))
    ids, xyz = sc.geometry()
    uff = tmp_path / "stiffening.uff"
    write_frf_uff(uff, FRFSet(sc.freq, sc.H, sc.sensors.ids, sc.sensors.reported_dirs,
                              sc.forces.ids, sc.forces.reported_dirs, Geometry(ids, xyz)))
    window, note, js = _opened_with_cli(qtbot, make_window, choose_file, uff, tmp_path)
    res = window.results_view
    assert "stiffness rising +" in note and "K stated at" in note, note
    assert f"{js['stiffening_choice']}" in note  # the same words as the command line's
    window.tabs.setCurrentWidget(res)
    res.table_tabs.setCurrentWidget(res.damping_page)
    _shot(window, "results_stiffening", tmp_path)


def test_channel_delays_in_the_results(qtbot, make_window, choose_file, tmp_path: Path) -> None:
    """FRFs whose responses are each up to a sample late at 1024 Hz (the independent
    reference model's, the delays put on here): the results' damping page says the delays
    were read and taken out, in the command line's words."""
    from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
    from processing.data import FRFSet, Geometry

    sc = build_scenario(ScenarioSpec(seed=8210, shape="engine", n_forces=12, noise=0.005,
                                     elastic_ratio=8.0))
    tau = np.random.default_rng(8211).uniform(-1, 1, sc.H.shape[0]) / 1024
    H = sc.H * np.exp(-2j * np.pi * sc.freq[None, :] * tau[:, None])[:, None, :]
    ids, xyz = sc.geometry()
    uff = tmp_path / "skewed.uff"
    write_frf_uff(uff, FRFSet(sc.freq, H, sc.sensors.ids, sc.sensors.reported_dirs,
                              sc.forces.ids, sc.forces.reported_dirs, Geometry(ids, xyz),
                              sc.coherence))
    window, note, js = _opened_with_cli(qtbot, make_window, choose_file, uff, tmp_path)
    res = window.results_view
    assert js["channel_delays"] is not None
    assert js["channel_delays_choice"].startswith("channel delays read on")
    assert js["channel_delays_choice"][1:] in note, note  # the command line's words
    window.tabs.setCurrentWidget(res)
    res.table_tabs.setCurrentWidget(res.damping_page)
    _shot(window, "results_channel_delays", tmp_path)
