"""``insitu frf``: UFF time records of the simulated engine -> FRF UFF file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff import read_frf_uff
from app.io.uff_time import TimeRun, write_time_uff
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import half_sine, impulse_response, simulate
from processing.excitation import continuous_random

FS = 256.0
EXC = (0, 7)  # two excitation DOFs of the engine


def _engine():
    b = get_bench("engine-rigid")
    g = b.geometry
    return b, g, g.coordinates(b.resp_nodes), g.coordinates(b.exc_nodes)


def _runs(kind: str) -> tuple[list[TimeRun], object]:
    b, g, rx, ex = _engine()
    runs = []
    for lc, k in enumerate(EXC, start=1):
        ir = impulse_response(b.model, FS, rx, b.resp_dirs, ex[k:k + 1], b.exc_dirs[k:k + 1])
        if kind == "random":
            f = continuous_random(64 * 1024, FS, rms=10.0, seed=lc)
        else:
            n = int(16 * FS)
            f = sum(half_sine(n, FS, t, 0.02, 200.0) for t in (1.0, 6.0, 11.0))[None]
            if lc == 2:  # a double hit in the second run's second record
                f = f + half_sine(n, FS, 6.1, 0.02, 80.0)[None]
        x = simulate(ir, f)
        runs.append(TimeRun(lc, FS, f[0], int(b.exc_nodes[k]), b.exc_dirs[k], x,
                            b.resp_nodes, b.resp_dirs))
    return runs, g


def test_random_runs_to_frf_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs, g = _runs("random")
    src, out = tmp_path / "time.uff", tmp_path / "frf.uff"
    write_time_uff(src, runs, g, binary=True)  # type: ignore[arg-type]
    assert main(["frf", str(src), "--out", str(out), "--nperseg", "1024", "--binary"]) == 0
    text = capsys.readouterr().out
    assert "averages" in text and "rigid from" in text and "written to" in text
    frf = read_frf_uff(out)
    b, _, rx, ex = _engine()
    # up to fs / 2.56, from the first line whose median coherence reaches the gate's 0.8
    n_low = 400 - frf.H.shape[-1]
    assert frf.H.shape[:2] == (12, 2) and 0 <= n_low <= 4 and frf.coherence is not None
    assert (f"the {n_low} lines below have a median coherence under 0.8" in text) == (n_low > 0)
    He = b.model.frf(frf.freq, rx, b.resp_dirs, ex[list(EXC)], b.exc_dirs[list(EXC)])
    m = (frf.coherence > 0.99) & (frf.freq > 5) & (frf.freq < 90)
    assert m.mean() > 0.5
    assert np.max(np.abs(np.abs(frf.H[m]) / np.abs(He[m]) - 1)) < 0.05


def test_impact_runs_report_rejected_hits(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    runs, g = _runs("impact")
    src, out = tmp_path / "time.uff", tmp_path / "frf.uff"
    write_time_uff(src, runs, g, binary=True)  # type: ignore[arg-type]
    assert main(["frf", str(src), "--out", str(out), "--method", "impact", "--record", "4",
                 "--pretrigger", "0.25", "--exp-tau", "0.5"]) == 0
    text = capsys.readouterr().out
    assert "load case 1 (node" in text and "3 hits accepted" in text
    assert "2 hits accepted, rejected: hit 2: double hit" in text
    assert read_frf_uff(out).H.shape == (12, 2, 400)  # lines up to fs / 2.56


def test_frf_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs, g = _runs("random")
    src = tmp_path / "time.uff"
    write_time_uff(src, runs, g, binary=True)  # type: ignore[arg-type]
    assert main(["frf", str(src), "--out", str(tmp_path / "o.uff"), "--nperseg",
                 "999999"]) == 2
    err = capsys.readouterr().err.strip()
    assert "fewer than --nperseg" in err and "\n" not in err


def test_averages_random_uses_the_first_segments(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    runs, g = _runs("random")
    src, out = tmp_path / "time.uff", tmp_path / "frf.uff"
    write_time_uff(src, runs, g, binary=True)  # type: ignore[arg-type]
    assert main(["frf", str(src), "--out", str(out), "--nperseg", "1024", "--averages",
                 "10"]) == 0
    text = capsys.readouterr().out
    assert text.count(": 10 averages") == 2
    # the same as the runs cut to the samples of their first 10 segments (50 % overlap)
    n = 9 * 512 + 1024
    cut = [TimeRun(r.load_case, r.fs, r.force[:n], r.exc_node, r.exc_dir, r.responses[:, :n],
                   r.resp_nodes, r.resp_dirs) for r in runs]
    src2, out2 = tmp_path / "cut.uff", tmp_path / "cut_frf.uff"
    write_time_uff(src2, cut, g, binary=True)  # type: ignore[arg-type]
    assert main(["frf", str(src2), "--out", str(out2), "--nperseg", "1024"]) == 0
    assert ": 10 averages" in capsys.readouterr().out
    np.testing.assert_array_equal(read_frf_uff(out).H, read_frf_uff(out2).H)
    # more than there are: all of them
    assert main(["frf", str(src), "--out", str(out), "--nperseg", "1024", "--averages",
                 "100000"]) == 0
    assert ": 127 averages" in capsys.readouterr().out
    assert main(["frf", str(src), "--out", str(out), "--averages", "0"]) == 2
    assert "--averages must be at least 1" in capsys.readouterr().err


def test_averages_impact_uses_the_first_accepted_hits_of_a_point(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs, g = _runs("impact")
    r1 = runs[0]  # a second run at the first run's point
    again = TimeRun(3, r1.fs, r1.force, r1.exc_node, r1.exc_dir, r1.responses, r1.resp_nodes,
                    r1.resp_dirs)
    src, out = tmp_path / "time.uff", tmp_path / "frf.uff"
    write_time_uff(src, [*runs, again], g, binary=True)  # type: ignore[arg-type]
    opts = ["--method", "impact", "--record", "4", "--pretrigger", "0.25", "--exp-tau", "0"]
    assert main(["frf", str(src), "--out", str(out), *opts, "--averages", "2"]) == 0
    text = capsys.readouterr().out
    assert "load case 1 (node" in text
    assert "2 hits accepted; 1 more not used (--averages 2)" in text
    assert "2 hits accepted, rejected: hit 2: double hit" in text  # point 2: none left over
    assert "load case 3 (node" in text and "not used, the first 2 accepted hits" in text
    assert main(["frf", str(src), "--out", str(out), *opts, "--averages", "4"]) == 0
    text = capsys.readouterr().out
    assert "3 hits accepted\n" in text and "1 hits accepted; 2 more not used" in text
    # with 3: exactly the hits of the first run at that point
    assert main(["frf", str(src), "--out", str(out), *opts, "--averages", "3"]) == 0
    src2, out2 = tmp_path / "two.uff", tmp_path / "two_frf.uff"
    write_time_uff(src2, runs, g, binary=True)  # type: ignore[arg-type]
    assert main(["frf", str(src2), "--out", str(out2), *opts]) == 0
    np.testing.assert_array_equal(read_frf_uff(out).H, read_frf_uff(out2).H)
