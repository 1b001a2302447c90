"""What the pipeline is asked (:class:`Settings`) and what it says back (:class:`RunReport`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from processing.data import InputError

__all__ = ["OpenError", "RunReport", "Settings"]


@dataclass(frozen=True)
class Settings:
    """How a file's FRFs are obtained; the defaults are the command line's.

    Attributes
    ----------
    excitation : time records: ``"random"`` (shaker, Welch) or ``"impact"`` (hammer hits)
    estimator : FRF estimator (``"H1"``, ``"H2"``, ...: :data:`processing.spectral.ESTIMATORS`)
    nperseg : random: samples per segment (line spacing fs / nperseg)
    overlap : random: segment overlap, in [0, 1)
    window : random: window name (``"hann"``, ``"boxcar"``, ...)
    averages : at most this many averages (random: the first segments of each run; impact and
        run files: the first used hits or blocks of each point); None for all
    level : impact: trigger level, N (None: 10 % of the run's largest force)
    record : impact: record length, s
    pretrigger : impact: pre-trigger, s
    exp_tau : impact: exponential window time constant, s (None: no exponential window)
    coherence : coherence gate threshold of the checks reported
    fmax : highest line kept, Hz, for FRFs computed from time data (None: fs / 2.56)
    run_points : run files: ``"all"`` (every point needs a used hit or block, else the file
        is refused; a run whose force is aligned by host timing only is refused too: it is
        not identifiable) or ``"usable"`` (points without one are reported and left out,
        FRFs computed for any run)
    stored : run files: a finished run's stored FRFs instead of recomputing them (with
        ``run_points="all"``)
    """

    excitation: Literal["random", "impact"] = "random"
    estimator: str = "H1"
    nperseg: int = 2048
    overlap: float = 0.5
    window: str = "hann"
    averages: int | None = None
    level: float | None = None
    record: float = 1.0
    pretrigger: float = 0.01
    exp_tau: float | None = None
    coherence: float = 0.8
    fmax: float | None = None
    run_points: Literal["all", "usable"] = "all"
    stored: bool = False

    def check_averages(self) -> None:
        """Refuse (InputError, one line) an ``averages`` below 1."""
        if self.averages is not None and self.averages < 1:
            raise InputError(f"--averages must be at least 1, got {self.averages}")


@dataclass(frozen=True)
class RunReport:
    """One line about a run, a point, an FRF column or the checks of the FRF set.

    Attributes
    ----------
    message : the line, naming what it is about
    skipped : True when that run, point or column was bad and is left out of the FRFs
    """

    message: str
    skipped: bool = False


class OpenError(InputError):
    """No FRFs can be obtained from the file; ``reports`` says what was found before."""

    def __init__(self, message: str, reports: Sequence[RunReport] = ()) -> None:
        super().__init__(message)
        self.reports = list(reports)


def n_skipped(reports: Sequence[RunReport]) -> int:
    """How many runs, points or columns the reports leave out."""
    return sum(1 for r in reports if r.skipped)
