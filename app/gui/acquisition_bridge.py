"""The acquisition procedure's listener, turned into Qt signals and a queue.

The procedure calls its listeners from its worker thread; :class:`AcquisitionBridge` only
emits signals there (Qt queues them to the GUI thread, where the views draw) and puts the
streamed samples (``on_samples``, about ten a second) on :attr:`AcquisitionBridge.samples`,
which the live traces drain from a QTimer. It never touches a widget and never blocks the
worker.
"""

from __future__ import annotations

import queue
from typing import Any

from PySide6 import QtCore

from app.acquire.events import HitRecord, PointFRF, Progress, RunState, SampleBlock

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
    result = QtCore.Signal(object, object, bool)  # Measurement, IdentificationResult, final
    finished = QtCore.Signal(object)  # RunState

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.samples: queue.SimpleQueue[SampleBlock] = queue.SimpleQueue()

    def on_samples(self, block: SampleBlock) -> None:
        self.samples.put(block)

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

    def on_result(self, measurement: Any, result: Any, final: bool) -> None:
        self.result.emit(measurement, result, final)

    def on_error(self, message: str) -> None:
        self.error.emit(message)

    def on_finished(self, state: RunState) -> None:
        self.finished.emit(state)
