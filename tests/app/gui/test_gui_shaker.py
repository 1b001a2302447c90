"""A shaker run from the Acquisition view on the mock bench: blocks with verdicts, averages,
live traces and FRF per block; and the shaker's output off at once on Stop, on a device
error and when the window closes, with the blocks acquired so far in the run file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from app.acquire.events import RunState
from app.gui.main_window import MainWindow
from app.io.runfile import read_run
from app.mockbench.bench import plan_for_bench
from hardware_mocks.shaker_device import ShakerDevice
from tests.app.gui.test_gui_acquisition import _screenshot

#: periodic chirp, 0.25 s blocks, 2 averages per point: about 1 s a point
SHORT = {"waveform": "chirp", "level": 0.5, "f_start": 4.0, "f_stop": 400.0, "averages": 2,
         "nperseg": 256, "ramp": 0.1, "settle": 0.2}


#: two shakers need random signals (burst random, bursts started together); four 0.5 s blocks
#: (more blocks than forces)
PAIR = {"shakers": 2, "waveform": "burst-random", "duty": 0.5, "nperseg": 512, "averages": 4}


def _shaker_window(make_window: Callable[..., MainWindow], points: list[int],
                   averages: int = 2) -> tuple[MainWindow, ShakerDevice]:
    window = make_window()
    station = window.station_view
    station.method_combo.setCurrentText("shaker")
    station.mock_button.click()
    assert station.mock is not None and window.plan_view.plan is not None
    assert window.plan_view.plan.method == "shaker"  # the built-in shaker plan
    # a shorter plan than the built-in one (18 points), given as the mock bench gives its own
    window.plan_view.set_plan(plan_for_bench("engine-rigid", points=points, method="shaker",
                                             shaker={**SHORT, "averages": averages}))
    return window, station.mock.shaker


def _output_went_off_by_command(dev: ShakerDevice, watchdog: bool = False) -> bool:
    """The host turned the output off (OUTP OFF after the last OUTP ON), the output is off,
    and the device did not have to turn it off by itself because the host went away (nor
    because its watchdog expired, unless ``watchdog``)."""
    cmds = dev.commands
    on = max(i for i, c in enumerate(cmds) if c == "OUTP ON")
    by_itself = {102} if watchdog else {101, 102}
    return not dev.output and "OUTP OFF" in cmds[on:] and not by_itself & set(dev.errors)


def _cells(window: MainWindow, row: int) -> list[str]:
    t = window.acquisition_view.hits_table
    return [t.item(row, j).text() if t.item(row, j) else "" for j in range(t.columnCount())]


def test_shaker_run_shows_blocks_averages_and_live_traces(
        qtbot, make_window: Callable[..., MainWindow], tmp_path: Path) -> None:
    window, dev = _shaker_window(make_window, [0, 4])
    acq = window.acquisition_view
    run = tmp_path / "shaker.h5"
    acq.run_path.setText(str(run))
    acq.start_button.click()
    assert window.messages.level == "warning" and "Partial run" in window.messages.text
    assert acq.hits_table.horizontalHeaderItem(0).text() == "block"
    assert acq.accept_button.text() == "Accept selected block"
    qtbot.waitUntil(lambda: acq.next_label.text().startswith("Shaker at point 1 of 2"),
                    timeout=120000)
    qtbot.waitUntil(lambda: acq.hits_table.rowCount() >= 1, timeout=120000)
    # the output was turned on and the stinger attached for the first point (their history:
    # on a loaded machine the run may be past that point by the time the row is shown)
    assert "OUTP ON" in dev.commands and len(dev.attached_at) >= 1
    # the block's row, its FRF and the progress are three signals from the worker, which
    # computes the point's FRF between them: wait for the later two as well
    qtbot.waitUntil(lambda: "1 of 2 blocks averaged" in acq.progress_label.text(),
                    timeout=120000)
    qtbot.waitUntil(
        lambda: "(1 block averaged)" in acq.plots.frf_plot.getPlotItem().titleLabel.text,
        timeout=120000)
    qtbot.waitUntil(lambda: acq.state is not RunState.RUNNING, timeout=120000)
    assert acq.state is RunState.FINISHED, (acq.next_label.text(), window.messages.text)
    assert _output_went_off_by_command(dev)
    assert acq.hits_table.rowCount() == 4
    assert [_cells(window, i)[1] for i in range(4)] == ["1", "1", "2", "2"]
    assert all(_cells(window, i)[4:] == ["yes", "-", "accepted"] for i in range(4))
    assert "2 of 2 blocks averaged" in acq.progress_label.text()
    assert acq.progress_bar.value() == 2
    assert "(2 blocks averaged)" in acq.plots.frf_plot.getPlotItem().titleLabel.text
    assert "point 2" in acq.plots.frf_plot.getPlotItem().titleLabel.text
    # the live traces got every streamed sample (ramps and settling too), scrolling at
    # the redraw rate between the procedure's ten reads a second
    live = acq.plots.live
    assert live.names[0] == "F_fe" and live.shown == live.received
    assert live.received >= 4 * 256 + 2 * (0.1 + 0.2) * 1024
    assert live.frames_new > live.received / 102  # more new frames than reads
    force = live._curves[0].getData()[1]
    assert np.nanmax(np.abs(force)) > 1.0  # the shaker's force, in N
    # selecting a block shows its force record
    acq.hits_table.selectRow(1)
    assert "block 2 (point 1): accepted" in acq.plots.record_plot.getPlotItem().titleLabel.text
    stored = read_run(run, with_data=False)
    assert stored.method == "shaker" and stored.state == "finished"
    assert len(stored.records) == 4 and stored.records.accepted.all()


def test_shaker_output_off_on_stop_device_error_and_close(
        qtbot, make_window: Callable[..., MainWindow], tmp_path: Path) -> None:
    window, dev = _shaker_window(make_window, [0, 4, 8], averages=50)
    acq = window.acquisition_view
    bench = window.station_view.mock
    assert bench is not None

    def start(name: str) -> Path:
        path = tmp_path / name
        acq.run_path.setText(str(path))
        assert acq.start() is True
        qtbot.waitUntil(lambda: acq.hits_table.rowCount() >= 2 and dev.output, timeout=120000)
        return path

    # 1. Stop: the output is off as soon as the run has ended (the point's 50 blocks not
    # awaited); the blocks are saved
    path = start("stopped.h5")
    with qtbot.waitSignal(acq.bridge.finished, timeout=120000):
        acq.stop_button.click()
    assert _output_went_off_by_command(dev)
    assert acq.state is RunState.STOPPED and "saved in" in window.messages.text
    stored = read_run(path, with_data=False)
    assert stored.state == "stopped" and len(stored.records) == acq.hits_table.rowCount() >= 2
    assert len(stored.records) < 50  # stopped within the first point's averages

    # 2. the front end stops answering: the procedure turns the shaker off and pauses; the
    # message bar says why in one red line
    path = start("fault.h5")
    bench.frontend.faults.silent = True
    qtbot.waitUntil(lambda: acq.state is RunState.PAUSED, timeout=120000)
    # "OUTP OFF" was written before the pause was reported; the device reads it when its
    # thread next runs (the read stalls for the mock bench's stall timeout, longer than the
    # shaker's watchdog: the device may turn itself off first)
    qtbot.waitUntil(lambda: _output_went_off_by_command(dev, watchdog=True), timeout=120000)
    assert window.messages.level == "error" and "device problem" in window.messages.text
    assert "\n" not in window.messages.text
    assert acq.resume_button.isEnabled() and acq.stop_button.isEnabled()
    bench.frontend.faults.silent = False
    with qtbot.waitSignal(acq.bridge.finished, timeout=120000):
        acq.stop_button.click()
    stored = read_run(path, with_data=False)
    assert stored.state == "stopped" and len(stored.records) == acq.hits_table.rowCount() >= 2

    # 3. the window closes during the run: output off before the port closes
    path = start("closed.h5")
    window.close()
    assert _output_went_off_by_command(dev)
    stored = read_run(path, with_data=False)
    assert stored.state == "stopped" and len(stored.records) >= 2


@pytest.mark.slow
def test_two_shaker_plan_runs_on_the_mock_bench_counting_drives(
        qtbot, make_window: Callable[..., MainWindow], tmp_path: Path) -> None:
    """A plan that drives two shakers at once: the simulated bench gets its second shaker
    at Start, the progress counts drives (pairs of points), not points, and both forces are
    on the force plot, not among the accelerations. Six points (the least that identifies):
    three drives."""
    points = [0, 1, 4, 8, 12, 15]
    window, _ = _shaker_window(make_window, points)
    window.plan_view.set_plan(plan_for_bench("engine-rigid", points=points, method="shaker",
                                             shaker={**SHORT, **PAIR}))
    acq = window.acquisition_view
    run = tmp_path / "pair.h5"
    acq.run_path.setText(str(run))
    acq.start_button.click()
    bench = window.station_view.mock
    assert bench is not None and len(bench.shakers) == 2
    assert acq.progress_bar.maximum() == 3 and acq.progress_bar.format() == "%v of %m drives"
    assert acq.hits_table.horizontalHeaderItem(1).text() == "drive"
    qtbot.waitUntil(lambda: acq.state is not RunState.RUNNING, timeout=120000)
    assert acq.state is RunState.FINISHED, (acq.next_label.text(), window.messages.text)
    assert acq.progress_bar.value() == 3
    assert acq.progress_label.text().startswith("drive 3: 4 of 4 blocks averaged")
    live = acq.plots.live
    assert live.names[:2] == ("F1_fe", "F2_fe") and live._n_force_curves == 2
    frf_title = acq.plots.frf_plot.getPlotItem().titleLabel.text
    assert "FRF, drive 3, point 5 (4 blocks averaged)" in frf_title
    frf_names = [item.text for _, item in acq.plots.frf_plot.getPlotItem().legend.items]
    assert frf_names[0] == "a1x" and "F2_fe" not in frf_names
    _screenshot(window, acq, "acquisition_two_shakers", tmp_path)
    stored = read_run(run, with_data=False)
    assert stored.state == "finished" and len(stored.records) == 12
    assert [c.name for c in stored.channels[:2]] == ["F1_fe", "F2_fe"]
