"""Replay bench FRFs through the GUI: open, identify, adjust a band, export, check truth."""

from __future__ import annotations

import base64
import json
import re
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtWidgets

from app.gui.main_window import MainWindow
from app.io.uff import read_frf_uff, write_frf_uff
from app.report.analysis import Analysis
from hardware_mocks.benches import get_bench


def _value(text: str) -> float:
    """The number of a table cell, without its spread (``± h`` or ``[lo, hi]``)."""
    return float(text.split(" ")[0])


def _bench_uff(tmp_path: Path, name: str = "engine-rigid", noise: float = 0.0) -> Path:
    frf = get_bench(name).frfset(noise=noise)
    # coherence as an analyser would give it: 0.99 everywhere, a dip in one FRF at 100-110 Hz
    coh = np.full(frf.H.shape, 0.99)
    coh[0, 0, (frf.freq >= 100) & (frf.freq <= 110)] = 0.5
    path = tmp_path / f"{name}.uff"
    write_frf_uff(path, replace(frf, coherence=coh))
    return path


def _open(qtbot, window: MainWindow, choose_file: Callable[..., None],
          path: Path) -> Analysis:
    choose_file(path)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000) as blocker:
        window.open_action.trigger()
    a = blocker.args[0]
    assert isinstance(a, Analysis)
    return a


def _cell(table: QtWidgets.QTableWidget, row: int, col: int) -> str:
    item = table.item(row, col)
    assert item is not None
    return item.text()


def test_replay_identify_band_export(qtbot, make_window, choose_file,
                                     tmp_path: Path) -> None:
    model = get_bench("engine-rigid").model
    window: MainWindow = make_window()
    a = _open(qtbot, window, choose_file, _bench_uff(tmp_path))
    r = a.result
    assert r is not None
    # the tables show the identified values, against the model's truth
    results = window.results_view
    assert _cell(results.inertia, 0, 0) == "mass m"
    assert _value(_cell(results.inertia, 0, 2)) == pytest.approx(model.mass, rel=1e-4)
    for k in range(3):  # CoG, mm
        assert _value(_cell(results.inertia, 1 + k, 3)) == pytest.approx(model.cog[k] * 1e3,
                                                                        abs=0.05)
    J = model.inertia_cog
    assert _value(_cell(results.inertia, 4, 2)) == pytest.approx(J[0, 0], rel=1e-3)
    assert _value(_cell(results.inertia, 7, 2)) == pytest.approx(-J[0, 1], abs=1e-3)
    np.testing.assert_allclose(r.K, model.K, atol=2e-3 * np.abs(model.K).max())
    assert _value(_cell(results.K, 2, 3)) == pytest.approx(model.K[2, 2], rel=1e-3)
    assert "Physically consistent" in results.verdict.text()
    # the plan view shows the file's DOFs and a sound geometry
    assert window.plan_view.table.rowCount() == 12 + 18
    assert window.plan_view.geometry_text().startswith("Geometry OK")
    # checks: the coherence dip fails the coherence check, the rigid body passes rigidity
    verdicts = window.checks_view.verdicts()
    assert verdicts["coherence ≥ 0.8"] is False
    assert verdicts["rigidity (sensors predict each other)"] is True
    assert window.checks_view.overall.text().startswith("FAIL: coherence")

    # the operator narrows the bands: re-identified off the GUI thread with those bands
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000) as blocker:
        results.set_bands((50.0, 80.0), (2.0, 30.0))
    b = blocker.args[0]
    assert b.result is not None and not results.auto_bands.isChecked()
    assert b.result.mass_band == pytest.approx((50.0, 80.0))
    assert b.result.stiffness_band == pytest.approx((2.0, 30.0))
    assert b.result.properties.mass == pytest.approx(model.mass, rel=1e-4)
    assert results.mass_lo.value() == pytest.approx(50.0)
    # an impossible band is a message in the window, not a traceback
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000):
        results.set_bands((50.0, 900.0), (2.0, 30.0))
    assert window.messages.level == "error"
    assert "outside the data" in window.messages.text
    assert results.verdict.text().startswith("Identification failed")
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000):
        results.set_bands((50.0, 80.0), (2.0, 30.0))
    assert window.session.analysis is not None and window.session.analysis.result is not None

    # exports through the Export view's buttons
    export = window.export_view
    assert not export.run_button.isEnabled()  # UFF data: no run file to save
    out_json, out_uff, out_html = (tmp_path / "r.json", tmp_path / "f.uff", tmp_path / "r.html")
    choose_file(out_json, save=True)
    export.json_button.click()
    choose_file(out_uff, save=True)
    export.uff_button.click()
    choose_file(out_html, save=True)
    export.html_button.click()
    assert export.written == [out_json, out_uff, out_html]
    res = json.loads(out_json.read_text())
    assert res["mass"] == pytest.approx(model.mass, rel=1e-4)
    np.testing.assert_allclose(res["cog"], model.cog, atol=5e-5)
    np.testing.assert_allclose(res["inertia_cog"], model.inertia_cog, atol=2e-3)
    assert res["bands"]["mass_line"] == pytest.approx([50.0, 80.0])
    back = read_frf_uff(out_uff)
    assert window.session.frf is not None
    np.testing.assert_allclose(back.H, window.session.frf.H, rtol=1e-9, atol=1e-15)
    assert back.coherence is not None
    html = out_html.read_text()
    pngs = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", html)
    assert len(pngs) == 6
    assert all(base64.b64decode(p)[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    assert f"{model.mass:.3f}" in html and "FAIL" in html and "PASS" in html


def test_bad_file_and_bad_geometry_show_messages(qtbot, make_window, choose_file,
                                                 tmp_path: Path) -> None:
    window: MainWindow = make_window()
    bad = tmp_path / "broken.uff"
    bad.write_text("    -1\n    58\nnot a uff file\n")
    choose_file(bad)
    with qtbot.waitSignal(window.session.message, timeout=300000,
                          check_params_cb=lambda level, text: level == "error"):
        window.open_action.trigger()
    assert window.messages.text.startswith("cannot open the file: ")
    assert "Traceback" not in window.messages.text
    # a plan whose response points are collinear cannot identify 6 DOFs: said before any hit
    csv = tmp_path / "plan.csv"
    lines = ["role,node,x,y,z,dx,dy,dz"]
    for n in range(3):
        for d in ("1,0,0", "0,1,0", "0,0,1"):
            lines.append(f"response,{n + 1},{0.1 * n},0,0,{d}")
    for n, (p, d) in enumerate([("0.25,0.1,0.2", "1,0,0"), ("-0.25,0.12,0.22", "0,1,0"),
                                ("0.05,-0.05,0.18", "0,0,1"), ("0.02,0.48,0.2", "0,1,0"),
                                ("0.1,0.2,0.33", "1,0,0"), ("-0.12,0.3,0.32", "0,-1,0")]):
        lines.append(f"excitation,{101 + n},{p},{d}")
    csv.write_text("\n".join(lines) + "\n")
    choose_file(csv)
    window.plan_view.import_csv_button.click()
    assert window.plan_view.table.rowCount() == 15
    text = window.plan_view.geometry_text()
    assert text.startswith("Geometry cannot identify all six DOFs")
    assert "collinear" in text
    # the operator moves point 3 off the line: the check passes at once
    for j, v in zip((2, 3, 4), ("0.1", "0.3", "0.1"), strict=True):
        for row in (6, 7, 8):
            item = window.plan_view.table.item(row, j)
            assert item is not None
            item.setText(v)
    assert window.plan_view.geometry_text().startswith("Geometry OK"), \
        window.plan_view.geometry_text()
