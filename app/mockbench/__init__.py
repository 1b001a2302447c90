"""The mock bench wired to the real drivers, kept apart from the production chain.

Only the mock-bench entry points import this package and :mod:`hardware_mocks`: the
command-line verbs ``demo``, ``mock-bench``, ``simulate`` and ``acquire --mock`` /
``--mock-operator``, and the GUI's "Use mock bench" option (import-linter contract
"Only the mock-bench entry points import hardware_mocks" in ``pyproject.toml``).

- :mod:`app.mockbench.bench`: :func:`~app.mockbench.bench.plan_for_bench` (the test plan
  of a built-in bench) and :class:`~app.mockbench.bench.InProcessBench` (simulated front
  end, hammer digitiser and shaker on one shared physics, the station that connects the
  drivers to them, and simulated operators);
- here, without importing any simulator: :func:`unavailable` (why the in-process bench
  cannot run on this machine) and :func:`bench_names`.
"""

from __future__ import annotations

import os

__all__ = ["bench_names", "unavailable"]


def unavailable() -> str:
    """Why the in-process mock bench cannot run here, or ``""`` when it can.

    Its hammer digitiser and shaker are serial devices on pseudo-terminals
    (:mod:`hardware_mocks.pty_port`), which only POSIX systems have.
    """
    if os.name != "posix" or not hasattr(os, "openpty"):
        return (f"the mock bench needs pseudo-terminals for its serial devices, which this "
                f"system ({os.name}) does not have: use a station file, or run the mock "
                "bench on Linux or macOS")
    return ""


def bench_names() -> list[str]:
    """The built-in benches' names, sorted (:data:`hardware_mocks.benches.BENCHES`)."""
    from hardware_mocks.benches import BENCHES

    return sorted(BENCHES)
