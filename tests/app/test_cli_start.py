"""``insitu --help`` lists every verb without loading any: numpy, scipy and the verbs'
modules load only for the verb that runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

_HELP = """
import contextlib, io, sys
from app.cli.main import main
with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):
    main(sys.argv[1:])
loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("numpy", "scipy", "processing")
                or m.startswith("app.cli."))
print(" ".join(loaded))
print(out.getvalue().count("\\n    "), file=sys.stderr)
"""


def _loaded(*argv: str) -> tuple[set[str], str]:
    out = subprocess.run([sys.executable, "-c", _HELP, *argv], capture_output=True, text=True,
                         timeout=120, cwd=Path(__file__).parents[2], check=True)
    return set(out.stdout.split()), out.stderr


def test_help_lists_the_verbs_without_loading_them() -> None:
    loaded, listed = _loaded("--help")
    assert loaded == {"app.cli.common", "app.cli.main"}, loaded
    assert int(listed) == 11  # one line each


def test_a_verb_loads_what_it_uses() -> None:
    loaded, _ = _loaded("repair", "--help")
    assert "app.cli.repair" in loaded and "app.cli.identify" not in loaded
    assert not any(m.startswith("scipy.signal") for m in loaded)
