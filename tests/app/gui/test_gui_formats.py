"""The GUI opens every format the command line reads: an FRF file (.h5) and a UFF file of
time records go through File > Open, the pipeline and the same views."""

from __future__ import annotations

from pathlib import Path

import pytest
from PySide6 import QtWidgets

from app.gui.main_window import MainWindow
from app.io.frf_h5 import write_frf_h5
from app.io.uff_time import TimeRun, write_time_uff
from app.pipeline import FRF_H5, TIME_UFF
from app.report.analysis import Analysis
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import ImpulseResponse, impulse_response, simulate
from processing.excitation import continuous_random

FS = 256.0


def _open(qtbot, window: MainWindow, monkeypatch: pytest.MonkeyPatch,
          path: Path) -> tuple[Analysis, str]:
    """File > Open answering ``path``; returns the analysis and the dialog's filter."""
    filters: list[str] = []

    def answer(*args: object, **_: object) -> tuple[str, str]:
        filters.append(str(args[3]))
        return str(path), ""

    monkeypatch.setattr(QtWidgets.QFileDialog, "getOpenFileName", staticmethod(answer))
    with qtbot.waitSignal(window.session.analysis_changed, timeout=300000) as blocker:
        window.open_action.trigger()
    a = blocker.args[0]
    assert isinstance(a, Analysis)
    return a, filters[0]


def test_gui_opens_an_frf_file_and_time_records(qtbot, make_window, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    b = get_bench("engine-rigid")
    window: MainWindow = make_window()
    # what the message bar was told (an info line hides after 6 s: the identification that
    # follows the opening may take longer on a loaded machine)
    told: list[tuple[str, str]] = []
    window.session.message.connect(lambda level, text: told.append((level, text)))
    h5 = tmp_path / "bench.h5"
    write_frf_h5(h5, b.frfset())
    a, dialog_filter = _open(qtbot, window, monkeypatch, h5)
    for suffix in ("*.uff", "*.unv", "*.h5", "*.hdf5"):
        assert suffix in dialog_filter.split(";;")[0]
    assert window.session.format == FRF_H5
    assert a.result is not None
    assert a.result.properties.mass == pytest.approx(b.model.mass, rel=1e-4)
    assert told[-1][1].startswith("opened bench.h5 (FRF file"), told
    assert not window.export_view.run_button.isEnabled()  # an FRF file is not a run

    g = b.geometry
    ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                          g.coordinates(b.exc_nodes), b.exc_dirs)
    runs = []
    for k in range(b.exc_nodes.size):
        f = continuous_random(12 * 1024, FS, rms=10.0, seed=k)
        x = simulate(ImpulseResponse(ir.h[:, k:k + 1], FS), f)
        runs.append(TimeRun(k + 1, FS, f[0], int(b.exc_nodes[k]), b.exc_dirs[k], x,
                            b.resp_nodes, b.resp_dirs))
    src = tmp_path / "time.uff"
    write_time_uff(src, runs, g, binary=True)
    a, _ = _open(qtbot, window, monkeypatch, src)
    assert window.session.format == TIME_UFF
    # nperseg 2048 (the default): lines every 0.125 Hz, up to fs / 2.56 = 100 Hz, the 0 Hz
    # line cut (its median coherence is under the gate: random excitation has no DC)
    assert a.frf.H.shape == (b.resp_nodes.size, b.exc_nodes.size, 799)
    assert a.frf.freq[0] > 0
    assert a.frf.freq[-1] <= FS / 2.56 and a.gate is not None
    assert a.result is not None  # the same accuracy as insitu identify on this file
    assert abs(a.result.properties.mass - b.model.mass) / b.model.mass < 2e-4
