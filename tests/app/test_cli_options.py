"""Options checked once, up front, in the units the user typed: one line, exit 2, no file read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff_time import TimeRun, write_time_uff
from hardware_mocks.benches import get_bench
from hardware_mocks.signals import half_sine, impulse_response, simulate

FS = 256.0


@pytest.mark.parametrize(("option", "message"), [
    (["--nperseg", "0"], "--nperseg must be from 8 to 16777216 samples, got 0"),
    (["--overlap", "1"], "--overlap must be at least 0 and below 1, got 1"),
    (["--window", "nonsense"], "--window 'nonsense' is not a window scipy knows"),
    (["--averages", "0"], "--averages must be at least 1, got 0"),
    (["--level", "-3"], "--level must be a positive force in N"),
    (["--record", "1e9"], "--record must be from 0.001 to 3600 s, got 1000000000"),
    (["--pretrigger", "-1"], "--pretrigger must be at least 0 s, got -1 s"),
    (["--pretrigger", "2", "--record", "1"], "--pretrigger must be at least 0 s and shorter "
                                             "than --record (1 s), got 2 s"),
    (["--exp-tau", "-1"], "--exp-tau must be a time constant in s (0: no exponential window), "
                          "got -1"),
    (["--coherence", "1.5"], "--coherence must be from 0 to 1, got 1.5"),
    (["--fmax", "1e300"], "--fmax must be from 0.001 to 10000000 Hz, got 1e+300"),
    (["--fmax", "nan"], "--fmax must be from"),
])
@pytest.mark.parametrize("verb", ["frf", "identify"])
def test_bad_option_is_one_line_before_any_file_is_read(
        verb: str, option: list[str], message: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "not-read.uff"  # the option is refused before the file is looked at
    assert main([verb, str(missing), *option]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert "not found" not in err[0]


def test_usage_mistake_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["frf", "x.uff", "--method", "bogus"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "invalid choice: 'bogus'" in err[0]
    assert err[0].endswith("(see insitu frf --help)")


def _impact_file(tmp_path: Path, n_runs: int = 3) -> Path:
    b = get_bench("engine-rigid")
    g = b.geometry
    rx, ex = g.coordinates(b.resp_nodes), g.coordinates(b.exc_nodes)
    runs = []
    for lc in range(1, n_runs + 1):
        k = lc - 1
        ir = impulse_response(b.model, FS, rx, b.resp_dirs, ex[k:k + 1], b.exc_dirs[k:k + 1])
        f = half_sine(int(8 * FS), FS, 1.0, 0.02, 200.0)[None]
        runs.append(TimeRun(lc, FS, f[0], int(b.exc_nodes[k]), b.exc_dirs[k],
                            simulate(ir, f), b.resp_nodes, b.resp_dirs))
    path = tmp_path / "time.uff"
    write_time_uff(path, runs, g, binary=True)  # type: ignore[arg-type]
    return path


def test_options_that_depend_on_the_data_are_checked_once_per_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = _impact_file(tmp_path)
    out = tmp_path / "frf.uff"
    assert main(["frf", str(src), "--out", str(out), "--method", "impact", "--record",
                 "100"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--record 100 s is longer than every run (the longest is 8 s)" \
        in err[0]
    assert main(["frf", str(src), "--out", str(out), "--method", "impact", "--fmax",
                 "1000"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "above the records' Nyquist frequency (128 Hz)" in err[0]
    assert not out.exists()
    assert main(["frf", str(src), "--out", str(out), "--method", "impact", "--record",
                 "4"]) == 0
    assert out.exists() and np.isfinite(out.stat().st_size)
