"""One measurement, one fit: every view gives the same numbers from the same data.

A hammer run and a shaker run are acquired on the mock bench; the acquisition's stored
result, ``insitu replay``, ``insitu identify run.h5``, the GUI after the live run, the GUI
opening the run file, ``insitu report`` (its analysis) and an ``insitu batch`` row must
agree to the bit.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from app.acquire import HammerProcedure, RunState, ShakerProcedure
from app.acquire.analysis import anti_aliased
from app.batch.campaign import COLUMNS, identify_file, result_row
from app.cli.main import main
from app.io.runfile import read_run
from app.mockbench.bench import InProcessBench, plan_for_bench
from app.pipeline import Settings
from app.report.analysis import analyse
from app.report.sources import open_source
from processing.identify import IdentifyOptions

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

#: six forces (x, y, y, x, z, z) that span the rigid-body motions: the least that identifies
POINTS = [0, 1, 4, 8, 12, 15]


def _json(result: Any) -> dict[str, Any]:
    """A result as its JSON reads back (what a file holds)."""
    return dict(json.loads(json.dumps(result.to_json())))


def _gui_session(qtbot: Any, measurement: Any = None, path: Path | None = None) -> Any:
    """The GUI's analysis of a measurement handed over after a live run, or of a file it
    opens: the window's :class:`~app.gui.session.Session`, its worker thread and signals."""
    from app.gui.session import Session
    from app.gui.worker import TaskRunner

    runner = TaskRunner()
    session = Session(runner)
    try:
        with qtbot.waitSignal(session.analysis_changed, timeout=120_000) as blocker:
            if path is not None:
                session.open_file(path)
            else:
                session.set_measurement(measurement, "acquisition")
        return blocker.args[0].result
    finally:
        runner.shutdown()


def _every_view(path: Path, tmp_path: Path, proc: Any, qtbot: Any) -> dict[str, dict[str, Any]]:
    """The result of the run file ``path`` as each view gives it."""
    views: dict[str, dict[str, Any]] = {}
    assert proc.result is not None
    views["live"] = _json(proc.result)
    stored = read_run(path).result
    assert stored is not None
    views["stored"] = stored
    assert main(["replay", str(path), "--out", str(tmp_path / "replay.json")]) == 0
    views["replay"] = json.loads((tmp_path / "replay.json").read_text())
    assert main(["identify", str(path), "--out", str(tmp_path / "identify.json")]) == 0
    ident = json.loads((tmp_path / "identify.json").read_text())
    views["identify"] = {k: ident[k] for k in views["live"]}  # + the mount system's keys
    views["gui after the run"] = _json(_gui_session(qtbot, anti_aliased(proc.measurement)))
    views["gui opening the file"] = _json(_gui_session(qtbot, path=path))
    m, _ = open_source(path)  # as insitu report does
    report = analyse(m, IdentifyOptions(), path.name).result
    views["report"] = _json(report)
    row = identify_file(str(path), Settings(), IdentifyOptions())
    assert row["status"] == "ok", row["error"]
    mine = result_row(report)
    assert {name: row[name] for name, *_ in COLUMNS} == {name: mine[name] for name, *_ in COLUMNS}
    return views


def _assert_same(views: dict[str, dict[str, Any]]) -> None:
    first = views["live"]
    for name, got in views.items():
        differ = sorted(k for k in first if got.get(k) != first[k])
        assert not differ, f"{name} differs from the live run's result in {differ}"


@pytest.mark.slow
def test_hammer_run_same_result_in_every_view(tmp_path: Path, qtbot: Any) -> None:
    path = tmp_path / "hammer.h5"
    plan = plan_for_bench("engine-rigid", points=POINTS, hits=2, length=1.0)
    with InProcessBench("engine-rigid") as bench:
        proc = HammerProcedure(plan, bench.station, path, listeners=[bench.operator])
        proc.start()
        assert proc.wait(120) is RunState.FINISHED, proc.message
    assert proc.measurement is not None and proc.measurement.provenance.units is not None
    _assert_same(_every_view(path, tmp_path, proc, qtbot))


@pytest.mark.slow
def test_shaker_run_same_result_in_every_view(tmp_path: Path, qtbot: Any) -> None:
    path = tmp_path / "shaker.h5"
    fs = 512.0
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=fs, method="shaker", shaker={
        "waveform": "chirp", "level": 0.5, "f_start": 2.0, "f_stop": fs / 2.56, "averages": 2,
        "nperseg": 512, "ramp": 0.1, "settle": 1.0})
    with InProcessBench("engine-rigid", fs_frontend=fs) as bench:
        proc = ShakerProcedure(plan, bench.station, path, listeners=[bench.shaker_operator])
        proc.start()
        assert proc.wait(120) is RunState.FINISHED, proc.message
    assert proc.measurement is not None
    _assert_same(_every_view(path, tmp_path, proc, qtbot))


def test_time_uff_same_result_in_identify_gui_report_and_batch(tmp_path: Path,
                                                                qtbot: Any) -> None:
    from benchmarks.timedata import case
    from hardware_mocks.reference.timedata import write_uff

    path = tmp_path / "hits.uff"
    write_uff(case(9001, "hammer"), path)  # a seed of the tests' own, in no published suite
    assert main(["identify", str(path), "--out", str(tmp_path / "identify.json")]) in (0, 2)
    ident = json.loads((tmp_path / "identify.json").read_text())
    m, _ = open_source(path)  # as insitu report does
    report = _json(analyse(m, IdentifyOptions(), path.name).result)
    views = {"report": report, "identify": {k: ident[k] for k in report},
             "gui opening the file": _json(_gui_session(qtbot, path=path))}
    assert m.provenance.units is not None  # the bootstrap's hits, in every view alike
    row = identify_file(str(path), Settings(), IdentifyOptions())
    assert row["status"] == "ok", row["error"]
    assert row["mass_kg"] == report["mass"]
    first = views["report"]
    for name, got in views.items():
        differ = sorted(k for k in first if got.get(k) != first[k])
        assert not differ, f"{name} differs from the report's result in {differ}"
