"""The state every view shares: the measurement being analysed, its analysis and the options.

:class:`Session` is the one place that starts background work on the data: loading a file
and (re-)identifying. Views call its methods and redraw on its signals; none of them runs
numerics on the GUI thread.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from PySide6 import QtCore

from app.gui.worker import TaskRunner
from app.io.mounts import MountsFile
from app.io.runfile import run_mounts
from app.pipeline import FORMATS, RunReport
from app.pipeline.formats import H5_SUFFIXES
from app.report.analysis import Analysis, analyse
from app.report.sources import open_source
from processing.data import FRFSet
from processing.identify import IdentificationResult, IdentifyOptions
from processing.measurement import Measurement

__all__ = ["Session"]


class Session(QtCore.QObject):
    """Shared data of the window.

    Signals
    -------
    data_changed(FRFSet)
        New FRFs (a file opened, or an acquisition finished: a new measurement); an
        analysis follows.
    analysis_changed(Analysis)
        A newer analysis of the current data is ready.
    message(str, str)
        (level, text) for the window's message bar; level is "info", "warning" or "error".
    mounts_changed(object)
        A mounts file was loaded (or cleared) in the plan view.
    """

    data_changed = QtCore.Signal(object)
    analysis_changed = QtCore.Signal(object)
    message = QtCore.Signal(str, str)
    #: the mounts file (:class:`~app.io.mounts.MountsFile`) or None
    mounts_changed = QtCore.Signal(object)

    def __init__(self, runner: TaskRunner, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.runner = runner
        self.measurement: Measurement | None = None
        self.source = ""
        self.path: Path | None = None
        self.format: str | None = None  # the file's format (app.pipeline.FORMATS), if any
        self.analysis: Analysis | None = None
        self.options = IdentifyOptions()
        self.mounts: MountsFile | None = None
        self._generation = 0  # bumped with each new data set: older analyses are dropped
        runner.done.connect(self._on_done)
        runner.failed.connect(self._on_failed)

    @property
    def frf(self) -> FRFSet | None:
        """The current measurement's FRFs (None before any)."""
        return None if self.measurement is None else self.measurement.frf

    def open_file(self, path: str | Path) -> None:
        """Load any file the command line reads (UFF FRFs or time records, a run file, an
        FRF file: :func:`app.report.sources.open_source`) in the background; data_changed
        follows."""
        p = Path(path)
        self.message.emit("info", f"opening {p.name} …")
        self.runner.submit("session.load", lambda: (p, *open_source(p), (
            run_mounts(p) if p.suffix.lower() in H5_SUFFIXES else None)))

    def set_measurement(self, measurement: Measurement, source: str, path: Path | None = None,
                        fmt: str | None = None, result: IdentificationResult | None = None,
                        ) -> None:
        """Make ``measurement`` the current data and analyse it with automatic bands.

        ``fmt`` is the format of the file at ``path`` (:data:`app.pipeline.FORMATS`).
        ``result`` is ``fit(measurement)`` with the default options when already made (a live
        run's): taken when the session's options are the defaults, else it fits again."""
        self.measurement = measurement
        self.source, self.path, self.format = source, path, fmt
        self._generation += 1
        self.analysis = None
        self.options = replace(self.options, mass_band=None, stiffness_band=None)
        self.data_changed.emit(measurement.frf)
        if result is None or not self.set_result(result):
            self.reanalyse()

    def set_result(self, result: IdentificationResult) -> bool:
        """Show ``result``, ``fit`` of the current measurement with the default options (a
        live run's final result after its preliminary one); False, and nothing done, when the
        session's options are not the defaults (the operator changed them)."""
        m, opt, src, gen = self.measurement, self.options, self.source, self._generation
        if m is None or opt != IdentifyOptions():
            return False
        self.runner.submit("session.analysis",
                           lambda: (gen, analyse(m, opt, src, result=result)))
        return True

    def set_mounts(self, mounts: MountsFile | None) -> None:
        """The mounts the results view analyses (rates, torque roll axis); None clears."""
        if mounts is self.mounts:
            return
        self.mounts = mounts
        self.mounts_changed.emit(mounts)

    def set_options(self, options: IdentifyOptions) -> None:
        """New identification options; re-identifies the current data in the background."""
        self.options = options
        self.reanalyse()

    def reanalyse(self) -> None:
        """Identify and check the current data again (no-op without data)."""
        m, opt, src, gen = self.measurement, self.options, self.source, self._generation
        if m is None:
            return
        self.runner.submit("session.analysis", lambda: (gen, analyse(m, opt, src)))

    @QtCore.Slot(str, object)
    def _on_done(self, key: str, result: object) -> None:
        if key == "session.load":
            assert isinstance(result, tuple)
            path, m, fmt, mounts = result
            self.message.emit(*_opened(path, m.provenance.reports, fmt))
            if mounts is not None:  # a run file's mounts table
                self.set_mounts(mounts)
            self.set_measurement(m, path.name, path, fmt)
        elif key == "session.analysis":
            assert isinstance(result, tuple)
            gen, result = result
            assert isinstance(result, Analysis)
            if gen != self._generation:
                return  # analysis of data replaced meanwhile
            self.analysis = result
            self.analysis_changed.emit(result)
            if result.result is None:
                self.message.emit("error", f"identification failed: {result.error}")

    @QtCore.Slot(str, str)
    def _on_failed(self, key: str, message: str) -> None:
        if key == "session.load":
            self.message.emit("error", f"cannot open the file: {message}")
        elif key == "session.analysis":
            self.message.emit("error", f"analysis failed: {message}")


def _opened(path: Path, reports: Sequence[RunReport], fmt: str) -> tuple[str, str]:
    """The message bar's (level, text) for a file opened: what it was, what was left out."""
    left_out = [r.message for r in reports if r.skipped]
    if not left_out:
        return "info", f"opened {path.name} ({FORMATS[fmt]})"
    return "warning", (f"opened {path.name}; {len(left_out)} run(s) or column(s) left out: "
                       + "; ".join(left_out))
