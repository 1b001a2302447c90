"""A simulated operator: hits the mock hammer, or moves the mock shaker, where a procedure asks.

:class:`MockOperator` is a listener of a procedure (duck-typed: ``on_next_point``,
``on_hit``): on each new point it hits there, and after each hit it hits again
until the procedure reports the point complete. A hit the procedure never
reports (its trigger lost in corrupted frames) is repeated once the procedure has
read ``patience`` s of data since, as an operator who saw nothing happen would: the
wait runs on the data the run reads (``on_samples``), not on the wall clock, and
counts only the samples taken after the hit landed (a block's ``t_first``), so a loaded
machine that is slow to judge a hit, or reads a backlog of older samples, does not get it
twice. Faults can be scripted by hit number (double hits, overloads) for tests and demos.
:class:`MockShakerOperator` attaches the mock shaker's stinger at each point the shaker
procedure announces.

:class:`RemoteOperator` and :class:`RemoteShakerOperator` do the same to a mock
bench in another process (``insitu mock-bench``), through its control channel
(:class:`~hardware_mocks.bench_control.BenchControl`): what ``insitu acquire
--mock-operator`` attaches. A request the bench refuses, or a bench that went away,
is kept in their ``error`` (they stop acting), never raised into the procedure.

Example
-------
>>> op = MockOperator(hammer_device, faults={1: "double"})  # doctest: +SKIP
>>> proc.add_listener(op)  # doctest: +SKIP
>>> with BenchControl.from_station("bench.toml") as control:  # doctest: +SKIP
...     proc.add_listener(RemoteOperator(control))
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable, Mapping
from typing import Any, Protocol

import numpy as np

from hardware_mocks.bench_control import BenchControl, BenchControlError
from hardware_mocks.bench_drive import BenchDrive
from hardware_mocks.benches import Bench, get_bench
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.physics import TIP_DURATION, TIP_PEAK

__all__ = ["MockOperator", "MockShakerOperator", "RemoteOperator", "RemoteShakerOperator",
           "check_points", "excitation_index"]

logger = logging.getLogger(__name__)

FAULTS = ("double", "overload")
#: a plan direction at most this far (cosine) from the bench's excitation is the same DOF
SAME_DIRECTION = 0.999


class Hammer(Protocol):
    """What hits the bench: the in-process :class:`HammerDevice` or a :class:`BenchControl`."""

    def hit(self, exc: int = 0, peak: float = TIP_PEAK, *, duration: float = TIP_DURATION,
            delay: float = 0.05, double: tuple[float, float] | None = None) -> Any: ...


def excitation_index(bench: Bench, point: Any) -> int:
    """The bench excitation DOF of a plan point (by node, then the closest direction)."""
    cand = np.flatnonzero(bench.exc_nodes == int(point.node))
    if cand.size == 0:
        raise ValueError(f"the bench has no excitation node {point.node}")
    d = np.asarray(point.direction, dtype=float)
    return int(cand[np.argmax(bench.exc_dirs[cand] @ d)])


def check_points(bench: Bench, points: Iterable[Any]) -> list[int]:
    """The bench excitation DOF of every plan point; ValueError (one line) for a point the
    bench cannot be excited at: an unknown node, or a direction off the bench's there."""
    out = []
    for p in points:
        label = getattr(p, "label", f"node {p.node}")
        try:
            j = excitation_index(bench, p)
        except ValueError as err:
            nodes = ", ".join(str(n) for n in dict.fromkeys(bench.exc_nodes.tolist()))
            raise ValueError(f"{label}: {err} (it has {nodes})") from None
        d = np.asarray(p.direction, dtype=float)
        if bench.exc_dirs[j] @ d / np.linalg.norm(d) < SAME_DIRECTION:
            dirs = "; ".join(f"[{', '.join(f'{x:g}' for x in bench.exc_dirs[k])}]"
                             for k in np.flatnonzero(bench.exc_nodes == int(p.node)))
            raise ValueError(f"{label}: the bench excites node {p.node} only along {dirs}")
        out.append(j)
    return out


class MockOperator:
    """Hits the bench of ``hammer`` at the excitation point the procedure announces.

    Parameters
    ----------
    hammer : HammerDevice or Hammer
        The mock hammer (its physics has the bench and its excitation DOFs), or any
        object with its ``hit`` method (then give ``bench``).
    bench : Bench, optional
        The bench hit (default: the in-process hammer's).
    peak : float
        Peak force of a normal hit, N (default: the bench's steel tip,
        :data:`~hardware_mocks.physics.TIP_PEAK`).
    duration : float
        Pulse duration, s (default :data:`~hardware_mocks.physics.TIP_DURATION`).
    pause : float
        Delay between the procedure's request and the hit, s.
    settle : float
        Least time between two hits, s: the operator waits for the bench to ring out (the
        previous hit's response carried into the next record is an error of that record's
        FRF). 0: hit ``pause`` s after each request.
    faults : mapping of int to str
        By hit number (0-based, over the run): ``"double"`` (a rebound 12 ms later at 40 %),
        or ``"overload"`` (``overload_peak`` N).
    overload_peak : float
        Peak force of an overloading hit, N.
    patience : float
        Seconds of data the procedure reads after a hit without reporting it, after which
        the hit is repeated (0: never).
    """

    def __init__(self, hammer: HammerDevice | Hammer, *, bench: Bench | None = None,
                 peak: float = TIP_PEAK, duration: float = TIP_DURATION, pause: float = 0.2,
                 faults: Mapping[int, str] | None = None, overload_peak: float = 3000.0,
                 patience: float = 8.0, settle: float = 0.0) -> None:
        for k, v in (faults or {}).items():
            if v not in FAULTS:
                raise ValueError(f"fault {v!r} for hit {k}: choose one of {', '.join(FAULTS)}")
        if bench is None:
            if not isinstance(hammer, HammerDevice):
                raise ValueError("give the bench hit by this hammer (bench=...)")
            bench = hammer.physics.bench
        self.hammer = hammer
        self.bench = bench
        self.peak, self.duration, self.pause, self.settle = peak, duration, pause, settle
        self._last_t0: float | None = None
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
        self._waiting: Any = None  # the point of the hit not reported yet
        self._data_seen = 0.0  # s of data the run read since that hit
        self._hit_at = 0.0  # host time that hit lands
        self._overdue = False

    def exc_index(self, point: Any) -> int:
        """The bench excitation DOF of a plan point (by node, then closest direction)."""
        return excitation_index(self.bench, point)

    def _watch(self, point: Any, at: float) -> None:
        """(Re)start the wait for the procedure to report the hit about to land at host
        time ``at``."""
        with self._lock:
            self._waiting = point if self.patience > 0 and not self._closed else None
            self._data_seen, self._overdue, self._hit_at = 0.0, False, at

    def _cancel(self) -> None:
        with self._lock:
            self._waiting = None

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
        now = time.monotonic()
        delay = self.pause
        if self.settle > 0 and self._last_t0 is not None:
            delay = max(delay, self._last_t0 + self.settle - now)
        self._last_t0 = now + delay
        # the wait for the report is armed before the hit can land: on a loaded machine this
        # thread may be held until the hit is reported (even the run finished), whose
        # callbacks then find and cancel it; armed after, it would repeat a reported hit
        self._watch(point, now + delay)
        try:
            self.hammer.hit(exc=exc, peak=peak, duration=self.duration, double=double,
                            delay=delay)
        except BaseException:  # no hit made: nothing to wait for
            self._cancel()
            raise

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

    def on_samples(self, block: Any) -> None:
        """The run read ``block`` (a :class:`~app.acquire.events.SampleBlock`): past
        :attr:`patience` s of data taken after a hit not reported, hit again. Not at the read
        that crosses it, which may hold the hit (a machine slow to read reads much at once),
        but at the next: the run judges what it read before it reads again. A block without
        its samples' time (``t_first`` None) counts whole."""
        with self._lock:
            point = self._waiting
            if point is None:
                return
            span = block.data.shape[-1] / block.fs
            if block.t_first is not None:  # only the samples after the hit landed
                span = min(span, max(0.0, block.t_first + span - self._hit_at))
            self._data_seen += span
            if self._data_seen < self.patience:
                return
            if not self._overdue:
                self._overdue = True
                return
        logger.info("operator: no hit reported in %.1f s of data; hitting again",
                    self._data_seen)
        self.repeats += 1
        self.hit(point)

    def on_paused(self, reason: str) -> None:
        self._cancel()  # no hitting while the run waits

    def on_finished(self, state: Any) -> None:
        self._cancel()

    def shutdown(self) -> None:
        """Stop hitting (idempotent)."""
        with self._lock:
            self._closed = True
            self._waiting = None


class MockShakerOperator:
    """Attaches the mock shaker at each point the shaker procedure announces.

    Parameters
    ----------
    *shakers : BenchDrive
        The mock shakers (SG-1 or 33500 generator mocks), on the bench's physics. With
        ``n`` of them, the plan's points are driven ``n`` at a time
        (:attr:`app.acquire.plan.TestPlan.drives`): point ``index`` gets shaker ``index % n``.
    """

    def __init__(self, *shakers: BenchDrive) -> None:
        if not shakers or any(s.physics is None for s in shakers):
            raise ValueError("the mock shaker has no bench (physics=None)")
        self.shakers = shakers
        self.shaker = shakers[0]
        self.points: list[int] = []

    def on_next_point(self, point: Any) -> None:
        shaker = self.shakers[int(point.index) % len(self.shakers)]
        assert shaker.physics is not None
        exc = excitation_index(shaker.physics.bench, point)
        logger.debug("operator: shaker attached at excitation %d", exc)
        self.points.append(int(point.index))
        shaker.attach(exc)

    def on_finished(self, state: Any) -> None:
        for shaker in self.shakers:
            shaker.attach(None)


class RemoteOperator(MockOperator):
    """A :class:`MockOperator` whose hits go to a mock bench in another process.

    Parameters
    ----------
    control : BenchControl
        Connection to the bench's control channel (``insitu mock-bench``); not closed here.
    bench : Bench, optional
        The bench (default: the built-in one the bench process reports it runs).
    **kwargs
        As :class:`MockOperator` (``peak``, ``pause``, ``faults``, ``patience``...).

    Attributes
    ----------
    error : str
        Empty, or why the bench could not be hit (then the operator has stopped).
    """

    def __init__(self, control: BenchControl, *, bench: Bench | None = None,
                 **kwargs: Any) -> None:
        if bench is None:
            bench = _remote_bench(control)
        super().__init__(control, bench=bench, **kwargs)
        self.control = control
        self.error = ""

    def hit(self, point: Any) -> None:
        if self.error:
            return
        try:
            super().hit(point)
        except BenchControlError as err:
            self.error = str(err)
            logger.error("operator: %s", err)


class RemoteShakerOperator:
    """Attaches the shakers of a mock bench in another process at each point announced.

    Parameters
    ----------
    control : BenchControl
        Connection to the bench's control channel; not closed here.
    bench : Bench, optional
        The bench (default: the one the bench process reports).
    shakers : int
        Shakers the plan drives at once (:attr:`app.acquire.plan.TestPlan.drives`): as
        :class:`MockShakerOperator`, point ``index`` gets shaker ``index % shakers + 1``.

    Attributes
    ----------
    error : str
        Empty, or why the shaker could not be moved.
    """

    def __init__(self, control: BenchControl, *, bench: Bench | None = None,
                 shakers: int = 1) -> None:
        if shakers < 1:
            raise ValueError(f"shakers must be at least 1, not {shakers}")
        self.control = control
        self.bench = bench if bench is not None else _remote_bench(control)
        self.shakers = shakers
        self.points: list[int] = []
        self.error = ""

    def _attach(self, exc: int | None, shaker: int) -> None:
        if self.error:
            return
        try:
            self.control.attach_shaker(exc, shaker)
        except BenchControlError as err:
            self.error = str(err)
            logger.error("operator: %s", err)

    def on_next_point(self, point: Any) -> None:
        exc = excitation_index(self.bench, point)
        shaker = int(point.index) % self.shakers + 1
        logger.debug("operator: shaker %d attached at excitation %d", shaker, exc)
        self.points.append(int(point.index))
        self._attach(exc, shaker)

    def on_finished(self, state: Any) -> None:
        for shaker in range(1, self.shakers + 1):
            self._attach(None, shaker)


def _remote_bench(control: BenchControl) -> Bench:
    """The built-in bench a mock bench process runs (from its ``status``)."""
    name = control.status().get("bench")
    try:
        return get_bench(str(name))
    except KeyError as err:
        raise BenchControlError(f"mock bench control {control.address}: the bench runs "
                                f"{name!r}, not a built-in bench") from err
