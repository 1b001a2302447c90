"""A procedure running in a worker thread: startup, execute, shutdown (as PyMeasure's).

:class:`Procedure` owns the thread, the listeners and the commands other threads
send (pause, resume, stop, overrides, notes). Commands go through a queue the
worker polls, so only the worker touches devices and the run file. Subclasses
implement :meth:`startup`, :meth:`execute` and :meth:`shutdown`, call
:meth:`poll` often, and :meth:`pause_for` when a device stops answering.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from app.acquire.events import RunState, SampleBlock, dispatch

__all__ = ["Procedure", "StopRequestedError"]

logger = logging.getLogger(__name__)

T = TypeVar("T")


class StopRequestedError(Exception):
    """Raised in the worker by :meth:`Procedure.poll` once :meth:`Procedure.stop` was called."""


class Procedure:
    """Base of the acquisition procedures.

    Parameters
    ----------
    listeners : iterable
        Objects with any of the :class:`~app.acquire.events.Listener` callbacks.
    """

    def __init__(self, listeners: Iterable[Any] = ()) -> None:
        self.listeners: list[Any] = list(listeners)
        self.state = RunState.IDLE
        self.message = ""
        self._cmds: queue.Queue[tuple[str, Any]] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._done = threading.Event()
        self._stop_asked = threading.Event()
        self._stop_reason = "stopped by the operator"

    # -- public API (any thread) ----------------------------------------------------------------
    def add_listener(self, listener: Any) -> None:
        """Add a listener; do it before :meth:`start`."""
        self.listeners.append(listener)

    def start(self) -> None:
        """Run the procedure in a new worker thread; returns at once."""
        if self._thread is not None:
            raise RuntimeError("a procedure runs once; create a new one")
        self.state = RunState.RUNNING
        self._thread = threading.Thread(target=self._run, name=type(self).__name__, daemon=True)
        self._thread.start()

    def pause(self, reason: str = "paused by the operator") -> None:
        """Pause after the current hit (devices stop streaming; data stay in the file)."""
        self._cmds.put(("pause", reason))

    def resume(self) -> None:
        """Continue a paused run (devices restart; the current point is announced again)."""
        self._cmds.put(("resume", None))

    def stop(self, reason: str = "stopped by the operator") -> None:
        """End the run early; everything acquired stays in the file (state ``stopped``,
        message ``reason``; the first stop's reason is kept)."""
        if not self._stop_asked.is_set():
            self._stop_reason = reason
        self._stop_asked.set()  # seen at once by long steps (a shaker's ramp) that poll it
        self._cmds.put(("stop", None))

    @property
    def stop_asked(self) -> bool:
        """True once :meth:`stop` was called (any thread)."""
        return self._stop_asked.is_set()

    def accept_hit(self, hit_id: int) -> None:
        """Operator override: use hit ``hit_id`` although the automatic checks rejected it."""
        self._cmds.put(("override", (hit_id, "accept")))

    def reject_hit(self, hit_id: int) -> None:
        """Operator override: do not use hit ``hit_id`` although it passed the checks."""
        self._cmds.put(("override", (hit_id, "reject")))

    def clear_override(self, hit_id: int) -> None:
        """Go back to the automatic verdict of hit ``hit_id``."""
        self._cmds.put(("override", (hit_id, "")))

    def add_note(self, text: str) -> None:
        """Store an operator note in the run file."""
        self._cmds.put(("note", text))

    def wait(self, timeout: float | None = None) -> RunState:
        """Block until the worker ends (or ``timeout`` s); returns the state then."""
        self._done.wait(timeout)
        return self.state

    @property
    def running(self) -> bool:
        return self._thread is not None and not self._done.is_set()

    # -- to implement -----------------------------------------------------------------------------
    def startup(self) -> None:
        """Open devices and the run file (worker thread)."""

    def execute(self) -> None:
        """Acquire (worker thread); call :meth:`poll` often."""
        raise NotImplementedError

    def shutdown(self) -> None:
        """Release devices and close the run file; always called (worker thread)."""

    def apply_override(self, hit_id: int, override: str) -> None:
        """Apply an override command (worker thread)."""

    def apply_note(self, text: str) -> None:
        """Store a note (worker thread)."""

    def on_pause(self) -> None:
        """Stop devices when pausing (worker thread); errors are logged."""

    def on_resume(self) -> None:
        """Restart devices when resuming (worker thread); a DeviceError pauses again."""

    # -- worker side -------------------------------------------------------------------------
    def emit(self, name: str, *args: Any) -> None:
        """Call listener callback ``name`` on every listener."""
        dispatch(self.listeners, name, *args)

    def emit_samples(self, data: NDArray[np.float64], fs: float, names: Sequence[str],
                     t_first: float | None = None) -> None:
        """Send ``on_samples`` with the rows just read (skipped when no listener has it);
        ``t_first``: the host time of their first sample, if known."""
        if any(getattr(listener, "on_samples", None) for listener in self.listeners):
            self.emit("on_samples", SampleBlock(data, fs, tuple(names), time.monotonic(),
                                                t_first))

    def next_to_do(self, items: Iterable[T], done: Callable[[T], bool]) -> T | None:
        """The first of ``items`` not ``done``, or None, once the commands already sent are
        handled: overrides sent together (one reopening a point, the next completing it
        again) never make the run announce a point it no longer needs."""
        self.poll()
        return next((item for item in items if not done(item)), None)

    def poll(self) -> None:
        """Handle pending commands; pauses here when asked; raises StopRequestedError on stop."""
        while True:
            try:
                cmd, arg = self._cmds.get_nowait()
            except queue.Empty:
                return
            self._handle(cmd, arg)

    def _handle(self, cmd: str, arg: Any) -> bool:
        """Handle one command; True when it was ``resume``."""
        if cmd == "stop":
            raise StopRequestedError
        if cmd == "override":
            self.apply_override(*arg)
        elif cmd == "note":
            self.apply_note(arg)
        elif cmd == "pause" and self.state is RunState.RUNNING:
            self.pause_for(arg)
        return cmd == "resume"

    def pause_for(self, reason: str) -> None:
        """Pause (devices stopped), tell the listeners why, and wait for resume or stop."""
        from drivers.errors import DeviceError

        while True:
            self.state = RunState.PAUSED
            self.message = reason
            try:
                self.on_pause()
            except DeviceError as err:
                # the device that made the run pause often fails to stop too: the
                # log file keeps it, the listeners say the one thing that matters
                logger.info("stopping devices while pausing: %s", err)
            logger.info("run paused: %s", reason)
            self.emit("on_paused", reason)
            while not self._handle(*self._cmds.get()):
                pass
            try:
                self.on_resume()
            except DeviceError as err:
                reason = f"{err}; check the device and resume"
                continue
            self.state = RunState.RUNNING
            self.message = ""
            self.emit("on_resumed")
            return

    def _run(self) -> None:
        try:
            try:
                self.startup()
                self.execute()
                self.state = RunState.FINISHED
            except StopRequestedError:
                self.state = RunState.STOPPED
                self.message = self._stop_reason
            except Exception as err:  # surfaced to the listeners, never lost
                logger.exception("procedure failed")
                self.state = RunState.FAILED
                self.message = str(err).splitlines()[0] if str(err) else repr(err)
                self.emit("on_error", self.message)
            finally:
                try:
                    self.shutdown()
                except Exception as err:
                    logger.exception("procedure shutdown failed")
                    if self.state is not RunState.FAILED:
                        self.state = RunState.FAILED
                        self.message = f"shutdown failed: {err}"
                        self.emit("on_error", self.message)
        finally:
            self.emit("on_finished", self.state)
            self._done.set()
