"""A simulated operator: hits the mock hammer, or moves the mock shaker, where a procedure asks.

:class:`MockOperator` is a listener of a procedure (duck-typed: ``on_next_point``,
``on_hit``): on each new point it hits there, and after each hit it hits again
until the procedure reports the point complete. A hit the procedure never
reports (its trigger lost in corrupted frames) is repeated after ``patience``
s, as an operator who saw nothing happen would. Faults can be scripted by hit
number (double hits, overloads) for tests and demos. :class:`MockShakerOperator`
attaches the mock shaker's stinger at each point the shaker procedure announces.

Example
-------
>>> op = MockOperator(hammer_device, faults={1: "double"})  # doctest: +SKIP
>>> proc.add_listener(op)  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping
from typing import Any

import numpy as np

from hardware_mocks.benches import Bench
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.shaker_device import ShakerDevice

__all__ = ["MockOperator", "MockShakerOperator", "excitation_index"]

logger = logging.getLogger(__name__)

FAULTS = ("double", "overload")


def excitation_index(bench: Bench, point: Any) -> int:
    """The bench excitation DOF of a plan point (by node, then the closest direction)."""
    cand = np.flatnonzero(bench.exc_nodes == int(point.node))
    if cand.size == 0:
        raise ValueError(f"the bench has no excitation node {point.node}")
    d = np.asarray(point.direction, dtype=float)
    return int(cand[np.argmax(bench.exc_dirs[cand] @ d)])


class MockOperator:
    """Hits the bench of ``hammer`` at the excitation point the procedure announces.

    Parameters
    ----------
    hammer : HammerDevice
        The mock hammer (its physics has the bench and its excitation DOFs).
    peak : float
        Peak force of a normal hit, N.
    duration : float
        Pulse duration, s.
    pause : float
        Delay between the procedure's request and the hit, s (lets the last one ring out).
    faults : mapping of int to str
        By hit number (0-based, over the run): ``"double"`` (a rebound 12 ms later at 40 %),
        or ``"overload"`` (``overload_peak`` N).
    overload_peak : float
        Peak force of an overloading hit, N.
    patience : float
        Seconds without a reported hit after which the last hit is repeated (0: never).
    """

    def __init__(self, hammer: HammerDevice, *, peak: float = 200.0, duration: float = 0.004,
                 pause: float = 0.2, faults: Mapping[int, str] | None = None,
                 overload_peak: float = 3000.0, patience: float = 8.0) -> None:
        for k, v in (faults or {}).items():
            if v not in FAULTS:
                raise ValueError(f"fault {v!r} for hit {k}: choose one of {', '.join(FAULTS)}")
        self.hammer = hammer
        self.peak, self.duration, self.pause = peak, duration, pause
        self.faults = dict(faults or {})
        self.overload_peak = overload_peak
        self.hits_made = 0
        self.points: list[int] = []
        self._lock = threading.Lock()
        self._closed = False
        self._current: Any = None
        self.patience = patience
        self.repeats = 0
        self._seen: set[int] = set()
        self._timer: threading.Timer | None = None

    def exc_index(self, point: Any) -> int:
        """The bench excitation DOF of a plan point (by node, then closest direction)."""
        return excitation_index(self.hammer.physics.bench, point)

    def _watch(self, point: Any) -> None:
        """(Re)start the wait for the procedure to report the hit just made."""
        self._cancel()
        if self.patience <= 0:
            return
        timer = threading.Timer(self.patience, self._repeat, (point,))
        timer.daemon = True
        with self._lock:
            if self._closed:
                return
            self._timer = timer
        timer.start()

    def _cancel(self) -> None:
        with self._lock:
            timer, self._timer = self._timer, None
        if timer is not None:
            timer.cancel()

    def _repeat(self, point: Any) -> None:
        logger.info("operator: no hit reported for %.1f s; hitting again", self.patience)
        self.repeats += 1
        self.hit(point)

    def hit(self, point: Any) -> None:
        """Hit at ``point`` after :attr:`pause` s, with the fault scripted for this hit."""
        with self._lock:
            if self._closed:
                return
            n = self.hits_made
            self.hits_made += 1
        fault = self.faults.get(n)
        exc = self.exc_index(point)
        logger.debug("operator: hit %d at excitation %d%s", n, exc, f" ({fault})" if fault else "")
        peak = self.overload_peak if fault == "overload" else self.peak
        double = (0.012, 0.4) if fault == "double" else None
        self.hammer.hit(exc=exc, peak=peak, duration=self.duration, double=double,
                        delay=self.pause)
        self._watch(point)

    # -- listener callbacks --------------------------------------------------------------------
    def on_next_point(self, point: Any) -> None:
        self.points.append(int(point.index))
        self._current = point
        self.hit(point)

    def on_hit(self, hit: Any) -> None:
        hit_id = getattr(hit, "hit_id", None)
        # an operator's override (or the clearing of one) re-reports a hit: not a new hit
        if hit.override or (hit_id is not None and hit_id in self._seen):
            return
        if hit_id is not None:
            self._seen.add(hit_id)
        self._cancel()
        if not hit.point_complete and self._current is not None:
            self.hit(self._current)

    def on_paused(self, reason: str) -> None:
        self._cancel()  # no hitting while the run waits

    def on_finished(self, state: Any) -> None:
        self._cancel()

    def shutdown(self) -> None:
        """Stop hitting (idempotent)."""
        with self._lock:
            self._closed = True
            timer, self._timer = self._timer, None
        if timer is not None:
            timer.cancel()
            if timer is not threading.current_thread():
                timer.join(1.0)


class MockShakerOperator:
    """Attaches the mock shaker at each point the shaker procedure announces.

    Parameters
    ----------
    shaker : ShakerDevice
        The mock shaker, on the bench's physics.
    """

    def __init__(self, shaker: ShakerDevice) -> None:
        if shaker.physics is None:
            raise ValueError("the mock shaker has no bench (physics=None)")
        self.shaker = shaker
        self.points: list[int] = []

    def on_next_point(self, point: Any) -> None:
        assert self.shaker.physics is not None
        exc = excitation_index(self.shaker.physics.bench, point)
        logger.debug("operator: shaker attached at excitation %d", exc)
        self.points.append(int(point.index))
        self.shaker.attach(exc)

    def on_finished(self, state: Any) -> None:
        self.shaker.attach(None)
