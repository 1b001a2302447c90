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


@pytest.mark.parametrize(("argv", "message"), [
    (["identify", "{f}", "--refine-points", "1000000000"],
     "--refine-points must be from 0 to 20 rounds, got 1000000000"),
    (["identify", "{f}", "--refine-points", "-1"],
     "--refine-points must be from 0 to 20 rounds, got -1"),
    (["identify", "{f}", "--refine-points", "3", "--bootstrap", "50"],
     "--refine-points runs no bootstrap (each round is one fit): drop --bootstrap or "
     "--refine-points"),
    (["identify", "{f}", "--mass-band", "50", "10"],
     "--mass-band 50 10: give the lower edge first (LO < HI, Hz)"),
    (["identify", "{f}", "--stiffness-band", "-1", "10"],
     "--stiffness-band must be from 0 to 10000000 Hz, got -1"),
    (["identify", "{f}", "--stiffness-band", "1", "inf"],
     "--stiffness-band must be above 0 and at most 10000000 Hz, got inf"),
    (["identify", "{f}", "--excitation-hz", "inf"],
     "--excitation-hz must be above 0 and at most 10000000 Hz, got inf"),
    (["identify", "{f}", "--loss-factor-hz", "nan"],
     "--loss-factor-hz must be above 0 and at most 10000000 Hz, got nan"),
    (["report", "{f}", "--excitation-hz", "1e300"],
     "--excitation-hz must be above 0 and at most 10000000 Hz, got 1e+300"),
    (["batch", "{f}", "--out", "{d}", "--workers", "100000"],
     "--workers must be from 1 to 256 worker processes, got 100000"),
    (["batch", "{f}", "--out", "{d}", "--refine-points", "50"],
     "--refine-points must be from 0 to 20 rounds, got 50"),
    (["simulate", "engine", "--out", "{d}/x.uff", "--noise", "nan"],
     "--noise must be from 0 to 1 (relative to |H|), got nan"),
    (["simulate", "engine", "--out", "{d}/x.uff", "--location-error", "5"],
     "--location-error must be from 0 to 0.1 m, got 5"),
    (["simulate", "engine", "--out", "{d}/x.uff", "--seed", "-1"],
     "--seed must be from 0 to 4294967295, got -1"),
    (["simulate", "engine", "--out", "{d}/x.h5"],
     "--out {d}/x.h5: simulate writes UFF: give a .uff or .unv name"),
    (["demo", "--frf-only", "--noise", "-0.5"],
     "--noise must be from 0 to 1 (relative to |H|), got -0.5"),
    (["demo", "--length", "1e9"], "--length must be from 0.1 to 60 s, got 1000000000"),
    (["demo", "--frf-only", "--out", "{d}/x.h5"],
     "--frf-only writes no run file: leave out --out"),
])
def test_numbers_out_of_range_are_one_line_naming_the_range_before_any_work(
        argv: list[str], message: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Refused before the file is looked at (it does not exist) or anything is computed."""
    words = [a.format(f=tmp_path / "not-read.uff", d=tmp_path) for a in argv]
    assert main(words) == 2
    err = capsys.readouterr().err.strip().splitlines()
    expected = f"insitu {argv[0]}: error: " + message.format(d=tmp_path)
    assert err == [expected], err
    assert sorted(tmp_path.iterdir()) == []


# --- options that do not apply to the input: named in one warning line ------------------------


def _stop_at_load(monkeypatch: pytest.MonkeyPatch) -> None:
    """The verb stops where it would read the file (the pipeline's load, which every verb
    reaches through ``app.cli.frf.load_and_show``): the warning comes before."""
    from app.cli.common import UserError

    def stop(*args: object, **kwargs: object) -> None:
        raise UserError("stopped before reading")

    monkeypatch.setattr("app.cli.frf.load", stop)


def test_time_options_on_an_frf_file_are_named_ignored(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from app.io.uff import write_frf_uff

    uff = tmp_path / "engine.uff"
    write_frf_uff(uff, get_bench("engine-rigid").frfset(), binary=True)
    assert main(["identify", str(uff), "--nperseg", "256", "--overlap", "0.25",
                 "--estimator", "H2", "--bootstrap", "50", "--no-uncertainty"]) == 2
    capsys.readouterr()  # --bootstrap with --no-uncertainty: refused before the warning
    assert main(["identify", str(uff), "--nperseg", "256", "--overlap", "0.25",
                 "--estimator", "H2", "--bootstrap", "50"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["insitu identify: warning: --estimator, --nperseg, --overlap, --bootstrap "
                   "ignored: engine.uff holds FRFs, not time records"], err
    assert main(["identify", str(uff), "--coherence", "0.5", "--no-uncertainty"]) == 0
    assert capsys.readouterr().err == ""  # the coherence gate applies to FRFs too


def test_time_options_on_a_run_file_are_named_ignored(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    import h5py

    run = tmp_path / "shaker.h5"
    with h5py.File(run, "w") as f:  # not an FRF file: a run file to the format detection
        f.attrs["format"] = "insitu-run"
    _stop_at_load(monkeypatch)
    assert main(["identify", str(run), "--nperseg", "256", "--overlap", "0.5"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[0] == (
        "insitu identify: warning: --nperseg, --overlap ignored: shaker.h5 is a run file: its "
        "records are processed with its plan's settings")
    _stop_at_load(monkeypatch)
    # insitu frf averages a run file's first N records and cuts its band: those apply
    assert main(["frf", str(run), "--averages", "3", "--fmax", "100", "--window", "hann"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[0] == (
        "insitu frf: warning: --window ignored: shaker.h5 is a run file: its records are "
        "processed with its plan's settings")


def test_welch_options_on_impact_data_are_named_ignored(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = _impact_file(tmp_path)
    out = tmp_path / "frf.uff"
    assert main(["frf", str(src), "--out", str(out), "--method", "impact", "--nperseg",
                 "256"]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warned == ["insitu frf: warning: --nperseg ignored: the excitation is impact (they "
                      "cut the Welch segments of random excitation)"]
    # the excitation read from the data: the warning comes once it is known
    assert main(["frf", str(src), "--out", str(out), "--window", "hann"]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warned == ["insitu frf: warning: --window ignored: the excitation is impact (they "
                      "cut the Welch segments of random excitation)"]
