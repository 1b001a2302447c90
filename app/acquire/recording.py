"""What the hammer and shaker procedures share: a run file, its notes and its last step.

:class:`RecordingProcedure` is a :class:`~app.acquire.procedure.Procedure` that writes
one run file (:class:`app.io.runfile.RunWriter`). Subclasses open their devices and the
file in ``startup``, close their devices in :meth:`_close_devices`, and call
:meth:`_finish_run` with the run's FRFs when every point is done.
"""

from __future__ import annotations

import time

from app.acquire.analysis import identify_frfs
from app.acquire.procedure import Procedure
from app.io.runfile import RunWriter
from processing.data import FRFSet, InputError
from processing.geometry import GeometryError, GeometryReport
from processing.identify import IdentificationResult

__all__ = ["RecordingProcedure"]


class RecordingProcedure(Procedure):
    """A procedure that records into a run file (see the module docstring)."""

    writer: RunWriter | None
    frf: FRFSet | None
    result: IdentificationResult | None
    do_identify: bool
    geometry_report: GeometryReport
    _t0: float
    _t_offset: float

    def _close_devices(self) -> None:
        """Shut every device down (idempotent); subclasses own their devices."""
        raise NotImplementedError

    def shutdown(self) -> None:
        """Devices off, then the file closed with the run's state unless it is complete."""
        self._close_devices()
        if self.writer is not None:
            state = self.state.value if self.state.value != "running" else "failed"
            if self.frf is None:
                self.writer.finish(state, self.message)
            self.writer = None

    def apply_note(self, text: str) -> None:
        if self.writer is not None:
            self.writer.add_note(text, time.monotonic() - self._t0 + self._t_offset)

    def _finish_run(self, frf: FRFSet) -> None:
        """Store the FRFs and, when the plan allows, the identification; the run is done."""
        assert self.writer is not None
        self.frf = frf
        message, result_json = "", None
        if self.do_identify and self.geometry_report.ok:
            try:
                self.result = identify_frfs(frf)
                result_json = self.result.to_json()
            except (InputError, GeometryError) as err:
                message = f"identification failed: {err}"
                self.emit("on_error", message)
        self.writer.finish("finished", message, frf, result_json)
        self.writer = None
