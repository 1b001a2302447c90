"""TDMS and MDF files of time records, read through a channel map: the same FRFs as the time
UFF of the same records, bit for bit; a run's records exported and read back whole; every
bad file or map refused in one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from app.cli.main import main
from app.io.channel_map import map_text
from app.io.mdf import write_time_mdf
from app.io.runfile import RunWriter, read_run
from app.io.tdms import write_time_tdms
from app.io.time_channels import MappedTimeFile
from app.io.uff_time import TimeRun, write_time_uff
from app.mockbench.bench import plan_for_bench
from app.pipeline import TIME_MDF, TIME_TDMS, Settings, detect_format, load
from drivers.base import ChannelConfig
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import ImpulseResponse, half_sine, impulse_response, simulate
from processing.excitation import continuous_random
from tests.app.cli_lines import one_error_line

FS = 256.0
POINTS = [0, 7, 9]
NAMES = ["Force", *(f"acc {i}" for i in range(12))]


def _runs(kind: str, points: list[int] = POINTS) -> list[TimeRun]:
    """Hammer runs (three hits each) or continuous random runs at bench excitations
    ``points``."""
    b = get_bench("engine-rigid")
    g = b.geometry
    ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                          g.coordinates(b.exc_nodes), b.exc_dirs)
    runs = []
    for lc, k in enumerate(points, start=1):
        if kind == "hammer":
            n = int(8 * FS)
            f = sum(half_sine(n, FS, 0.5 + 2.5 * j, 0.01, 200.0) for j in range(3))
        else:
            f = continuous_random(8 * 1024, FS, rms=10.0, seed=k)[0]
        x = simulate(ImpulseResponse(ir.h[:, k:k + 1], FS), np.asarray(f)[None])
        runs.append(TimeRun(lc, FS, f, int(b.exc_nodes[k]), b.exc_dirs[k], x, b.resp_nodes,
                            b.resp_dirs))
    return runs


def _groups(runs: list[TimeRun]) -> list[str]:
    return [f"run {r.load_case}" for r in runs]


def _map(runs: list[TimeRun]) -> str:
    b = get_bench("engine-rigid")
    return map_text("test", NAMES[0], [(n, int(nd), d) for n, nd, d in
                                       zip(NAMES[1:], b.resp_nodes, b.resp_dirs, strict=True)],
                    [(r.exc_node, r.exc_dir, [g]) for r, g in zip(runs, _groups(runs),
                                                                  strict=True)],
                    b.geometry)


def _write_all(d: Path, runs: list[TimeRun]) -> dict[str, Path]:
    """The runs as a time UFF, a TDMS file and an MDF file, one channel map beside both."""
    paths = {"uff": d / "t.uff", "tdms": d / "t.tdms", "mf4": d / "t.mf4"}
    write_time_uff(paths["uff"], runs, get_bench("engine-rigid").geometry, binary=True)
    write_time_tdms(paths["tdms"], runs, _groups(runs), NAMES)
    write_time_mdf(paths["mf4"], runs, _groups(runs), NAMES)
    (d / "t.map.toml").write_text(_map(runs))
    return paths


def _same_frfs(a: object, b: object) -> None:
    for name in ("freq", "H", "coherence", "resp_nodes", "resp_dirs", "exc_nodes", "exc_dirs"):
        assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("kind", ["hammer", "shaker"])
def test_tdms_and_mdf_give_the_time_uffs_frfs_bit_for_bit(tmp_path: Path, kind: str) -> None:
    paths = _write_all(tmp_path, _runs(kind))
    assert detect_format(paths["tdms"]) == TIME_TDMS and detect_format(paths["mf4"]) == TIME_MDF
    ref = load(paths["uff"], Settings())
    for name in ("tdms", "mf4"):
        m = load(paths[name], Settings())  # the map beside the file
        _same_frfs(ref.frf, m.frf)
        assert m.provenance.excitation == ("impact" if kind == "hammer" else "random")
        assert [r.message for r in m.provenance.reports] == [
            r.message for r in ref.provenance.reports]


def test_identify_tdms_and_mf4_with_channels_equal_the_time_uff(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    paths = _write_all(tmp_path, _runs("hammer", list(range(18))))
    mapped = tmp_path / "map.toml"
    (tmp_path / "t.map.toml").rename(mapped)
    results = {}
    for name, p in paths.items():
        out = tmp_path / f"{name}.json"
        extra = [] if name == "uff" else ["--channels", str(mapped)]
        assert main(["identify", str(p), *extra, "--no-uncertainty", "--out", str(out)]) == 0
        results[name] = json.loads(out.read_text())
    assert "time records; computing FRFs" in capsys.readouterr().out
    assert results["tdms"] == results["uff"] and results["mf4"] == results["uff"]


def _run_file(path: Path) -> Path:
    """A small hammer run: two hits at each of three points, one rejected double hit."""
    from tests.app.test_cli_frf_runfile import _hit

    b = get_bench("engine-rigid")
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    chans = [ChannelConfig("F", 0, "force", 2.25)] + [
        ChannelConfig(f"a{i}", i + 1, "acceleration", 10.2, node=int(nd),
                      direction=(float(d[0]), float(d[1]), float(d[2])))
        for i, (nd, d) in enumerate(zip(b.resp_nodes, b.resp_dirs, strict=True))]
    w = RunWriter.create(path, plan_data=plan.to_dict(), station_data={}, channels=chans,
                         devices=["fe"] * len(chans), geometry=plan.geometry(), fs=FS,
                         n_samples=_hit(POINTS[0]).shape[1], method="hammer")
    t = 0.0
    for j, p in enumerate(POINTS):
        for _ in range(2):
            w.add_record(j, _hit(p), time=t, peak_force=200.0, auto_accepted=True, reason="")
            t += 1.0
        if j == 1:
            w.add_record(j, _hit(p, double=True), time=t, peak_force=200.0,
                         auto_accepted=False, reason="double hit")
    w.finish("stopped", "stopped by the operator")
    return path


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run_file(tmp_path_factory.mktemp("run") / "run.h5")


def test_export_round_trips_the_records(tmp_path: Path, run_file: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    outs = {"tdms": tmp_path / "e.tdms", "mf4": tmp_path / "e.mf4", "uff": tmp_path / "e.uff"}
    assert main(["export", str(run_file), "--tdms", str(outs["tdms"]), "--mf4",
                 str(outs["mf4"]), "--uff", str(outs["uff"])]) == 0
    text = capsys.readouterr().out
    assert "6 records written to" in text and "e.map.toml" in text
    run = read_run(run_file)
    used = np.flatnonzero(run.records.accepted)
    assert used.size == 6  # the double hit left out
    plan = plan_for_bench("engine-rigid", points=POINTS, fs=FS, length=4.0, pretrigger=0.25)
    from app.io.channel_map import read_channel_map
    from app.io.mdf import MdfRaw
    from app.io.tdms import TdmsRaw

    cmap = read_channel_map(tmp_path / "e.map.toml")
    for raw in (TdmsRaw(outs["tdms"]), MdfRaw(outs["mf4"])):
        f = MappedTimeFile(raw, cmap)
        assert f.load_cases == tuple(range(1, 7))
        for lc, i in zip(f.load_cases, used, strict=True):
            r = f.read_run(lc)
            data = run.records.data[i]
            assert r.fs == run.records.fs
            assert_array_equal(r.force, data[0])  # float64 kept, to the bit
            assert_array_equal(r.responses, data[1:])
            point = plan.excitations[int(run.records.point[i])]
            assert r.exc_node == point.node
            assert_array_equal(r.exc_dir, point.direction)
            assert_array_equal(r.resp_nodes, [c.node for c in run.channels[1:]])
            assert f.run_name(lc) == f"group 'record {i + 1}'"
        assert_array_equal(f.geometry().xyz, run.geometry.xyz)
    ref = load(outs["uff"], Settings())
    for name in ("tdms", "mf4"):
        _same_frfs(ref.frf, load(outs[name], Settings()).frf)


def test_export_all_keeps_the_rejected_records(tmp_path: Path, run_file: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "all.tdms"
    assert main(["export", str(run_file), "--tdms", str(out), "--all"]) == 0
    assert "7 records written" in capsys.readouterr().out
    from app.io.channel_map import read_channel_map
    from app.io.tdms import TdmsRaw

    f = MappedTimeFile(TdmsRaw(out), read_channel_map(tmp_path / "all.map.toml"))
    assert len(f.load_cases) == 7 and f.run_name(5) == "group 'record 5'"


def test_point_channel_layout_and_scaled_units(tmp_path: Path) -> None:
    """One group of a continuous recording split by a point channel, the force in mV and
    the accelerations in g: the FRFs of the time UFF (to rounding of the scaling)."""
    runs = _runs("shaker", [0, 7])
    ref = tmp_path / "t.uff"
    write_time_uff(ref, runs, get_bench("engine-rigid").geometry, binary=True)
    gap = np.zeros(100)
    force = np.concatenate([gap, runs[0].force, gap, runs[1].force]) * 2.25  # mV
    acc = np.hstack([np.zeros((12, 100)), runs[0].responses, np.zeros((12, 100)),
                     runs[1].responses]) / 9.80665  # g
    point = np.concatenate([gap, np.full(runs[0].n_samples, 1.0), gap,
                            np.full(runs[1].n_samples, 2.0)])
    whole = TimeRun(1, FS, force, 0, [0, 0, 1], np.vstack([acc, point]),
                    [*runs[0].resp_nodes, 999], np.vstack([runs[0].resp_dirs, [0, 0, 1]]))
    write_time_tdms(tmp_path / "c.tdms", [whole], ["recording"], [*NAMES, "Point"])
    b = get_bench("engine-rigid")
    lines = ['geometry = "t.uff"', "", "[layout]", 'runs = "point-channel"',
             'point_channel = "Point"', "",
             "[force]", 'channel = "Force"', 'unit = "mV"', 'sensitivity = "2.25 mV/N"', ""]
    for n, nd, d in zip(NAMES[1:], b.resp_nodes, b.resp_dirs, strict=True):
        axis = "xyz"[int(np.argmax(np.abs(d)))]
        sign = "+" if d.max() > 0 else "-"
        lines += ["[[response]]", f'channel = "{n}"', f"node = {nd}",
                  f'direction = "{sign}{axis}"', 'unit = "g"', ""]
    for k, r in enumerate(runs, start=1):
        lines += ["[[excitation]]", f"point = {k}", f"node = {r.exc_node}",
                  f"direction = {list(map(float, r.exc_dir))}", ""]
    (tmp_path / "c.toml").write_text("\n".join(lines) + "\n")
    m = load(tmp_path / "c.tdms", Settings(channel_map=tmp_path / "c.toml"))
    want = load(ref, Settings())
    np.testing.assert_allclose(m.frf.H, want.frf.H, rtol=0,
                               atol=1e-12 * np.max(np.abs(want.frf.H)))
    assert_array_equal(m.frf.exc_nodes, want.frf.exc_nodes)


# --- errors: one line, exit status 2 ----------------------------------------------------------


@pytest.fixture()
def small(tmp_path: Path) -> dict[str, Path]:
    return _write_all(tmp_path, _runs("shaker", [0, 7]))


def _refused(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(["frf", *argv]) == 2
    return one_error_line(capsys)


def test_a_missing_map_is_named(small: dict[str, Path],
                                capsys: pytest.CaptureFixture[str]) -> None:
    (small["tdms"].parent / "t.map.toml").unlink()
    line = _refused(capsys, str(small["tdms"]))
    assert "needs a channel map" in line and "--channels" in line and "t.map.toml" in line
    line = _refused(capsys, str(small["mf4"]), "--channels", str(small["mf4"].parent / "no.toml"))
    assert "channel map" in line and "not found" in line


def test_an_unknown_channel_in_the_map_is_named(small: dict[str, Path],
                                                capsys: pytest.CaptureFixture[str]) -> None:
    m = small["tdms"].parent / "t.map.toml"
    m.write_text(m.read_text().replace('channel = "acc 3"', 'channel = "acc 33"'))
    for p in (small["tdms"], small["mf4"]):
        line = _refused(capsys, str(p))
        assert "has no channel 'acc 33'" in line and "fix the channel map" in line


def test_a_bad_map_is_one_line(small: dict[str, Path],
                               capsys: pytest.CaptureFixture[str]) -> None:
    m = small["tdms"].parent / "t.map.toml"
    text = m.read_text()
    for bad, said in [(text.replace('unit = "N"', 'unit = "furlong"'), "unknown unit"),
                      (text.replace('unit = "N"', 'unit = "mV"'), "give its sensitivity"),
                      (text + "\n[extra]\n", "unknown key 'extra'"),
                      (text.replace("[layout]", "[layout"), "not valid TOML"),
                      (text.replace('groups = ["run 2"]', 'groups = ["run 9"]'),
                       "group 'run 2' is in no [[excitation]]")]:
        m.write_text(bad)
        assert said in _refused(capsys, str(small["tdms"]))


def test_channels_at_different_rates_skip_the_run(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    runs = _runs("shaker", [0, 7])
    write_time_tdms(tmp_path / "t.tdms", runs, _groups(runs), NAMES)
    (tmp_path / "t.map.toml").write_text(_map(runs))
    from nptdms import ChannelObject, TdmsWriter

    with TdmsWriter(str(tmp_path / "t.tdms"), mode="a") as w:  # run 2's acc 0 re-sampled
        w.write_segment([ChannelObject("run 2", "acc 0", runs[1].responses[0],
                                       properties={"wf_increment": 1 / 512})])
    assert main(["frf", str(tmp_path / "t.tdms"), "--out", str(tmp_path / "f.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith("(skipped)")
    assert "load case 2 (group 'run 2')" in err[0] and "different sample rates" in err[0]


def test_nan_samples_skip_the_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = _runs("shaker", [0, 7])
    bad = runs[1].responses.copy()
    bad[3, 100:110] = np.nan
    runs[1] = TimeRun(2, FS, runs[1].force, runs[1].exc_node, runs[1].exc_dir, bad,
                      runs[1].resp_nodes, runs[1].resp_dirs)
    write_time_mdf(tmp_path / "t.mf4", runs, _groups(runs), NAMES)
    (tmp_path / "t.map.toml").write_text(_map(runs))
    assert main(["frf", str(tmp_path / "t.mf4"), "--out", str(tmp_path / "f.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "channel 'acc 3': 10 NaN or infinite sample(s)" in err[0]
    assert err[0].endswith("(skipped)")


@pytest.mark.parametrize("suffix", [".tdms", ".mf4"])
def test_a_file_of_another_kind_is_refused(tmp_path: Path, suffix: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / f"x{suffix}"
    p.write_bytes(b"    -1\n  2411\n" * 40)
    line = _refused(capsys, str(p))
    assert f"x{suffix} is not a{'n MDF' if suffix == '.mf4' else ' TDMS'} file" in line


@pytest.mark.parametrize("name", ["tdms", "mf4"])
@pytest.mark.parametrize("keep", [0.5, 0.98])
def test_a_truncated_file_is_refused(small: dict[str, Path], name: str, keep: float,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    p = small[name]
    raw = p.read_bytes()
    p.write_bytes(raw[:int(len(raw) * keep)])
    line = _refused(capsys, str(p))
    assert "truncated" in line and "again" in line


@pytest.mark.parametrize(("module", "suffix", "extra"),
                         [("nptdms", "tdms", "tdms"), ("asammdf", "mf4", "mdf")])
def test_a_missing_extra_names_the_install(small: dict[str, Path], run_file: Path,
                                           monkeypatch: pytest.MonkeyPatch, module: str,
                                           suffix: str, extra: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, module, None)  # import fails as if not installed
    line = _refused(capsys, str(small[suffix]))
    assert line.endswith(f"pip install 'insitu[{extra}]'")
    out = small[suffix].parent / f"e.{suffix}"
    assert main(["export", str(run_file), f"--{suffix}", str(out)]) == 2
    assert one_error_line(capsys).endswith(f"pip install 'insitu[{extra}]'")
    assert not out.exists()


def test_channels_on_a_uff_is_said_ignored(small: dict[str, Path],
                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = small["uff"].parent / "f.h5"
    assert main(["frf", str(small["uff"]), "--channels", "m.toml", "--out", str(out)]) == 0
    assert "--channels ignored: t.uff is a UFF file" in capsys.readouterr().err


def test_time_uff_and_frf_files_load_neither_extra(small: dict[str, Path]) -> None:
    code = ("import sys; from app.pipeline import load, Settings; "
            f"load({str(small['uff'])!r}, Settings()); "
            "print(sorted(m for m in ('nptdms', 'asammdf') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, cwd=Path(__file__).parents[2], check=True)
    assert out.stdout.strip() == "[]"
