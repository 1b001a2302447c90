"""Shared settings of the fuzz tests: a few hundred examples in ``make test``.

``benchmarks/fuzz.py`` runs the same tests with ``INSITU_FUZZ_EXAMPLES=10000``.
"""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator

from hypothesis import HealthCheck, settings

EXAMPLES = int(os.environ.get("INSITU_FUZZ_EXAMPLES", "200"))

FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
#: for examples that write and read whole files with pyuff (about 0.2 s each)
FUZZ_SLOW = settings(FUZZ, max_examples=max(10, EXAMPLES // 5))


@contextlib.contextmanager
def no_hang(seconds: float = 10.0) -> Iterator[None]:
    """Fail the example (TimeoutError) if the code under test runs longer than ``seconds``."""
    def _alarm(signum: int, frame: object) -> None:
        raise TimeoutError(f"hung for more than {seconds} s")

    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
