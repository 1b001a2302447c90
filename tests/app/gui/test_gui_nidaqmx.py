"""The GUI on a station file that simulates its NI-DAQmx (docs/ni_station.toml): the run
gets the simulated NI-DAQmx injected and the simulated operator hits."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from app.acquire.events import RunState
from app.gui.main_window import MainWindow
from app.io.runfile import read_run

DOCS = Path(__file__).resolve().parents[3] / "docs"


def test_simulated_ni_station_runs_from_the_gui(qtbot, make_window: Callable[..., MainWindow],
                                                tmp_path: Path) -> None:
    plan = tmp_path / "plan.toml"
    text = (DOCS / "mock_bench_plan.toml").read_text()
    head, *points = text.split("[[excitation]]")
    # two points, one hit each: a partial run (FRFs only)
    plan.write_text(head.replace("\nhits = 3\n", "\nhits = 1\n") + "[[excitation]]"
                    + "[[excitation]]".join(points[:2]) + "[[response]]"
                    + points[-1].split("[[response]]", 1)[1])
    window = make_window(DOCS / "ni_station.toml")
    assert window.plan_view.load_plan_file(plan)
    acq = window.acquisition_view
    run = tmp_path / "run.h5"
    acq.run_path.setText(str(run))
    assert acq.start() is True
    qtbot.waitUntil(lambda: acq.state is not RunState.RUNNING, timeout=120000)
    assert acq.state is RunState.FINISHED, (acq.next_label.text(), window.messages.text)
    assert acq._simulated is None  # closed with the run
    data = read_run(run, with_data=False)
    assert len(data.records) == 2 and data.records.accepted.all()
    assert data.station_data["devices"]["frontend"]["backend"] == "frontend-nidaqmx"
