"""Sample buffering shared by the streaming drivers.

A driver's reader thread appends decoded samples (and NaN for samples it knows
were lost) to a :class:`SampleBuffer`; ``read_block`` takes them out in order.
The buffer also keeps ``(host time, sample count)`` pairs, one per frame, from
which :mod:`drivers.sync` estimates the device clock. A reader thread that dies
stores its exception in the buffer, and the next ``take`` raises it (python-can's
``Notifier`` thread can die silently; ours cannot).

A device is taken for silent when the reader heard nothing from it for the stall
time *while it was listening*: the reader marks the start of each poll of its
transport (:meth:`SampleBuffer.polled`), and the silence counts up to the start of
the latest poll that has been handed over. A reader that did not run (a loaded
host, a process stopped for a while, a thread holding the GIL) therefore does not
make a device look silent: the samples that arrived meanwhile wait in the transport
and are read first.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from drivers.errors import DeviceError, DeviceTimeoutError

__all__ = ["SampleBuffer"]


class SampleBuffer:
    """Thread-safe FIFO of samples ``(n_channels, n)`` with lost-sample and overload marks.

    Parameters
    ----------
    n_channels : int
    name : str
        Device name for error messages.
    max_pairs : int
        How many timing pairs to keep (oldest dropped first).
    """

    def __init__(self, n_channels: int, name: str, max_pairs: int = 20000) -> None:
        self.n_channels = n_channels
        self.name = name
        self._cond = threading.Condition()
        self._chunks: deque[tuple[NDArray[np.float64], frozenset[int]]] = deque()
        self._buffered = 0
        self._next_out = 0  # device sample index of the first buffered sample
        self._appended = 0  # samples appended since reset
        self._error: BaseException | None = None
        self._last_arrival = time.monotonic()
        self._listened: float | None = None  # start of the reader's latest poll handed over
        self._pairs: deque[tuple[float, int]] = deque(maxlen=max_pairs)

    def reset(self) -> None:
        with self._cond:
            self._chunks.clear()
            self._buffered = self._next_out = self._appended = 0
            self._error = None
            self._last_arrival = time.monotonic()
            self._listened = None
            self._pairs.clear()

    # -- producer side (reader thread) ----------------------------------------------------------
    def append(self, data: NDArray[np.float64], host_time: float | None = None,
               overloaded: frozenset[int] = frozenset()) -> None:
        """Add samples (n_channels, k); ``host_time`` is when the frame that ended them arrived;
        ``overloaded`` holds the row indices the device flagged."""
        data = np.asarray(data, dtype=np.float64).reshape(self.n_channels, -1)
        with self._cond:
            self._chunks.append((data, overloaded))
            self._buffered += data.shape[1]
            self._appended += data.shape[1]
            self._last_arrival = time.monotonic()
            if host_time is not None:
                self._pairs.append((host_time, self._appended))
            self._cond.notify_all()

    def append_missing(self, n: int) -> None:
        """Add ``n`` NaN sample instants for samples the device sent but we did not get."""
        if n > 0:
            with self._cond:
                nan = np.full((self.n_channels, n), np.nan)
                self._chunks.append((nan, frozenset()))
                self._buffered += n
                self._appended += n
                self._cond.notify_all()

    def fail(self, error: BaseException) -> None:
        """Record the reader thread's fatal error; the next ``take`` raises it."""
        with self._cond:
            self._error = error
            self._cond.notify_all()

    def touch(self) -> None:
        """Note that the device is alive even though no samples came (e.g. a status frame)."""
        with self._cond:
            self._last_arrival = time.monotonic()

    def polled(self, started: float) -> None:
        """The reader polled its transport from host time ``started`` (``time.monotonic()``,
        taken before the poll) and has handed over whatever came: the device has been
        silent at least from the last arrival until ``started``.

        A reader that never calls this leaves the silence counted up to now.
        """
        with self._cond:
            self._listened = started

    # -- consumer side --------------------------------------------------------------------------
    @property
    def appended(self) -> int:
        return self._appended

    def taken_by(self, k: int, fs: float, recent: int = 64) -> float | None:
        """Host time by which sample ``k`` (counted since the reset) had been taken, s: the
        tightest of the ``recent`` latest frames' bounds (a frame ending sample ``c - 1``
        arrived at ``t``, so sample ``k`` was taken by ``t - (c - 1 - k) / fs``); None
        before any frame. Late frames loosen no bound: the earliest arrival decides. The
        lower envelope :func:`drivers.sync.fit_clock` fits over a whole run, taken here
        at the nominal rate over the latest frames, without a fit: cheap for every read."""
        with self._cond:
            if not self._pairs:
                return None
            last = list(itertools.islice(reversed(self._pairs), recent))
        return min(t - (c - 1 - k) / fs for t, c in last)

    def pairs(self) -> list[tuple[float, int]]:
        """``(host arrival time, samples received so far)`` per frame, oldest first."""
        with self._cond:
            return list(self._pairs)

    def take(self, n: int, timeout: float, stall_timeout: float
             ) -> tuple[NDArray[np.float64], int, int, frozenset[int]]:
        """The next ``n`` samples: ``(data, first index, n missing, overloaded rows)``.

        A sample instant counts as missing when any channel is NaN there.

        Raises the reader's error if it died, or :class:`DeviceTimeoutError` when
        ``timeout`` s pass or nothing at all arrives for ``stall_timeout`` s while the
        reader listens (see :meth:`polled`).
        """
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._buffered < n:
                if self._error is not None:
                    err = self._error
                    if isinstance(err, DeviceError):
                        raise err
                    raise DeviceError(f"{self.name}: reader thread failed: {err!r}",
                                      self.name) from err
                now = time.monotonic()
                heard = now if self._listened is None else self._listened
                if heard - self._last_arrival > stall_timeout:
                    raise DeviceTimeoutError(
                        f"{self.name}: no data for {heard - self._last_arrival:.2f} s "
                        f"(device stopped answering?)", self.name)
                if now >= deadline:
                    raise DeviceTimeoutError(
                        f"{self.name}: only {self._buffered} of {n} samples within "
                        f"{timeout:g} s", self.name)
                self._cond.wait(min(deadline - now, stall_timeout / 4, 0.05))
            out = np.empty((self.n_channels, n))
            overloaded: set[int] = set()
            filled = 0
            while filled < n:
                chunk, ovl = self._chunks[0]
                k = min(n - filled, chunk.shape[1])
                out[:, filled:filled + k] = chunk[:, :k]
                overloaded |= ovl
                if k == chunk.shape[1]:
                    self._chunks.popleft()
                else:
                    self._chunks[0] = (chunk[:, k:], ovl)
                filled += k
            first = self._next_out
            self._next_out += n
            self._buffered -= n
        missing = int(np.count_nonzero(np.isnan(out).any(axis=0)))
        return out, first, missing, frozenset(overloaded)


class ReaderThread:
    """A streaming device's background reader thread: started for each run, asked to stop
    and joined idempotently (also from the reader itself, which then does not wait).

    Parameters
    ----------
    name : str
        Device name; the thread is called ``"<name>-reader"``.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, target: Callable[[], None]) -> None:
        """Run ``target`` in a new daemon thread."""
        self._stop.clear()
        self._thread = threading.Thread(target=target, name=f"{self.name}-reader", daemon=True)
        self._thread.start()

    @property
    def stopping(self) -> bool:
        """True once :meth:`join` asked the reader to end."""
        return self._stop.is_set()

    def is_alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def join(self, timeout: float = 1.0) -> None:
        """Ask the reader to end and wait up to ``timeout`` s for it (idempotent)."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)

