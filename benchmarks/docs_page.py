"""docs/benchmarks.md: one section per benchmark script, each rewritten only by its own.

A section runs from its marker line ``<!-- written by benchmarks/NAME.py -->`` to the next
marker; a script writes its section with :func:`write_section` and leaves the others as they
are.
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "benchmarks.md"
HEAD = ("# Benchmarks\n\nEach section is written by the benchmark script it names "
        "(`--write-docs`); run it again to refresh that section.\n")


def machine() -> str:
    """The CPU model, cores, system and Python, in one line."""
    cpu = platform.processor()
    info = Path("/proc/cpuinfo")
    if info.exists():
        cpu = next((line.split(":", 1)[1].strip() for line in info.read_text().splitlines()
                    if line.startswith("model name")), cpu)
    return (f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}")


def provenance(script: str) -> list[str]:
    """Date, machine, command and load average, as list items."""
    return [f"- date: {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC",
            f"- machine: {machine()}",
            f"- command: `{' '.join(['.venv/bin/python', script, *sys.argv[1:]])}`",
            f"- load average (1 min) when written: {os.getloadavg()[0]:.1f} on "
            f"{os.cpu_count()} cores"]


def marker(script: str) -> str:
    return f"<!-- written by {script} -->"


def write_section(script: str, body: str, page: Path = PAGE) -> None:
    """Replace ``script``'s section of ``page`` with ``body`` (appended when absent)."""
    text = page.read_text() if page.exists() else HEAD
    lines = text.splitlines()
    mark = marker(script)
    start = next((k for k, line in enumerate(lines) if line == mark), None)
    new = [mark, *body.strip("\n").splitlines(), ""]
    if start is None:
        lines = [*lines, "", *new] if lines else new
    else:
        end = next((k for k in range(start + 1, len(lines))
                    if lines[k].startswith("<!-- written by ")), len(lines))
        lines = [*lines[:start], *new, *lines[end:]]
    page.write_text("\n".join(lines).rstrip("\n") + "\n")
