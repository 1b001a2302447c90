"""The checks view says "not checked" for a check that cannot fail (one hit a point), and
the results view states the spreads' convention once (screenshot ``checks_not_checked``
into docs/screenshots with ``INSITU_SCREENSHOTS=1``)."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
from PySide6 import QtWidgets

from app.gui.main_window import MainWindow
from app.report.analysis import analyse
from app.report.tables import SPREADS
from hardware_mocks.benches import get_bench
from processing.measurement import Measurement, Provenance

DOC_SHOTS = Path(__file__).resolve().parents[3] / "docs" / "screenshots"


def _one_hit_a_point() -> Measurement:
    """FRFs of one hit a point: their coherence is 1 everywhere, by definition."""
    frf = get_bench("engine-rigid").frfset(noise=0.01, seed=5)
    frf = replace(frf, coherence=np.ones(frf.H.shape))
    n = frf.H.shape[1]
    return Measurement(frf, Provenance(excitation="impact", n_averages=(1,) * n),
                       source="one hit a point")


def test_checks_view_says_not_checked_for_one_hit_a_point(qtbot, make_window,
                                                          tmp_path: Path) -> None:
    window: MainWindow = make_window()
    a = analyse(_one_hit_a_point())
    assert a.result is not None and a.gate is not None
    window.session.analysis = a
    window.session.analysis_changed.emit(a)
    view = window.checks_view
    coherence = next(k for k in view.verdicts() if k.startswith("coherence"))
    assert view.verdicts()[coherence] is None
    row = next(i for i in range(view.table.rowCount())
               if view.table.item(i, 0).text() == coherence)
    assert view.table.item(row, 1).text() == "not checked"
    assert view.table.item(row, 2).text().startswith(
        "one hit a point: the coherence is 1 by definition")
    assert "All checks pass" not in view.overall.text()
    assert "not checked: " + coherence in view.overall.text()
    title = view.coherence_bars.getPlotItem().titleLabel.text
    assert "not checked (one hit a point" in title  # the bars are no "pass" either
    # the results view: the spreads' convention once, at the head of the uncertainty
    text = window.results_view.uncertainty.text()
    assert text.splitlines()[0] == SPREADS and text.count("95 %") == 1
    window.tabs.setCurrentWidget(view)
    QtWidgets.QApplication.processEvents()
    folder = DOC_SHOTS if os.environ.get("INSITU_SCREENSHOTS") == "1" else tmp_path / "shots"
    folder.mkdir(parents=True, exist_ok=True)
    assert window.grab().save(str(folder / "checks_not_checked.png"))
