"""The mock bench is kept apart: the command line and the GUI load without the simulators'
pseudo-terminals, and the mock bench is refused (one line) where it cannot run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import app.mockbench
from app.cli.main import main

_NO_PTY = """
import sys
for name in ("tty", "pty"):  # as on Windows: no pseudo-terminals (pyserial still loads)
    sys.modules[name] = None
from app.cli.main import build_parser
build_parser()
import app.gui.main_window
mocks = sorted(m for m in sys.modules if m.startswith("hardware_mocks."))
print(" ".join(mocks))
"""


def test_cli_and_gui_load_without_pseudo_terminals() -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    out = subprocess.run([sys.executable, "-c", _NO_PTY], capture_output=True, text=True,
                         env=env, timeout=120, cwd=Path(__file__).parents[2], check=False)
    assert out.returncode == 0, out.stderr
    loaded = out.stdout.split()
    # the bench models (for --bench choices) but no simulated device
    assert "hardware_mocks.benches" in loaded
    assert not {"hardware_mocks.pty_port", "hardware_mocks.hammer_device",
                "hardware_mocks.bench_process"} & set(loaded)


def test_unavailable_without_openpty(monkeypatch: pytest.MonkeyPatch) -> None:
    assert app.mockbench.unavailable() == ""  # this test machine runs the mock bench
    monkeypatch.delattr(os, "openpty")
    why = app.mockbench.unavailable()
    assert "pseudo-terminals" in why and "station file" in why


def test_mock_verbs_refuse_in_one_line(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(app.mockbench, "unavailable", lambda: "no pseudo-terminals here")
    for argv in (["acquire", "--mock", "--out", str(tmp_path / "run.h5")], ["mock-bench"],
                 ["demo"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "no pseudo-terminals here" in err, argv
    assert not (tmp_path / "run.h5").exists()
