"""A Dask distributed client: a local cluster of worker processes, or a running scheduler."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

from distributed import Client, LocalCluster

__all__ = ["SchedulerError", "open_client", "total_threads"]

#: seconds to wait for a scheduler given by address before giving up
CONNECT_TIMEOUT = 10.0


class SchedulerError(OSError):
    """The scheduler at the given address did not answer (one line, exit status 2)."""


@contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None,
                threads_per_worker: int = 1,
                timeout: float | None = None) -> Iterator[Client]:
    """A client on a running scheduler, or on a local cluster started here and shut down on exit.

    Parameters
    ----------
    scheduler : address of a running scheduler (``tcp://host:port``), or None for a local
        cluster of worker processes (no set-up)
    workers : local cluster: number of worker processes (default: one per core)
    threads_per_worker : local cluster: threads of each worker (1: each task has its core; the
        numerics of one file are not shared between threads)
    timeout : seconds to wait for ``scheduler`` to answer (default :data:`CONNECT_TIMEOUT`)

    Raises
    ------
    SchedulerError
        ``scheduler`` did not answer within ``timeout``, with what to do.
    ValueError
        ``workers`` below 1.
    """
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be at least 1, got {workers}")
    if scheduler is not None:
        timeout = CONNECT_TIMEOUT if timeout is None else timeout
        try:
            client = Client(scheduler, timeout=timeout)
        except (OSError, ValueError, TypeError) as err:  # TimeoutError is an OSError
            first = (str(err).splitlines() or [type(err).__name__])[0]
            raise SchedulerError(
                f"no Dask scheduler answered at {scheduler} within {timeout:g} s ({first}): "
                "start one with `dask scheduler` and workers with `dask worker ADDRESS`, or "
                "leave out --scheduler for a local cluster") from err
        try:
            yield client
        finally:
            client.close()
        return
    cluster = LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker,
                           processes=True, dashboard_address=None,
                           # the scheduler's HTTP server (health, metrics) on any free port:
                           # a fixed 8787 collides with a second batch on the same machine
                           scheduler_kwargs={"dashboard_address": ":0"},
                           silence_logs=logging.ERROR)
    try:
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def total_threads(client: Client) -> int:
    """Threads over all the client's workers (at least 1)."""
    return max(1, sum(client.nthreads().values()))
