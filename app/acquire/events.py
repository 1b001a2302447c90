"""What a running procedure reports: hit records, point FRFs, progress, and the listener protocol.

Listeners are plain objects with callback methods, called from the procedure's
worker thread. A GUI forwards them as Qt signals (never touch widgets from the
callbacks themselves); the headless CLI updates rich progress bars. Subclass
:class:`Listener` and override only what you need; a callback that raises is
logged and does not stop the run.
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["HitRecord", "Listener", "PointFRF", "Progress", "RunState", "SampleBlock", "dispatch"]

logger = logging.getLogger(__name__)


class RunState(enum.Enum):
    """Life cycle of a procedure (and the ``state`` attribute of its run file)."""

    IDLE = "idle"
    RUNNING = "running"
    PAUSED = "paused"
    STOPPED = "stopped"
    FINISHED = "finished"
    FAILED = "failed"


@dataclass(frozen=True)
class HitRecord:
    """One hit (hammer) or block (shaker) as acquired and judged.

    Attributes
    ----------
    hit_id : int
        Row in the run file (0-based, in acquisition order).
    point : int
        Excitation point index in the plan.
    time : float
        Seconds since the run started (first start, over resumes).
    peak_force : float
        Peak force, N (NaN if the record could not be judged).
    auto_accepted : bool
        The automatic verdict.
    reason : str
        Why the automatic verdict rejected it ("" when accepted).
    override : {"", "accept", "reject"}
        The operator's manual override, if any.
    bad_frames, missing : int
        Corrupted frames seen during the record, samples lost in it.
    point_accepted, point_needed : int
        Accepted hits at this point so far (after this one) and the number the plan asks for.
    data : (n_ch, n) float64 or None
        The record: force (N) then the responses (m/s^2), at ``fs``.
    fs : float
        Sample rate of ``data``, Hz.
    """

    hit_id: int
    point: int
    time: float
    peak_force: float
    auto_accepted: bool
    reason: str
    override: str = ""
    bad_frames: int = 0
    missing: int = 0
    point_accepted: int = 0
    point_needed: int = 0
    data: NDArray[np.float64] | None = None
    fs: float = 0.0

    @property
    def accepted(self) -> bool:
        """The verdict in force: the override if any, else the automatic one."""
        if self.override:
            return self.override == "accept"
        return self.auto_accepted

    @property
    def point_complete(self) -> bool:
        return self.point_accepted >= self.point_needed


@dataclass(frozen=True)
class PointFRF:
    """The averaged FRF column of one excitation point after the latest hit or override.

    ``H`` is (n_resp, n_f) accelerance, (m/s^2)/N; ``coherence`` (n_resp, n_f); ``freq`` Hz.
    ``H`` and ``coherence`` are None when the point has no accepted hit.
    """

    point: int
    freq: NDArray[np.float64]
    H: NDArray[np.complex128] | None
    coherence: NDArray[np.float64] | None
    n_averages: int


@dataclass(frozen=True)
class Progress:
    """Where the run is: current point, hits, frames lost, elapsed time (s).

    ``hits``, ``accepted`` and ``points_done`` count the whole run file: with a resumed
    run, the records and points done before it too. ``points_done`` counts the points
    (or drives) that have every record they need, wherever they are in the plan.
    """

    point: int
    n_points: int
    point_accepted: int
    point_needed: int
    hits: int
    accepted: int
    bad_frames: int
    elapsed: float
    points_done: int


@dataclass(frozen=True)
class SampleBlock:
    """Samples just read from the streams, for live display (not judged, not stored).

    Attributes
    ----------
    data : (n_rows, n) float64
        The procedure's rows as read: the force (N) then the responses (m/s^2), at ``fs``;
        NaN where samples were lost. With the force on a separate device (a hammer's
        digitiser) its row is that device's latest samples stretched to ``n``: close in
        time, not aligned (the hit records are).
    fs : float
        Sample rate of ``data``, Hz.
    names : tuple of str
        Channel name of each row.
    t_read : float
        ``time.monotonic()`` when the samples were read, s.
    t_first : float or None
        ``time.monotonic()`` by which the first sample had been taken (the reference
        device's frames, :attr:`drivers.base.TimeBlock.host_time`), s; None when unknown.
        Behind ``t_read`` by more than the block's length when the run reads a backlog.
    """

    data: NDArray[np.float64]
    fs: float
    names: tuple[str, ...]
    t_read: float
    t_first: float | None = None


class Listener:
    """Callbacks of a running procedure; every method does nothing by default.

    All are called from the procedure's worker thread, in this order for a point:
    ``on_next_point``, then per hit ``on_hit``, ``on_frf``, ``on_progress``;
    ``on_samples`` after every read of the streams, in between.
    """

    def on_next_point(self, point: Any) -> None:
        """The procedure waits for hits (or drives the shaker) at ``point``
        (an :class:`~app.acquire.plan.ExcitationPoint`)."""

    def on_hit(self, hit: HitRecord) -> None:
        """A hit (or block) was recorded and judged, or its verdict was overridden."""

    def on_frf(self, frf: PointFRF) -> None:
        """The averaged FRF of a point changed."""

    def on_progress(self, progress: Progress) -> None:
        """Counters after each hit."""

    def on_samples(self, block: SampleBlock) -> None:
        """New samples of the procedure's rows (a :class:`SampleBlock`), at the read
        cadence (about ten times a second) while the devices stream, ramps and settling
        included. For live traces: return at once (queue the block), the worker waits."""

    def on_paused(self, reason: str) -> None:
        """The run paused (operator request, or a device stopped answering: ``reason`` says)."""

    def on_resumed(self) -> None:
        """The run continues after a pause."""

    def on_result(self, measurement: Any, result: Any, final: bool) -> None:
        """The run's identification (an :class:`~processing.identify.IdentificationResult`
        of ``measurement``, the run's FRFs cut as every view reads the run file) once every
        point is done: first (``final`` False, when the bootstrap over hits or blocks runs)
        at once, with the fit covariance's spreads, then (``final`` True) the result stored
        in the run file, ``on_finished`` following."""

    def on_error(self, message: str) -> None:
        """A failure the run cannot continue from (one line); ``on_finished`` follows."""

    def on_finished(self, state: RunState) -> None:
        """The worker ended: FINISHED (all points done), STOPPED or FAILED."""


def dispatch(listeners: Iterable[Any], name: str, *args: Any) -> None:
    """Call ``name(*args)`` on every listener that has it; log (never raise) their errors."""
    for listener in listeners:
        fn = getattr(listener, name, None)
        if fn is None:
            continue
        try:
            fn(*args)
        except Exception:  # a broken listener must not lose the run
            logger.exception("listener %r failed in %s", listener, name)
