"""The acquisition procedure's listener, turned into Qt signals.

The procedure calls its listeners from its worker thread; :class:`AcquisitionBridge` only
emits signals there (Qt queues them to the GUI thread, where the views draw). It never
touches a widget.
"""

from __future__ import annotations

from typing import Any

from PySide6 import QtCore

from app.acquire.events import HitRecord, PointFRF, Progress, RunState

__all__ = ["AcquisitionBridge"]


class AcquisitionBridge(QtCore.QObject):
    """A :class:`~app.acquire.events.Listener` whose callbacks emit the signals below."""

    next_point = QtCore.Signal(object)  # ExcitationPoint
    hit = QtCore.Signal(object)  # HitRecord
    frf = QtCore.Signal(object)  # PointFRF
    progress = QtCore.Signal(object)  # Progress
    paused = QtCore.Signal(str)
    resumed = QtCore.Signal()
    error = QtCore.Signal(str)
    finished = QtCore.Signal(object)  # RunState

    def on_next_point(self, point: Any) -> None:
        self.next_point.emit(point)

    def on_hit(self, hit: HitRecord) -> None:
        self.hit.emit(hit)

    def on_frf(self, frf: PointFRF) -> None:
        self.frf.emit(frf)

    def on_progress(self, progress: Progress) -> None:
        self.progress.emit(progress)

    def on_paused(self, reason: str) -> None:
        self.paused.emit(reason)

    def on_resumed(self) -> None:
        self.resumed.emit()

    def on_error(self, message: str) -> None:
        self.error.emit(message)

    def on_finished(self, state: RunState) -> None:
        self.finished.emit(state)
