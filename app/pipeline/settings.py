"""What the pipeline is asked (:class:`Settings`) and what it says back (:class:`RunReport`)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from processing.data import InputError
from processing.measurement import Report

__all__ = ["OpenError", "RunReport", "SettingError", "Settings", "TestUncertaintySettings",
           "parse_quantity"]

#: largest accepted --nperseg (samples), --record (s) and --fmax (Hz): far beyond any test,
#: small enough that a typo is refused before memory is asked for
MAX_NPERSEG = 2**24
MAX_RECORD = 3600.0
MAX_FMAX = 1e7


class SettingError(InputError):
    """A setting out of range or contradicting another, in the settings' own terms.

    ``template`` names settings as ``{nperseg}``; ``str()`` gives them their own names,
    :meth:`worded` the words of a front end (the command line's flags).
    """

    def __init__(self, template: str, *names: str) -> None:
        self.template, self.names = template, names
        super().__init__(self.worded({}))

    def worded(self, words: Mapping[str, str]) -> str:
        """The message with each setting called ``words[name]`` (its own name if absent)."""
        return self.template.format(**{n: words.get(n, n) for n in self.names})


def _between(name: str, value: float, lo: float, hi: float, unit: str) -> None:
    if not (math.isfinite(value) and lo <= value <= hi):
        raise SettingError(f"{{{name}}} must be from {lo:.10g} to {hi:.10g} {unit}, got "
                           f"{value:.10g}", name)


@dataclass(frozen=True)
class Settings:
    """How a file's FRFs are obtained; the defaults are the command line's.

    Attributes
    ----------
    excitation : time records: ``"random"`` (shaker, Welch) or ``"impact"`` (hammer hits); None
        reads it from the data (an impulsive force is a hammer test; a hammer option given,
        ``level``, ``record``, ``pretrigger``, ``exp_tau``, ``ring`` or ``tail``, means one)
    estimator : FRF estimator (``"H1"``, ``"H2"``, ...: :data:`processing.spectral.ESTIMATORS`)
    nperseg : random: samples per segment (line spacing fs / nperseg); None: from the data
        (see ``records``), 2048 for Welch segments
    overlap : random: segment overlap, in [0, 1); None: 0.5 for Welch segments
    window : random: window name (``"hann"``, ``"boxcar"``, ...); None: Hann for Welch segments
    records : random: how records are cut: ``"welch"`` (overlapping windowed segments),
        ``"periodic"`` (whole periods of ``nperseg`` samples, rectangular window, the first
        ones skipped until the responses repeat) or ``"burst"`` (``nperseg`` samples from
        each burst's onset, rectangular window); None reads it from the force
        (:func:`processing.excitation.shaker_signal`) unless ``nperseg``, ``overlap`` or
        ``window`` is given (then Welch)
    averages : at most this many averages (random: the first segments of each run; impact and
        run files: the first used hits or blocks of each point); None for all
    level : impact: trigger level, N (None: from each run's force noise,
        :func:`processing.impact.impact_defaults`)
    record : impact: record length, s (None: from the hit spacing and the responses' decay)
    pretrigger : impact: pre-trigger, s (None: 0.01 s)
    ring : impact: samples the automatic force window keeps after each pulse's end at least
        (None: 0, one pulse width)
    exp_tau : impact: exponential window time constant, s (None: chosen when the responses
        have not decayed by the end of the record; 0: no exponential window)
    carryover : impact: take the earlier hits' free decay off each record
        (:attr:`processing.impact.ImpactSettings.carryover`); burst records: take the earlier
        bursts' free decay off each record and put its own cut-off tail back
        (:func:`processing.excitation.burst_records`); None: when the responses still ring
        above their noise when the next hit comes or the burst record ends
        (:data:`app.pipeline.time_uff.CARRY_GATE`)
    tail : impact: put each record's own cut-off tail back (its responses' free decay after
        the hit continued past the record's end and folded onto it:
        :attr:`processing.impact.ImpactSettings.complete`), so the rectangular window leaks
        nothing; None: on when no exponential window is used (an exponential window given
        excludes it)
    coherence : coherence gate threshold of the checks reported
    fmax : highest line kept, Hz, for FRFs computed from time data (None: fs / 2.56)
    run_points : run files: ``"all"`` (every point needs a used hit or block, else the file
        is refused; a run whose force is aligned by host timing only is refused too: it is
        not identifiable) or ``"usable"`` (points without one are reported and left out,
        FRFs computed for any run)
    channel_map : TDMS and MDF files: their channel map (``docs/time-files.md``); None: the
        file's name with ``.map.toml`` beside it (``run.map.toml`` for ``run.tdms``)
    """

    excitation: Literal["random", "impact"] | None = None
    estimator: str = "H1"
    nperseg: int | None = None
    overlap: float | None = None
    window: str | None = None
    records: Literal["welch", "periodic", "burst"] | None = None
    averages: int | None = None
    level: float | None = None
    record: float | None = None
    pretrigger: float | None = None
    exp_tau: float | None = None
    ring: int | None = None
    carryover: bool | None = None
    tail: bool | None = None
    coherence: float = 0.8
    fmax: float | None = None
    run_points: Literal["all", "usable"] = "all"
    channel_map: Path | None = None

    def __post_init__(self) -> None:
        """Every option checked once, here, in the units the user typed; one line each."""
        if self.nperseg is not None:
            _between("nperseg", self.nperseg, 8, MAX_NPERSEG, "samples")
            if not isinstance(self.nperseg, int):
                raise SettingError(f"{{nperseg}} must be a whole number of samples, got "
                                   f"{self.nperseg}", "nperseg")
        if self.overlap is not None and not (math.isfinite(self.overlap)
                                             and 0 <= self.overlap < 1):
            raise SettingError(f"{{overlap}} must be at least 0 and below 1, got "
                               f"{self.overlap:g}", "overlap")
        if self.window is not None:
            from processing.windows import window_samples

            try:
                window_samples(self.window, 16)
            except (ValueError, TypeError) as err:
                raise SettingError(f"{{window}} {self.window!r} is not a window scipy knows: "
                                   "use hann, hamming, blackman, flattop, boxcar, ...",
                                   "window") from err
        if self.averages is not None and self.averages < 1:
            raise SettingError(f"{{averages}} must be at least 1, got {self.averages}",
                               "averages")
        if self.level is not None and not (math.isfinite(self.level) and self.level > 0):
            raise SettingError(f"{{level}} must be a positive force in N (the trigger fires "
                               f"when the force rises above it), got {self.level:g}", "level")
        if self.record is not None:
            _between("record", self.record, 1e-3, MAX_RECORD, "s")
        if self.pretrigger is not None and not (
                math.isfinite(self.pretrigger) and 0 <= self.pretrigger
                and (self.record is None or self.pretrigger < self.record)):
            raise SettingError(f"{{pretrigger}} must be at least 0 s and shorter than "
                               f"{{record}} ({self.record:g} s), got {self.pretrigger:g} s"
                               if self.record is not None else
                               f"{{pretrigger}} must be at least 0 s, got {self.pretrigger:g} s",
                               "pretrigger", "record")
        if self.exp_tau is not None and not (math.isfinite(self.exp_tau) and self.exp_tau >= 0):
            raise SettingError(f"{{exp_tau}} must be a time constant in s (0: no exponential "
                               f"window), got {self.exp_tau:g}", "exp_tau")
        if self.tail and self.exp_tau:
            raise SettingError("{tail} on puts each record's own tail back, which an "
                               "exponential window would weigh down: give {exp_tau} 0 or "
                               f"{{tail}} off, not {{exp_tau}} {self.exp_tau:g}", "tail",
                               "exp_tau")
        if self.ring is not None and not (isinstance(self.ring, int) and self.ring >= 0):
            raise SettingError(f"{{ring}} must be a whole number of samples, at least 0, "
                               f"got {self.ring}", "ring")
        if not (math.isfinite(self.coherence) and 0 <= self.coherence <= 1):
            raise SettingError(f"{{coherence}} must be from 0 to 1, got {self.coherence:g}",
                               "coherence")
        if self.fmax is not None:
            _between("fmax", self.fmax, 1e-3, MAX_FMAX, "Hz")

    def check_rate(self, fs: float, longest: float) -> None:
        """The options that depend on the data, checked once per file: ``fs`` its sample
        rate (Hz), ``longest`` its longest run (s)."""
        if self.fmax is not None and self.fmax > fs / 2:
            raise SettingError(f"{{fmax}} {self.fmax:g} Hz is above the records' Nyquist "
                               f"frequency ({fs / 2:g} Hz): give at most {fs / 2.56:g} Hz "
                               "(fs / 2.56) or leave it out", "fmax")
        if self.record is not None and self.excitation != "random" and self.record > longest:
            raise SettingError(f"{{record}} {self.record:g} s is longer than every run (the "
                               f"longest is {longest:g} s): give at most that, or leave it out",
                               "record")


    @property
    def welch_given(self) -> bool:
        """A Welch option was given (segment length, overlap, window)."""
        return any(v is not None for v in (self.nperseg, self.overlap, self.window))

    @property
    def hammer_given(self) -> bool:
        """A hammer option was given (trigger level, record, pre-trigger, exponential window,
        force ring, record tails); ``carryover`` serves burst records too."""
        return any(v is not None for v in (self.level, self.record, self.pretrigger,
                                           self.exp_tau, self.ring, self.tail))


#: one line about a run, a point, an FRF column or the checks (kept in the measurement's
#: provenance: :class:`processing.measurement.Report`)
RunReport = Report


class OpenError(InputError):
    """No FRFs can be obtained from the file; ``reports`` says what was found before."""

    def __init__(self, message: str, reports: Sequence[RunReport] = ()) -> None:
        super().__init__(message)
        self.reports = list(reports)


def n_skipped(reports: Sequence[RunReport]) -> int:
    """How many runs, points or columns the reports leave out."""
    return sum(1 for r in reports if r.skipped)


#: unit suffixes of the stated test uncertainties and their SI factors
LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6}
ANGLE_UNITS = {"rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180}
RELATIVE_UNITS = {"%": 1e-2, "": 1.0}
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-z%]*)\s*$")


def parse_quantity(option: str, text: str, units: dict[str, float], example: str,
                   upper: float) -> float:
    """``text`` (a number with one of ``units``' suffixes, e.g. ``3mm``) in SI units.

    Raises
    ------
    InputError
        One line naming the option, what was given and an example, when the text is not a
        number with a known unit, or the value is negative, not finite or above ``upper``
        (in the unit typed).
    """
    match = _QUANTITY.match(text)
    allowed = ", ".join(u or "no unit" for u in units)
    if match is None or match.group(2) not in units:
        raise SettingError(f"{{{option}}} {text!r} is not a number with a unit ({allowed}): "
                           f"give e.g. {example}", option)
    value, unit = float(match.group(1)), match.group(2)
    if not (math.isfinite(value) and 0 <= value * units[unit] <= upper):
        raise SettingError(f"{{{option}}} must be from 0 to {upper / units[unit]:g}{unit} (a "
                           f"standard deviation), got {text}", option)
    return value * units[unit]


@dataclass(frozen=True)
class TestUncertaintySettings:
    """The stated test uncertainties as typed (``--location-uncertainty 3mm``,
    ``--angle-uncertainty 2deg``, ``--gain-uncertainty 2%``, ``--draws N``), checked here
    in the user's units; SI values in ``location`` (m), ``angle`` (rad), ``gain``."""

    location_text: str | None = None
    angle_text: str | None = None
    gain_text: str | None = None
    draws: int | None = None

    @property
    def location(self) -> float:
        return (0.0 if self.location_text is None else parse_quantity(
            "location_uncertainty", self.location_text, LENGTH_UNITS, "3mm", 0.5))

    @property
    def angle(self) -> float:
        return (0.0 if self.angle_text is None else parse_quantity(
            "angle_uncertainty", self.angle_text, ANGLE_UNITS, "2deg", math.radians(30)))

    @property
    def gain(self) -> float:
        return (0.0 if self.gain_text is None else parse_quantity(
            "gain_uncertainty", self.gain_text, RELATIVE_UNITS, "2%", 0.5))

    @property
    def stated(self) -> bool:
        """True when any uncertainty was given."""
        return any(t is not None for t in (self.location_text, self.angle_text,
                                           self.gain_text))

    def __post_init__(self) -> None:
        _ = self.location, self.angle, self.gain  # every text checked now, one line each
        if self.draws is not None:
            if not self.stated:
                raise SettingError("{draws} needs {location_uncertainty}, {angle_uncertainty} "
                                   "or {gain_uncertainty}: say what to draw", "draws",
                                   "location_uncertainty", "angle_uncertainty",
                                   "gain_uncertainty")
            _between("draws", self.draws, 2, 1_000_000, "draws")
