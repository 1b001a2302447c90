"""``insitu frf``: a bad run is one stderr line and skipped, the good runs written, exit 2."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import pyuff

from app.cli.main import main
from app.io.frf_h5 import read_frf_h5
from app.io.uff import read_frf_uff
from app.io.uff_time import TimeRun, write_time_uff
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import half_sine, impulse_response, simulate
from processing.excitation import continuous_random

FS = 256.0


def _run(lc: int, k: int, force: np.ndarray) -> TimeRun:
    b = get_bench("engine-rigid")
    g = b.geometry
    ir = impulse_response(b.model, FS, g.coordinates(b.resp_nodes), b.resp_dirs,
                          g.coordinates(b.exc_nodes[k:k + 1]), b.exc_dirs[k:k + 1])
    return TimeRun(lc, FS, force, int(b.exc_nodes[k]), b.exc_dirs[k],
                   simulate(ir, force[None]), b.resp_nodes, b.resp_dirs)


def _time_rec(node: int, lc: int, data: np.ndarray, *, kind: int = 12,
              dt: float = 1 / FS) -> dict[str, object]:
    return pyuff.prepare_58(
        binary=0, func_type=1, rsp_node=node, rsp_dir=1, ref_node=node, ref_dir=1,
        load_case_id=lc, data=data, x=np.arange(data.size) * dt, abscissa_spacing=1,
        abscissa_spec_data_type=17, ordinate_spec_data_type=kind, orddenom_spec_data_type=0,
        id1="bad run")


def _with_bad_runs(path: Path, runs: list[TimeRun], bad: list[dict[str, object]],
                   nan_last: bool = False) -> Path:
    """Good runs written by insitu, bad ASCII records by pyuff, in one UFF file (datasets
    appended); ``nan_last`` puts a NaN where the last record holds an exact 0 (pyuff
    itself writes NaN as 0)."""
    write_time_uff(path, runs, get_bench("engine-rigid").geometry, binary=True)
    if not bad:
        return path
    extra = path.with_suffix(".extra")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        pyuff.UFF(str(extra)).write_sets(bad, mode="overwrite")
    text = extra.read_bytes()
    if nan_last:
        zero = b"   0.00000000000e+00"
        k = text.rfind(zero)
        text = text[:k] + b"nan".rjust(len(zero)) + text[k + len(zero):]
    path.write_bytes(path.read_bytes() + text)
    return path


def _lines(err: str) -> list[str]:
    lines = err.strip().splitlines()
    assert all(line.startswith("insitu frf: ") and line.endswith("(skipped)") for line in lines)
    return lines


def test_random_bad_runs_are_reported_and_good_ones_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b = get_bench("engine-rigid")
    good = [_run(lc, k, continuous_random(16 * 1024, FS, rms=10.0, seed=lc)[0])
            for lc, k in ((1, 0), (2, 7))]
    node = int(b.resp_nodes[0])
    x = np.random.default_rng(0).standard_normal(64)
    bad = [
        _time_rec(node, 3, x), _time_rec(node, 3, 2 * x),  # no force record
        _time_rec(node, 4, x, kind=13), _time_rec(node, 4, x, dt=0.5 / FS),  # two rates
        _time_rec(node, 5, x, kind=13), _time_rec(node, 5, x[:32]),  # two lengths
        _time_rec(node, 6, x, kind=13), _time_rec(node, 6, np.r_[x[:10], 0.0, x[11:]]),
    ]
    src = _with_bad_runs(tmp_path / "time.uff", good, bad, nan_last=True)
    out = tmp_path / "frf.uff"
    assert main(["frf", str(src), "--out", str(out), "--nperseg", "1024"]) == 2
    cap = capsys.readouterr()
    lines = _lines(cap.err)
    assert len(lines) == 4
    assert "load case 3: no force record" in lines[0]
    assert "load case 4: records with different sample rates (256, 512 Hz)" in lines[1]
    assert "load case 5: records of different lengths (32, 64 samples)" in lines[2]
    assert "load case 6" in lines[3] and "1 NaN or infinite sample(s)" in lines[3]
    assert "4 bad run(s) skipped, exit status 2" in cap.out
    frf = read_frf_uff(out)
    assert frf.H.shape == (12, 2, 399)  # the 0 Hz line cut: under the coherence gate
    assert frf.freq[0] > 0
    assert frf.exc_nodes.tolist() == [int(b.exc_nodes[0]), int(b.exc_nodes[7])]


def test_impact_no_hit_and_every_hit_rejected(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    n = int(16 * FS)
    hits = np.sum([half_sine(n, FS, t, 0.02, 200.0) for t in (1.0, 6.0, 11.0)], axis=0)
    weak = np.sum([half_sine(n, FS, t, 0.02, 50.0) for t in (1.0, 6.0)], axis=0)
    double = hits + np.sum([half_sine(n, FS, t + 0.1, 0.02, 80.0) for t in (1.0, 6.0, 11.0)],
                           axis=0)
    runs = [_run(1, 0, hits), _run(2, 3, weak), _run(3, 5, double), _run(4, 7, hits),
            _run(5, 9, np.zeros(n))]
    src = _with_bad_runs(tmp_path / "time.uff", runs, [])
    out = tmp_path / "frf.h5"
    args = ["frf", str(src), "--out", str(out), "--method", "impact", "--record", "4",
            "--pretrigger", "0.25", "--level", "100"]
    assert main(args) == 2
    cap = capsys.readouterr()
    lines = _lines(cap.err)
    assert len(lines) == 3
    assert "load case 2: no hit found (the force never crosses 100 N): lower --level" in lines[0]
    assert "load case 3: every hit rejected (hit 1: double hit" in lines[1]
    assert "hit 3: double hit" in lines[1]
    assert "load case 5: no hit found" in lines[2]
    assert "load case 1 (node" in cap.out and "3 hits accepted" in cap.out
    frf = read_frf_h5(out)
    b = get_bench("engine-rigid")
    assert frf.exc_nodes.tolist() == [int(b.exc_nodes[0]), int(b.exc_nodes[7])]
    assert frf.H.shape == (12, 2, 400)
    # without --level the silent force channel is named as such
    assert main(args[:-2]) == 2
    err = capsys.readouterr().err
    assert "load case 5: the force channel is zero throughout" in err


def test_every_run_bad_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b = get_bench("engine-rigid")
    x = np.random.default_rng(1).standard_normal(64)
    node = int(b.resp_nodes[0])
    src = tmp_path / "time.uff"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        pyuff.UFF(str(src)).write_sets([_time_rec(node, 1, x), _time_rec(node, 2, x)],
                                       mode="overwrite")
    out = tmp_path / "frf.uff"
    assert main(["frf", str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and "no usable time run (2 bad run(s), see above)" in err[-1]
    assert not out.exists()


def test_unknown_output_suffix_is_one_line(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["frf", str(tmp_path / "t.uff"), "--out", str(tmp_path / "frf.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown suffix '.csv'" in err
