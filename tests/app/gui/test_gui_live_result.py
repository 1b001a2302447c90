"""The live run's result in the GUI: shown as soon as the points are done (before the
bootstrap over hits ends), then its final form, both the procedure's own fit: the session
does not fit the run again."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import pytest

from app.acquire.analysis import anti_aliased
from app.acquire.events import RunState
from app.gui.main_window import MainWindow
from processing.identify import IdentifyOptions, fit

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "benchmarks"))
from bootstrap import hammer_frfs, scenario


def test_preliminary_then_final_result_without_fitting_again(
        qtbot, make_window: Callable[..., MainWindow], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    m = anti_aliased(hammer_frfs(scenario(), seed=11, hits=3))  # as the procedure fits it
    early: list[object] = []
    final = fit(m, IdentifyOptions(bootstrap=10), preliminary=early.append)
    (first,) = early
    window = make_window()
    acq = window.acquisition_view
    # the procedure as the view sees it when its worker reports the result
    acq.procedure = SimpleNamespace(measurement=None, path=tmp_path / "run.h5", message="",
                                    running=False)  # type: ignore[assignment]
    acq.word, acq.hits = "hit", [object()] * 18  # type: ignore[list-item]

    def no_fit(*_a: object, **_k: object) -> None:
        raise AssertionError("the session fitted the run again")

    monkeypatch.setattr("app.report.analysis.fit", no_fit)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=60_000) as got:
        acq.bridge.on_result(m, first, False)  # from the worker thread, as the procedure calls
    assert got.args[0].result is first and got.args[0].error is None
    assert "bootstrap is running" in window.messages.text
    assert window.session.path == tmp_path / "run.h5"
    with qtbot.waitSignal(window.session.analysis_changed, timeout=60_000) as got:
        acq.bridge.on_result(m, final, True)
    assert got.args[0].result is final
    shown = window.session.measurement
    acq.procedure.measurement = m  # the run done: its FRFs on the disk
    acq.bridge.on_finished(RunState.FINISHED)
    qtbot.waitUntil(lambda: acq.next_label.text().startswith("Finished"), timeout=60_000)
    assert window.session.measurement is shown  # not handed over (and fitted) again
    assert window.session.analysis is not None and window.session.analysis.result is final


def test_options_changed_meanwhile_are_kept(qtbot, make_window: Callable[..., MainWindow],
                                            tmp_path: Path) -> None:
    """The operator changed the method while the bootstrap ran: the final result (the
    default options') does not replace the analysis with their options."""
    m = anti_aliased(hammer_frfs(scenario(), seed=12, hits=3))
    early: list[object] = []
    final = fit(m, IdentifyOptions(bootstrap=10), preliminary=early.append)
    window = make_window()
    acq = window.acquisition_view
    acq.procedure = SimpleNamespace(measurement=None, path=tmp_path / "run.h5", message="",
                                    running=False)  # type: ignore[assignment]
    with qtbot.waitSignal(window.session.analysis_changed, timeout=60_000):
        acq.bridge.on_result(m, early[0], False)
    with qtbot.waitSignal(window.session.analysis_changed, timeout=120_000) as got:
        window.session.set_options(IdentifyOptions(method="plain", bootstrap=0))
    assert got.args[0].options.method == "plain"
    assert not window.session.set_result(final)  # refused: nothing submitted
    busy: list[bool] = []
    window.runner.busy.connect(busy.append)
    acq._result(m, final, True)  # the slot the bridge's signal calls
    assert busy == []
    assert window.session.analysis is not None
    assert window.session.analysis.options.method == "plain"
    assert window.session.analysis.result is not final
