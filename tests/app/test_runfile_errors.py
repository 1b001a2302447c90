"""Bad plan files and bad run files: one line on stderr, exit status 2."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from app.acquire import PlanError, load_plan
from app.cli.main import main
from app.io.runfile import RunFileError, RunWriter, read_run
from app.mockbench.bench import plan_for_bench
from drivers.base import ChannelConfig
from processing.data import Geometry

GOOD = """
[plan]
method = "hammer"
hits = 2
[record]
fs = 1024
length = 1.0
trigger_level = 10.0
[[excitation]]
node = 101
xyz = [0, 0, 0]
direction = [1, 0, 0]
[[response]]
node = 1
xyz = [0.1, 0, 0]
channels = ["a1x"]
"""


@pytest.mark.parametrize(("edit", "message"), [
    (("fs = 1024", "fs = -5"), "record.fs: must be > 0, got -5"),
    (('method = "hammer"', 'method = "laser"'), "plan.method: must be 'hammer' or 'shaker'"),
    (("direction = [1, 0, 0]", "direction = [0, 0, 0]"), "excitation[0].direction: must be a "
                                                         "non-zero direction"),
    (("hits = 2", "hits = 2\ncolour = 1"), "plan.colour: unknown key"),
    (("fs = 1024", "fs = [1"), "not valid TOML"),
])
def test_bad_plan_file_is_one_line_naming_the_key(tmp_path: Path, capsys, edit, message) -> None:
    path = tmp_path / "plan.toml"
    path.write_text(GOOD.replace(*edit))
    with pytest.raises(PlanError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_plan(path)
    assert main(["acquire", "--mock", "--plan", str(path), "--out", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err
    assert not (tmp_path / "r.h5").exists()


def test_good_plan_round_trips(tmp_path: Path) -> None:
    path = tmp_path / "plan.toml"
    path.write_text(GOOD)
    plan = load_plan(path)
    assert plan.record.n_samples == 1024 and plan.hits == 2
    assert plan.geometry().node_ids.tolist() == [1, 101]
    built = plan_for_bench("engine")
    assert len(built.excitations) == 18 and len(built.responses) == 4


def _writer(path: Path) -> RunWriter:
    chans = [ChannelConfig("F", 0, "force", 2.25), ChannelConfig("a", 1, "acceleration", 10.2,
                                                                 node=1, direction=(1, 0, 0))]
    return RunWriter.create(path, plan_data={"x": 1}, station_data={}, channels=chans,
                            devices=["fe", "fe"], geometry=Geometry(np.array([1]),
                                                                    np.zeros((1, 3))),
                            fs=1024.0, n_samples=16, method="hammer")


def test_run_file_round_trip_and_units(tmp_path: Path) -> None:
    w = _writer(tmp_path / "r.h5")
    data = np.arange(32.0).reshape(2, 16)
    w.add_record(0, data, time=1.5, peak_force=20.0, auto_accepted=False, reason="double hit")
    w.set_override(0, "accept")
    w.add_note("hammer tip changed", 2.0)
    w.finish("stopped", "stopped by the operator")
    run = read_run(tmp_path / "r.h5")
    assert run.state == "stopped" and run.records.override == ("accept",)
    assert run.records.accepted.tolist() == [True] and run.records.reason == ("double hit",)
    assert np.array_equal(run.records.data[0], data) and run.notes == ((2.0, "hammer tip changed"),)
    with h5py.File(tmp_path / "r.h5") as f:
        missing = []
        f.visititems(lambda n, o: missing.append(n) if isinstance(o, h5py.Dataset)
                     and "units" not in o.attrs else None)
        assert missing == []
        assert f.attrs["schema_version"] == 1


@pytest.mark.parametrize("kind", ["foreign", "truncated", "version", "text", "missing"])
def test_bad_run_file_is_one_line(tmp_path: Path, capsys, kind: str) -> None:
    path = tmp_path / "r.h5"
    if kind == "foreign":
        with h5py.File(path, "w") as f:
            f["x"] = 1
    elif kind in ("truncated", "version"):
        w = _writer(path)
        w.add_record(0, np.zeros((2, 16)), time=0.0, peak_force=1.0, auto_accepted=True,
                     reason="")
        w.finish("finished")
        if kind == "truncated":
            raw = path.read_bytes()
            path.write_bytes(raw[: len(raw) // 3])
        else:
            with h5py.File(path, "a") as f:
                f.attrs["schema_version"] = 99
    elif kind == "text":
        path.write_text("not hdf5")
    with pytest.raises(RunFileError):
        read_run(path)
    assert main(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and str(path) in err
