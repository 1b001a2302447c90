"""The run file's optional ``/mounts`` group: written, read back, used by ``insitu identify``."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from app.acquire.analysis import margin_samples
from app.cli.main import main
from app.io.mounts import mounts_from_dict
from app.io.runfile import RunFileError, RunWriter, read_run, write_mounts
from app.mockbench.bench import plan_for_bench
from drivers.base import ChannelConfig
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import half_sine, impulse_response, simulate

FS = 256.0
#: well-conditioned subset of the engine's 18 excitations
POINTS = [0, 1, 3, 4, 6, 8, 9, 12, 15]


def _mounts() -> dict:
    model = get_bench("engine-rigid").model
    return {"crank_axis": [1.0, 0.0, 0.0],
            "mount": [{"name": f"mount {i + 1}", "position": m.position.tolist(),
                       "axes": m.axes.T.tolist()} for i, m in enumerate(model.mounts)]}


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished hammer run on the engine, one clean hit per point (simulated records)."""
    b = get_bench("engine-rigid")
    g = b.geometry
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    n = plan.record.n_samples + 2 * margin_samples(FS)
    t0 = (margin_samples(FS) + plan.record.n_pretrigger + 2) / FS
    chans = [ChannelConfig("F", 0, "force", 2.25)] + [
        ChannelConfig(f"a{i}", i + 1, "acceleration", 10.2, node=int(nd),
                      direction=(float(d[0]), float(d[1]), float(d[2])))
        for i, (nd, d) in enumerate(zip(b.resp_nodes, b.resp_dirs, strict=True))]
    path = tmp_path_factory.mktemp("run") / "run.h5"
    w = RunWriter.create(path, plan_data=plan.to_dict(), station_data={}, channels=chans,
                         devices=["fe"] * len(chans), geometry=plan.geometry(), fs=FS,
                         n_samples=n, method="hammer")
    f = half_sine(n, FS, t0, 0.02, 200.0)
    for i, k in enumerate(POINTS):
        ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                              g.coordinates(b.exc_nodes[k:k + 1]), b.exc_dirs[k:k + 1])
        w.add_record(i, np.vstack([f[None], simulate(ir, f[None])]), time=float(i),
                     peak_force=200.0, auto_accepted=True, reason="")
    w.finish("finished")
    return path


def test_mounts_round_trip(run_file: Path) -> None:
    assert read_run(run_file, with_data=False).mounts is None
    m = mounts_from_dict(_mounts())
    write_mounts(run_file, m)
    back = read_run(run_file, with_data=False).mounts
    assert back is not None and back.crank_axis == m.crank_axis
    assert [x.name for x in back.mounts] == ["mount 1", "mount 2", "mount 3"]
    for a, b in zip(back.mounts, m.mounts, strict=True):
        np.testing.assert_array_equal(a.position, b.position)
        np.testing.assert_array_equal(a.axes, b.axes)
    with h5py.File(run_file, "r") as f:
        assert f["mounts/position"].attrs["units"] == "m"
    write_mounts(run_file, None)
    assert read_run(run_file, with_data=False).mounts is None


def test_identify_uses_the_run_files_mounts(run_file: Path, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    write_mounts(run_file, mounts_from_dict(_mounts()))
    out = tmp_path / "r.json"
    try:
        assert main(["identify", str(run_file), "--out", str(out)]) == 0
    finally:
        write_mounts(run_file, None)
    assert "using the run file's mounts table (3 mounts)" in capsys.readouterr().out
    res = json.loads(out.read_text())
    model = get_bench("engine-rigid").model
    assert [m["name"] for m in res["mounts"]] == ["mount 1", "mount 2", "mount 3"]
    # 4 s records of a 256 Hz front end: the rates within 5 % of the bench's
    np.testing.assert_allclose([m["rates"] for m in res["mounts"]],
                               [m.stiffness for m in model.mounts], rtol=0.05)
    assert "torque_roll_axis" in res and len(res["modes"]) == 6


def test_damaged_mounts_group_is_one_line(run_file: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.h5"
    bad.write_bytes(run_file.read_bytes())
    write_mounts(bad, mounts_from_dict(_mounts()))
    with h5py.File(bad, "a") as f:
        f["mounts/axes"][0] = np.ones((3, 3))
    with pytest.raises(RunFileError, match="orthonormal"):
        read_run(bad, with_data=False)
    with pytest.raises(RunFileError, match="no such run file"):
        write_mounts(tmp_path / "none.h5", None)
