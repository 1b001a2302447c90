"""What an operator meets when things go wrong: one line, exit 2, nothing claimed that is untrue."""

from __future__ import annotations

import re
import socket
import time
from pathlib import Path

import pytest

from app.cli.main import main
from app.io.runfile import read_run
from drivers.errors import DeviceNotAvailableError
from drivers.transports import CanLink
from hardware_mocks.bench_process import MockBench
from tests.app.cli_lines import one_error_line
from tests.app.test_cli_demo import POINTS, six_point_plans

PLAN = Path(__file__).resolve().parents[2] / "docs" / "mock_bench_plan.toml"


def _dead_station(tmp_path: Path) -> Path:
    """The station file of a mock bench that has since stopped: every device unreachable."""
    with MockBench("engine") as bench:
        text = bench.station_toml()
    text = re.sub(r'url = "[^"]+"', 'url = "/dev/insitu-no-such-port"', text)
    path = tmp_path / "bench.toml"
    path.write_text(text)
    return path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_unreachable_socketcand_is_one_line_in_bounded_time(caplog: pytest.LogCaptureFixture
                                                            ) -> None:
    link = CanLink(name="fe", interface="socketcand", host="127.0.0.1", port=_free_port(),
                   channel="vcan0")
    t = time.monotonic()
    with pytest.raises(DeviceNotAvailableError, match=r"fe: socketcand server 127\.0\.0\.1:\d+ "
                                                      r"not reachable .* after 4 tries"):
        link.open()
    assert time.monotonic() - t < 5.0
    assert not [r for r in caplog.records if r.levelname == "WARNING"]


def test_acquire_on_a_dead_station_writes_no_file_and_claims_none(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    station = _dead_station(tmp_path)
    out = tmp_path / "dead.h5"
    assert main(["acquire", "--station", str(station), "--plan", str(PLAN), "--out",
                 str(out)]) == 2
    line = one_error_line(capsys)
    assert "no record was acquired and no run file was written" in line
    assert "records are in" not in line and not out.exists()


def test_acquire_into_a_missing_folder_is_refused_up_front(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "nope" / "x.h5"
    assert main(["acquire", "--mock", "--out", str(out)]) == 2
    line = one_error_line(capsys)
    assert f"folder {out.parent} does not exist" in line and not out.parent.exists()


def test_resume_takes_the_run_file_and_refuses_a_finished_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run.h5"
    assert main(["acquire", "--resume", str(out)]) == 2
    assert "no run file to resume" in one_error_line(capsys)
    assert main(["acquire", "--mock", "--bench", "engine-rigid", "--points", "0,1,3,4,6,8",
                 "--length", "0.5", "--out", str(out)]) == 0
    capsys.readouterr()
    size = out.stat().st_size
    assert read_run(out, with_data=False).state == "finished"
    assert main(["acquire", "--resume", str(out)]) == 2  # the README's form
    line = one_error_line(capsys)
    assert "is a finished run (6 records): nothing to resume" in line
    assert out.stat().st_size == size  # the file is not touched
    assert main(["acquire", "--resume", str(out), "--out", str(tmp_path / "other.h5")]) == 2
    assert "give the run file once" in one_error_line(capsys)
    assert main(["acquire", "--mock"]) == 2
    assert "give --out RUN.h5" in one_error_line(capsys)


def test_a_bug_is_one_line_naming_the_log_file(monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    import app.cli.replay as replay

    def boom(args: object) -> int:
        raise RuntimeError("something we did not foresee\nsecond line")

    monkeypatch.setattr(replay, "run", boom)
    assert main(["replay", "x.h5"]) == 1
    line = one_error_line(capsys)
    assert line.startswith("insitu replay: internal error: RuntimeError: something we did not "
                           "foresee (details in ")
    log = Path(line.split("details in ")[1].split(";")[0])
    assert "Traceback" in log.read_text() and "second line" in log.read_text()


@pytest.mark.slow
def test_piped_output_keeps_every_digit_and_shows_progress(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("COLUMNS", raising=False)
    uff = tmp_path / "engine.uff"
    assert main(["simulate", "engine-rigid", "--out", str(uff)]) == 0
    capsys.readouterr()
    assert main(["identify", str(uff)]) == 0  # stdout is captured: not a terminal
    out = capsys.readouterr().out
    assert "Stiffness" in out and "…" not in out  # no cell cut at 80 columns
    monkeypatch.chdir(tmp_path)
    (tmp_path / "demo-run.h5").write_bytes(b"")  # the default name is taken: the next one
    six_point_plans(monkeypatch)
    assert main(["demo", "--bench", "engine-rigid", "--length", "0.5"]) == 0
    out = capsys.readouterr().out
    n = len(POINTS)
    assert out.count(f"of {n} done)") == n  # one line per point in a log, not silence
    assert "run file demo-run-2.h5 kept" in out and "…" not in out
    assert len(read_run(tmp_path / "demo-run-2.h5", with_data=False).records) == n


def test_a_log_message_holding_a_traceback_is_one_line_without_it() -> None:
    """python-can's socketcand client logs ``Failed to receive: ERR  Traceback (most
    recent call last):`` and the traceback; the terminal shows the first part only."""
    import logging

    from app.cli.main import _OneLine

    record = logging.LogRecord(
        "can.interfaces.socketcand.socketcand", logging.ERROR, __file__, 1,
        "Failed to receive: [Errno 104] Connection reset by peer  Traceback (most recent "
        "call last):\n  File \"x.py\", line 1, in f\nConnectionResetError: reset", None, None)
    assert _OneLine().format(record) == ("ERROR can.interfaces.socketcand.socketcand: Failed "
                                         "to receive: [Errno 104] Connection reset by peer")


# --- output paths: checked before anything is read or computed --------------------------------


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every way a verb reads its input or computes, made to record its call: a verb that
    refuses its output up front leaves the list empty."""
    calls: list[str] = []

    def called(name: str) -> object:
        def record(*args: object, **kwargs: object) -> None:
            calls.append(name)
            raise AssertionError(f"{name} called before the output was checked")
        return record

    import app.cli.batch
    import app.cli.demo
    import app.cli.frf
    import app.cli.identify
    import app.cli.replay
    import app.cli.simulate
    import app.report.sources

    for module, name in [(app.cli.frf, "load"), (app.cli.identify, "detect_format"),
                         (app.cli.identify, "load_and_show"), (app.cli.replay, "read_run"),
                         (app.cli.replay, "load"), (app.report.sources, "load"),
                         (app.cli.simulate, "get_bench"), (app.cli.batch, "open_client"),
                         (app.cli.demo, "_acquire")]:
        monkeypatch.setattr(module, name, called(f"{module.__name__}.{name}"))
    return calls


def _verbs(src: Path, out: Path) -> dict[str, list[str]]:
    return {"frf": ["frf", str(src), "--out", str(out.with_suffix(".uff"))],
            "identify": ["identify", str(src), "--out", str(out)],
            "replay": ["replay", str(src.with_suffix(".h5")), "--out", str(out)],
            "report": ["report", str(src), "--out", str(out.with_suffix(".html"))],
            "simulate": ["simulate", "engine", "--out", str(out.with_suffix(".uff"))],
            "demo": ["demo", "--out", str(out.with_suffix(".h5"))]}


@pytest.mark.parametrize("verb", ["frf", "identify", "replay", "report", "simulate", "demo"])
def test_output_in_a_missing_folder_is_one_line_before_any_work(
        verb: str, tmp_path: Path, no_work: list[str],
        capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "in.uff"
    src.write_text("not read")
    (tmp_path / "in.h5").write_text("not read")
    out = tmp_path / "nonexistent_dir" / "x.json"
    argv = _verbs(src, out)[verb]
    assert main(argv) == 2
    line = one_error_line(capsys)
    assert line.startswith(f"insitu {verb}: error: --out {argv[-1]}: folder "
                           f"{out.parent} does not exist: create it or choose another --out")
    assert no_work == [] and not out.parent.exists()


def test_batch_output_folder_checked_before_any_work(
        tmp_path: Path, no_work: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "in.uff"
    src.write_text("not read")
    assert main(["batch", str(src), "--out", str(src)]) == 2
    assert one_error_line(capsys) == (f"insitu batch: error: --out {src} is a file, not a folder: "
                                 "give a folder for the tables")
    assert main(["batch", str(src), "--out", "/proc/insitu-campaign"]) == 2
    assert one_error_line(capsys) == ("insitu batch: error: --out /proc/insitu-campaign: folder "
                                 "/proc is not writable: choose another --out")
    assert no_work == []


@pytest.mark.parametrize(("target", "message"), [
    ("/proc/version", "--out /proc/version: folder /proc is not writable: choose another --out"),
    ("/proc/1/x", "--out /proc/1/x: folder /proc/1 is not writable: choose another --out"),
    ("/dev/null", "--out /dev/null is a device or special file, not a regular file"),
    ("{tmp}", "--out {tmp} is a folder: give a file name in it"),
    ("{tmp}/in.uff", "--out {tmp}/in.uff is the input file: it would be replaced"),
])
@pytest.mark.parametrize("verb", ["identify", "replay", "report"])
def test_special_or_unsafe_output_is_refused_naming_it(
        verb: str, target: str, message: str, tmp_path: Path, no_work: list[str],
        capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / ("in.h5" if verb == "replay" else "in.uff")
    src.write_text("not read")
    target = target.format(tmp=tmp_path).replace("in.uff", src.name)
    assert main([verb, str(src), "--out", target]) == 2
    assert one_error_line(capsys).startswith(
        f"insitu {verb}: error: " + message.format(tmp=tmp_path).replace("in.uff", src.name))
    assert no_work == [] and src.read_text() == "not read"


def test_write_failing_at_the_end_names_the_users_path_not_a_temporary_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The folder passed the check, then the disk filled: one line naming --out, the old
    file kept whole, no temporary file left."""
    import errno
    import os

    import app.io._uff_write

    uff = tmp_path / "engine.uff"
    assert main(["simulate", "engine-rigid", "--out", str(uff)]) == 0
    capsys.readouterr()
    out = tmp_path / "r.json"
    out.write_text("old result")
    real_replace = os.replace

    def disk_full(src: object, dst: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(src))

    monkeypatch.setattr(os, "replace", disk_full)
    assert main(["identify", str(uff), "--out", str(out), "--no-uncertainty"]) == 2
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line == (f"insitu identify: error: --out {out}: cannot write it (No space left on "
                    "device): free some space or choose another --out")
    frf_out = tmp_path / "frf.uff"
    monkeypatch.setattr(app.io._uff_write.os, "replace", disk_full)
    assert main(["simulate", "engine-rigid", "--out", str(frf_out)]) == 2
    assert one_error_line(capsys) == (
        f"insitu simulate: error: --out {frf_out}: cannot write it (No space left on device): "
        "free some space or choose another --out")
    monkeypatch.setattr(os, "replace", real_replace)
    assert out.read_text() == "old result" and not frf_out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["engine.uff", "r.json"]
