"""Session-wide settings: the command line's log file goes to a temporary folder, and
SIGINT is Python's own handler again when the suite was started with it ignored."""

from __future__ import annotations

import os
import signal
import tempfile
from pathlib import Path

_LOGS = Path(tempfile.mkdtemp(prefix="insitu-log-"))
os.environ.setdefault("INSITU_LOG", str(_LOGS / "insitu.log"))

# A suite started in the background by a script (``make test &`` in sh, a CI runner without
# job control) inherits SIGINT ignored, and so would every process it starts: the tests
# that stop ``insitu acquire`` as an operator's Ctrl-C does would then wait for nothing.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
