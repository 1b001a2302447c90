"""The results view and the HTML report show each number's 95 % spread and the largest
contributions when the result carries an uncertainty (screenshot ``results_uncertainty``
into docs/screenshots with ``INSITU_SCREENSHOTS=1``)."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from PySide6 import QtWidgets

from app.gui.main_window import MainWindow
from app.io.uff import write_frf_uff
from app.report.analysis import Analysis
from app.report.html import build_report
from app.report.tables import SPREADS
from hardware_mocks.benches import get_bench
from tests.app.test_cli_uncertainty import with_uncertainty

DOC_SHOTS = Path(__file__).resolve().parents[3] / "docs" / "screenshots"


def _cell(table: QtWidgets.QTableWidget, row: int, col: int) -> str:
    item = table.item(row, col)
    assert item is not None
    return item.text()


def test_results_view_and_report_show_uncertainty(qtbot, make_window, choose_file,
                                                  tmp_path: Path) -> None:
    uff = tmp_path / "engine.uff"
    write_frf_uff(uff, get_bench("engine-rigid").frfset(noise=0.01, seed=2))
    window: MainWindow = make_window()
    choose_file(uff)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000) as blocker:
        window.open_action.trigger()
    a: Analysis = blocker.args[0]
    assert a.result is not None
    res = window.results_view
    assert a.result.uncertainty is not None  # the fit's covariance, on by default
    assert "±" in _cell(res.inertia, 0, 2) and res.uncertainty.isVisibleTo(res)
    a = replace(a, result=replace(a.result, uncertainty=None))
    window.session.analysis = a
    window.session.analysis_changed.emit(a)
    plain = _cell(res.inertia, 0, 2)
    assert "±" not in plain and not res.uncertainty.isVisibleTo(res)
    # the identification's result with an uncertainty, shown as the session shows any result
    r = with_uncertainty(a.result)
    u = r.uncertainty
    assert u is not None
    b = replace(a, result=r)
    window.session.analysis = b
    window.session.analysis_changed.emit(b)
    p = r.properties
    assert _cell(res.inertia, 0, 2) == f"{p.mass:.3f} ± {1.96 * u.std['mass']:.2g}"
    assert _cell(res.inertia, 3, 3) == (f"{p.cog[2] * 1e3:.2f} ± "
                                        f"{1.96 * u.std['cog'][2] * 1e3:.2g}")
    # J_xy = -J[0, 1]: the interval's ends change sign and swap
    lo, hi = -u.ci95["inertia_cog"][0, 1, 1], -u.ci95["inertia_cog"][0, 1, 0]
    assert _cell(res.inertia, 7, 2) == f"{-p.inertia_cog[0, 1]:.4f} [{lo:.4f}, {hi:.4f}]"
    assert lo < -p.inertia_cog[0, 1] < hi
    assert _cell(res.inertia, 7, 3) == (f"{-p.inertia_origin[0, 1]:.4f} ± "
                                        f"{1.96 * u.std['inertia_origin'][0, 1]:.2g}")
    assert _cell(res.principal, 2, 1) == (f"{p.principal_moments[2]:.4f} ± "
                                          f"{1.96 * u.std['principal_moments'][2]:.2g}")
    assert _cell(res.K, 2, 3) == f"{r.K[2, 2]:.4g} ± {1.96 * u.std['stiffness'][2, 2]:.2g}"
    assert _cell(res.C, 0, 1) == f"{r.C[0, 0]:.4g} ± {1.96 * u.std['damping'][0, 0]:.2g}"
    f, sf = r.rigid_modes_hz, u.std["rigid_modes_hz"]
    assert f"{f[0]:.2f} ± {1.96 * sf[0]:.2g}" in res.summary.text()
    assert res.uncertainty.isVisibleTo(res)
    assert res.uncertainty.text().splitlines()[0] == SPREADS  # the convention, once
    assert res.uncertainty.text().splitlines()[2:] == [
        "Largest contributions to the variance:", "CoG z: 70 % from point 3 location",
        "J_xy about the CoG: 55 % from fit (noise)", "mass: 40 % from gain of channel 4"]
    window.tabs.setCurrentWidget(res)
    QtWidgets.QApplication.processEvents()
    folder = DOC_SHOTS if os.environ.get("INSITU_SCREENSHOTS") == "1" else tmp_path / "shots"
    folder.mkdir(parents=True, exist_ok=True)
    assert window.grab().save(str(folder / "results_uncertainty.png"))

    # the HTML report: the same cells and the contributions
    page = build_report(b)
    assert f"<td>{p.mass:.3f} ± {1.96 * u.std['mass']:.2g}</td>" in page
    assert f"<td>{-p.inertia_cog[0, 1]:.4f} [{lo:.4f}, {hi:.4f}]</td>" in page
    assert f"<td>{r.K[2, 2]:.4g} ± {1.96 * u.std['stiffness'][2, 2]:.2g}</td>" in page
    assert "<li>CoG z: 70 % from point 3 location</li>" in page
    assert "fit covariance (FRF noise); Monte Carlo of point locations ± 2 mm" in page
    # and without an uncertainty, no spread anywhere in the tables
    assert "±" not in build_report(a) and "contributions" not in build_report(a)
