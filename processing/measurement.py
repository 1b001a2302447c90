"""One measurement: the FRFs and everything about how they were obtained that the fit reads.

Every source (a UFF file of FRFs or of time records, an FRF file, a run file, a live run)
becomes one :class:`Measurement`, and :func:`processing.identify.fit` reads nothing else.
What changes the numerics is a typed field of :class:`Provenance`, never a loose key:

- ``origin``: FRFs ``"given"`` (an analyser's, a file's: their coherence stands for their
  noise) or ``"estimated"`` here from time records (their coherence comes from a few
  averages and the estimation's own errors are not in it: another error floor,
  :data:`processing.problem.TIME_DATA_ERROR_FLOOR`);
- ``units``: the spectra of each hit or block of each column (the bootstrap resamples them);
- ``exponential_tau``: the exponential window's time constant (its damping is removed from C);
- ``force_band_top``: the top of a hammer's usable band (no elastic mode is read above it).

The rest (``excitation``, ``anti_alias_fmax``, ``reports``) says what the data are and what
was found or left out on the way, for the views.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from processing.data import FRFSet, InputError

if TYPE_CHECKING:  # spectra and scipy.signal load where spectra are computed
    from processing.units import TimeUnits

__all__ = ["Measurement", "Origin", "Provenance", "Report"]

#: FRFs given (an analyser's, a file's) or estimated here from time records
Origin = Literal["given", "estimated"]


@dataclass(frozen=True)
class Report:
    """One line about a run, a point, an FRF column or the checks of the FRF set.

    Attributes
    ----------
    message : the line, naming what it is about
    skipped : True when that run, point or column was bad and is left out of the FRFs
    """

    message: str
    skipped: bool = False


def _positive_or_none(name: str, value: float | None) -> float | None:
    if value is None:
        return None
    v = float(value)
    if not math.isfinite(v) or v < 0:
        raise InputError(f"{name} must be a positive number, got {value!r}")
    return v if v > 0 else None


def _text(v: object) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


@dataclass(frozen=True)
class Provenance:
    """How a measurement's FRFs were obtained (see the module's docstring).

    Attributes
    ----------
    origin : ``"given"`` or ``"estimated"`` (here, from time records)
    excitation : what excited the structure, in words (``"impact"``, ``"random"``,
        ``"shaker chirp"``, ...), or ``""`` when unknown
    estimator : the FRF estimator (``"H1"``, ...)
    units : per-hit or per-block spectra of each column (time data only), or None
    exponential_tau : time constant of the exponential window on the records, s, or None
    force_band_top : Hz, the hammer's force is 20 dB or more under its peak above it, or None
    anti_alias_fmax : Hz, the lines were cut there (fs / 2.56), or None
    n_averages : records (hits, blocks, segments) each excitation column averages, or ()
    window : the records' window (``"hann"``, ``"boxcar"``), or ``""`` when not known
    references : forces driven at once (several shakers: multiple-reference H1)
    run_state : a run file's state (``"finished"``, ``"stopped"``, ...), or ``""``
    notes : what the file said about its FRFs, in words (coherence, units, ordinates)
    reports : what was found on the way, in order (bad runs or points left out: ``skipped``)
    """

    origin: Origin = "given"
    excitation: str = ""
    estimator: str = "H1"
    units: TimeUnits | None = field(default=None, repr=False)
    exponential_tau: float | None = None
    force_band_top: float | None = None
    anti_alias_fmax: float | None = None
    n_averages: tuple[int, ...] = ()
    window: str = ""
    references: int = 1
    run_state: str = ""
    notes: tuple[str, ...] = ()
    reports: tuple[Report, ...] = ()

    def __post_init__(self) -> None:
        if self.origin not in ("given", "estimated"):
            raise InputError(f"origin must be 'given' or 'estimated', got {self.origin!r}")
        for name in ("exponential_tau", "force_band_top", "anti_alias_fmax"):
            object.__setattr__(self, name, _positive_or_none(name, getattr(self, name)))
        if self.units is not None and self.origin != "estimated":
            raise InputError("per-hit or per-block spectra come with FRFs estimated from time "
                             "records (origin 'estimated')")
        object.__setattr__(self, "n_averages", tuple(int(n) for n in self.n_averages))
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        if not (isinstance(self.references, int) and self.references >= 1):
            raise InputError(f"references must be a whole number >= 1, got {self.references!r}")

    @property
    def estimated(self) -> bool:
        """True for FRFs estimated here from time records."""
        return self.origin == "estimated"

    @property
    def skipped(self) -> int:
        """How many runs, points or columns the reports leave out."""
        return sum(1 for r in self.reports if r.skipped)

    def stored(self) -> dict[str, object]:
        """The fields a file keeps, as HDF5 attributes (the per-unit spectra are not kept:
        a run file recomputes them from its records; nor are the reports)."""
        out: dict[str, object] = {"origin": self.origin, "excitation": self.excitation,
                                  "estimator": self.estimator, "window": self.window,
                                  "references": self.references, "run_state": self.run_state}
        for name in ("exponential_tau", "force_band_top", "anti_alias_fmax"):
            if (v := getattr(self, name)) is not None:
                out[name] = float(v)
        if self.n_averages:
            out["n_averages"] = list(self.n_averages)
        if self.notes:
            out["notes"] = list(self.notes)
        return out

    @classmethod
    def restored(cls, attrs: Mapping[str, object], origin: Origin = "given") -> Provenance:
        """The provenance a file kept (:meth:`stored`; ``origin`` when it names none);
        InputError naming a bad field."""
        def number(name: str) -> float | None:
            v = attrs.get(name)
            if v is None:
                return None
            try:
                return float(_text(v))
            except ValueError as err:
                raise InputError(f"provenance field {name} is not a number: {v!r}") from err

        def sequence(name: str) -> list[object]:
            v = attrs.get(name)
            if v is None:
                return []
            return [v] if isinstance(v, str | bytes) or not hasattr(v, "__iter__") else list(v)

        try:
            n_avg = tuple(int(float(_text(n))) for n in sequence("n_averages"))
            refs = int(float(_text(attrs.get("references", 1))))
        except ValueError as err:
            raise InputError(f"provenance field n_averages or references is not a whole "
                             f"number: {err}") from err
        kept = _text(attrs.get("origin", origin))
        return cls(origin="estimated" if kept == "estimated" else "given",
                   excitation=_text(attrs.get("excitation", "")),
                   estimator=_text(attrs.get("estimator", "H1")),
                   exponential_tau=number("exponential_tau"),
                   force_band_top=number("force_band_top"),
                   anti_alias_fmax=number("anti_alias_fmax"), n_averages=n_avg,
                   window=_text(attrs.get("window", "")), references=refs,
                   run_state=_text(attrs.get("run_state", "")),
                   notes=tuple(_text(n) for n in sequence("notes")))


@dataclass(frozen=True)
class Measurement:
    """FRFs and their :class:`Provenance`: what :func:`processing.identify.fit` takes.

    ``source`` names where they came from (a file name, ``"acquisition"``).
    """

    frf: FRFSet
    provenance: Provenance = field(default_factory=Provenance)
    source: str = ""

    @property
    def time_units(self) -> TimeUnits | None:
        """The units in the FRFs' column order (None without them, or when a column has
        none)."""
        units = self.provenance.units
        return None if units is None else units.aligned(self.frf.exc_nodes, self.frf.exc_dirs)
