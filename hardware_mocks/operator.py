"""A simulated operator arm: hits the mock hammer where an acquisition procedure asks.

It is a listener of a procedure (duck-typed: ``on_next_point``, ``on_hit``): on
each new point it hits there, and after each hit it hits again until the
procedure reports the point complete. Faults can be scripted by hit number
(double hits, overloads) for tests and demos.

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

from hardware_mocks.hammer_device import HammerDevice

__all__ = ["MockOperator"]

logger = logging.getLogger(__name__)

FAULTS = ("double", "overload")


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
    """

    def __init__(self, hammer: HammerDevice, *, peak: float = 200.0, duration: float = 0.004,
                 pause: float = 0.2, faults: Mapping[int, str] | None = None,
                 overload_peak: float = 3000.0) -> None:
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

    def exc_index(self, point: Any) -> int:
        """The bench excitation DOF of a plan point (by node, then closest direction)."""
        bench = self.hammer.physics.bench
        cand = np.flatnonzero(bench.exc_nodes == int(point.node))
        if cand.size == 0:
            raise ValueError(f"the bench has no excitation node {point.node}")
        d = np.asarray(point.direction, dtype=float)
        return int(cand[np.argmax(bench.exc_dirs[cand] @ d)])

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

    # -- listener callbacks --------------------------------------------------------------------
    def on_next_point(self, point: Any) -> None:
        self.points.append(int(point.index))
        self._current = point
        self.hit(point)

    def on_hit(self, hit: Any) -> None:
        if hit.override:  # an operator's override is not a new hit
            return
        if not hit.point_complete and self._current is not None:
            self.hit(self._current)

    def shutdown(self) -> None:
        """Stop hitting (idempotent)."""
        with self._lock:
            self._closed = True
