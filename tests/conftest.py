"""Session-wide settings: the command line's log file goes to a temporary folder (removed
when the process ends), one OpenBLAS thread a process, and SIGINT is Python's own handler
again when the suite was started with it ignored."""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import tempfile
from pathlib import Path

import pytest

_LOGS = Path(tempfile.mkdtemp(prefix="insitu-log-"))
atexit.register(shutil.rmtree, _LOGS, ignore_errors=True)  # one a worker: none left behind
os.environ.setdefault("INSITU_LOG", str(_LOGS / "insitu.log"))

# One OpenBLAS thread in every worker (and every process a test starts; set before the
# workers start, as OpenBLAS reads it when it loads): the workers run two a core, so a
# second BLAS thread in each only spins against the others, as processing/blas.py found
# for the fits. Measured on 2 cores, 4 workers: the reference-model, stiffening and
# uncertainty tests took 130 s with two threads each, 19 s with one.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# A suite started in the background by a script (``make test &`` in sh, a CI runner without
# job control) inherits SIGINT ignored, and so would every process it starts: the tests
# that stop ``insitu acquire`` as an operator's Ctrl-C does would then wait for nothing.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The ``slow`` tests (the real-time runs on the mock benches, tens of seconds each, most
    of it waiting on the bench's clock) spread evenly over the first three quarters of the
    others, each group in its own order. With ``--maxschedchunk 1`` the workers take the
    tests one or two at a time, so about as many workers wait on a bench as compute beside
    them, from the start to near the end: the cores stay busy, and no long test is left for
    one worker to finish alone at the end (all of them first left the cores half idle while
    the benches ran, then all busy)."""
    slow = [item for item in items if item.get_closest_marker("slow") is not None]
    rest = [item for item in items if item.get_closest_marker("slow") is None]
    step = 0.75 * len(rest) / max(len(slow), 1)
    out: list[pytest.Item] = []
    taken = 0  # of the others, placed so far
    for k, item in enumerate(slow):
        upto = max(taken, round(k * step))
        out.extend(rest[taken:upto])
        out.append(item)
        taken = upto
    out.extend(rest[taken:])
    items[:] = out


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: two workers per core free, at most two per core and at least one.

    Most of the long tests wait on real-time mock benches, so two workers share a core
    well on a quiet machine; on a busy one fewer workers keep the benches' streams in time.
    Free cores as :func:`processing.spectral.free_cores` counts them (the runnable threads
    of ``/proc/loadavg``), the most of ten readings over half a second: a process that runs
    for a moment (the lint just finished, a compiler) does not take a core away."""
    import time

    from processing.spectral import free_cores

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
    free = 0
    for _ in range(10):
        free = max(free, free_cores())
        time.sleep(0.05)
    return max(1, min(2 * cores, 2 * free))
