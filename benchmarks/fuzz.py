"""Fuzz every decoder at length: the tests of ``tests/fuzz`` with many examples each.

    .venv/bin/python benchmarks/fuzz.py [--examples 10000]

Runs ``pytest tests/fuzz`` with ``INSITU_FUZZ_EXAMPLES`` set (``make test`` runs the same
tests with 200) and prints, per test, the examples asked for, the outcome and the time.
An escape (an exception other than the decoder's own one-line error, or a hang) fails
the test and is printed with the smallest input hypothesis found.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=10_000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        xml = Path(d) / "fuzz.xml"
        env = {**os.environ, "INSITU_FUZZ_EXAMPLES": str(args.examples)}
        proc = subprocess.run([sys.executable, "-m", "pytest", "tests/fuzz", "-q",
                               "-p", "no:cacheprovider", f"--junitxml={xml}"],
                              cwd=ROOT, env=env, capture_output=True, text=True)
        cases = ET.parse(xml).getroot().iter("testcase")
        table = Table(title=f"fuzzing, {args.examples} examples per test "
                            "(the pyuff round trips: a fifth)")
        for col in ("decoder", "test", "examples", "escapes", "time s"):
            table.add_column(col)
        for c in cases:
            failed = c.find("failure") is not None or c.find("error") is not None
            name = c.get("name", "")
            slow = "reordered" in name
            table.add_row(c.get("classname", "").split(".")[-1].removeprefix("test_fuzz_"),
                          name.removeprefix("test_"),
                          str(max(10, args.examples // 5) if slow else args.examples),
                          "[red]1+[/red]" if failed else "0", f"{float(c.get('time', 0)):.0f}")
    Console().print(table)
    if proc.returncode:
        print(proc.stdout[-4000:])
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
