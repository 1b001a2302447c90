"""Ctrl-C in the terminal of ``insitu gui`` closes the window through its close path and
ends the process (exit status 0), instead of being ignored while Qt's loop runs."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

#: the GUI as `insitu gui` starts it, printing "ready" once Qt's event loop runs
START = ("import sys\n"
         "from PySide6 import QtCore, QtWidgets\n"
         "app = QtWidgets.QApplication(['insitu'])\n"
         "QtCore.QTimer.singleShot(500, lambda: print('ready', flush=True))\n"
         "from app.cli.main import main\n"
         "sys.exit(main(['gui']))\n")


def test_sigint_closes_the_gui(tmp_path: Path) -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "HOME": str(tmp_path),
           "XDG_CONFIG_HOME": str(tmp_path / "config"), "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", START], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()  # the loop runs
        assert line.strip() == "ready", proc.stderr.read() if proc.stderr else ""
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=15)  # a hang is the bug
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "KeyboardInterrupt" not in err and "Traceback" not in err
    # the close path ran: it saved the settings
    assert (tmp_path / "config" / "insitu" / "insitu.conf").is_file(), err
