"""One BLAS thread for the numerics of a measurement.

Loading, hit processing and the fit work on small matrices (6 x 6 to 10 x 10, stacked over
lines; the decay fits' least squares): a second BLAS thread gains nothing there, and beside
another busy process its spinning made a hammer run's fit 30 times slower (155 s against
4.8 s) and a hammer time UFF's load 20 times slower (``lstsq`` of the decay fits), measured
on 2 cores. The public entry points that do this work (:func:`processing.identify.fit`,
``app.pipeline.load``, the acquisition's analysis) run under :func:`one_blas_thread`; the
caller's own setting is restored after.

The BLAS libraries are found once, at the first call (numpy's and scipy's, both loaded
then): finding them reads the process's memory map, 1-2 ms a call, and the entry points nest
and run per hit.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import ThreadpoolController

__all__ = ["BLAS_THREADS", "one_blas_thread"]

#: BLAS threads inside :func:`one_blas_thread`
BLAS_THREADS = 1

_P = ParamSpec("_P")
_R = TypeVar("_R")

@functools.cache
def _blas() -> ThreadpoolController:
    """The process's BLAS libraries, listed at the first call."""
    import scipy.linalg  # noqa: F401  (its BLAS loaded before the libraries are listed)

    return ThreadpoolController()


def one_blas_thread(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """``fn`` run with :data:`BLAS_THREADS` BLAS threads (the caller's count restored)."""

    @functools.wraps(fn)
    def limited(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with _blas().limit(limits=BLAS_THREADS, user_api="blas"):
            return fn(*args, **kwargs)

    return limited
