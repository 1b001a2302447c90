"""Session-wide settings: the command line's log file goes to a temporary folder."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

_LOGS = Path(tempfile.mkdtemp(prefix="insitu-log-"))
os.environ.setdefault("INSITU_LOG", str(_LOGS / "insitu.log"))
