"""The bridge between the GUI thread and the work done off it.

:class:`TaskRunner` owns one worker :class:`~PySide6.QtCore.QThread`. Jobs are plain
callables submitted under a key ("analysis", "load", ...); they run one at a time in the
worker thread and their results come back to the GUI thread through queued signals. A job
superseded by a newer one of the same key before it starts is skipped, and a result that
arrives after a newer submission of its key is dropped, so rapid changes (a band dragged)
cost one computation and show the newest answer. Exceptions become one-line messages.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore

from app.report.analysis import message_of

__all__ = ["TaskRunner"]

log = logging.getLogger(__name__)


class _Worker(QtCore.QObject):
    """Lives in the worker thread; runs what the runner sends."""

    finished = QtCore.Signal(int, str, object)
    failed = QtCore.Signal(int, str, str)
    skipped = QtCore.Signal(int, str)

    def __init__(self, latest: dict[str, int]) -> None:
        super().__init__()
        self._latest = latest  # read-only here; ints are swapped atomically by the GUI thread

    @QtCore.Slot(int, str, object)
    def run(self, job: int, key: str, fn: Callable[[], Any]) -> None:
        if self._latest.get(key, job) != job:
            self.skipped.emit(job, key)
            return
        try:
            result = fn()
        except (ValueError, OSError) as err:  # bad data or files: the message says it all
            log.warning("background job %r: %s", key, err)
            self.failed.emit(job, key, message_of(err))
        except Exception as err:  # the worker must survive any job: report it in the window
            log.exception("background job %r failed", key)
            self.failed.emit(job, key, f"internal error ({type(err).__name__}): "
                             f"{message_of(err)}")
        else:
            self.finished.emit(job, key, result)


class TaskRunner(QtCore.QObject):
    """Run callables in one worker thread; results and failures come back as signals.

    Signals
    -------
    done(key, result)
        The newest job of ``key`` finished with ``result`` (emitted on the GUI thread).
    failed(key, message)
        The newest job of ``key`` raised; ``message`` is one line for the operator.
    busy(bool)
        True while any job is queued or running.
    """

    done = QtCore.Signal(str, object)
    failed = QtCore.Signal(str, str)
    busy = QtCore.Signal(bool)
    _submit = QtCore.Signal(int, str, object)

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self._latest: dict[str, int] = {}
        self._seq = 0
        self._pending = 0
        self._thread = QtCore.QThread()
        self._thread.setObjectName("insitu-worker")
        self._worker = _Worker(self._latest)
        self._worker.moveToThread(self._thread)
        self._submit.connect(self._worker.run, QtCore.Qt.ConnectionType.QueuedConnection)
        self._worker.finished.connect(self._on_finished)
        self._worker.failed.connect(self._on_failed)
        self._worker.skipped.connect(self._on_skipped)
        self._thread.finished.connect(self._worker.deleteLater)
        self._thread.start()

    @property
    def pending(self) -> int:
        """Jobs queued or running."""
        return self._pending

    def submit(self, key: str, fn: Callable[[], Any]) -> int:
        """Queue ``fn`` under ``key``; returns the job number."""
        self._seq += 1
        self._latest[key] = self._seq
        self._pending += 1
        if self._pending == 1:
            self.busy.emit(True)
        self._submit.emit(self._seq, key, fn)
        return self._seq

    def _settle(self) -> None:
        self._pending -= 1
        if self._pending == 0:
            self.busy.emit(False)

    @QtCore.Slot(int, str, object)
    def _on_finished(self, job: int, key: str, result: object) -> None:
        self._settle()
        if self._latest.get(key) == job:
            self.done.emit(key, result)

    @QtCore.Slot(int, str, str)
    def _on_failed(self, job: int, key: str, message: str) -> None:
        self._settle()
        if self._latest.get(key) == job:
            self.failed.emit(key, message)

    @QtCore.Slot(int, str)
    def _on_skipped(self, job: int, key: str) -> None:
        self._settle()

    def shutdown(self, timeout_ms: int = 10000) -> None:
        """Stop the worker thread after the running job (idempotent)."""
        if self._thread.isRunning():
            self._thread.quit()
            self._thread.wait(timeout_ms)
