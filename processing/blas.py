"""One BLAS thread for the numerics of a measurement.

Loading, hit processing and the fit work on small matrices (6 x 6 to 10 x 10, stacked over
lines; the decay fits' least squares): a second BLAS thread gains nothing there, and beside
another busy process its spinning made a hammer run's fit 30 times slower (155 s against
4.8 s) and a hammer time UFF's load 20 times slower (``lstsq`` of the decay fits), measured
on 2 cores. The public entry points that do this work (:func:`processing.identify.fit`,
``app.pipeline.load``, the acquisition's analysis) run under :func:`one_blas_thread`; the
caller's own setting is restored after.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

__all__ = ["BLAS_THREADS", "one_blas_thread"]

#: BLAS threads inside :func:`one_blas_thread`
BLAS_THREADS = 1

_P = ParamSpec("_P")
_R = TypeVar("_R")


class _Limit:
    """The limit, set when the first limited call begins and restored when the last one
    ends: a limited call inside another (a run file's hits inside its load, from any
    thread) costs a counter, not a scan of the loaded libraries (0.7 ms each)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.depth = 0
        self.active: threadpool_limits | None = None

    def enter(self) -> None:
        with self.lock:
            if self.depth == 0:
                self.active = threadpool_limits(BLAS_THREADS, user_api="blas")
            self.depth += 1

    def exit(self) -> None:
        with self.lock:
            self.depth -= 1
            if self.depth == 0 and self.active is not None:
                self.active.restore_original_limits()
                self.active = None


_LIMIT = _Limit()


def one_blas_thread(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """``fn`` run with :data:`BLAS_THREADS` BLAS threads (the caller's count restored when
    the outermost limited call ends)."""

    @functools.wraps(fn)
    def limited(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        _LIMIT.enter()
        try:
            return fn(*args, **kwargs)
        finally:
            _LIMIT.exit()

    return limited
