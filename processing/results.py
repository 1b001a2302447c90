"""The result of an identification: parameters, bands, evidence and checks.

:class:`IdentificationResult` is what :func:`processing.identify.identify` returns;
``to_json`` writes the result JSON of docs/conventions.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from processing.delays import ChannelDelays
from processing.geometry import DEFAULT_MAX_COND_T, GeometryReport
from processing.inertia import InertiaProperties
from processing.modes import rigid_body_modes
from processing.selection import ElasticPeak
from processing.stiffness import Stiffening
from processing.synthesis import SynthesisFit

__all__ = ["UNCERTAIN_KEYS", "Contribution", "IdentificationResult", "Method", "Uncertainty"]

Method = Literal["improved", "plain"]

#: the coherence check passes with at most this fraction of the bands' FRF values under the
#: threshold (low values sit at antiresonances; they are weighted down, not dropped)
COHERENCE_LOW_PASS = 0.05

#: the result-JSON keys an :class:`Uncertainty` mirrors, with their shapes
UNCERTAIN_KEYS: dict[str, tuple[int, ...]] = {
    "mass": (),
    "cog": (3,),
    "inertia_cog": (3, 3),
    "inertia_origin": (3, 3),
    "principal_moments": (3,),
    "stiffness": (6, 6),
    "damping": (6, 6),
    "rigid_modes_hz": (6,),
}


@dataclass(frozen=True)
class Contribution:
    """The share of one input in the variance of one identified number.

    ``quantity`` names the number as the terminal shows it (``"cog z"``,
    ``"inertia_cog xx"``, ``"mass"``); ``source`` the input (``"point 3 location"``,
    ``"fit (noise)"``); ``fraction`` its share of that number's variance, 0-1.
    """

    quantity: str
    source: str
    fraction: float


@dataclass(frozen=True)
class Uncertainty:
    """How far to trust a result: standard deviations mirroring the result's keys.

    ``std`` maps each key of :data:`UNCERTAIN_KEYS` present to an array of that key's
    shape (SI units, as the value); ``ci95`` maps keys whose 95 % interval is not
    ``value +- 1.96 std`` to an array of that shape plus a last axis (lo, hi).
    ``sources`` says what was propagated, in words (one entry per part: the fit's
    covariance, a Monte Carlo of stated test uncertainties, a bootstrap over hits);
    ``contributions`` the inputs that contribute most, largest first.
    """

    std: dict[str, NDArray[np.float64]]
    ci95: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    sources: tuple[str, ...] = ()
    contributions: tuple[Contribution, ...] = ()
    #: (82, 82) joint covariance of ``[theta (10), vec K (36), vec C (36)]`` (row-major),
    #: SI, when known (not written to the JSON; e.g. the mount-rate fit uses it)
    covariance: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        for table, extra in ((self.std, ()), (self.ci95, (2,))):
            for key, value in table.items():
                if key not in UNCERTAIN_KEYS:
                    raise ValueError(f"uncertainty of unknown key {key!r}")
                if np.shape(value) != UNCERTAIN_KEYS[key] + extra:
                    raise ValueError(f"uncertainty of {key!r} has shape {np.shape(value)}, "
                                     f"expected {UNCERTAIN_KEYS[key] + extra}")

    def to_json(self) -> dict[str, Any]:
        """``std``, ``ci95`` (when any) and ``uncertainty`` (sources, contributions) keys of
        the result JSON (docs/conventions.md)."""
        out: dict[str, Any] = {
            "std": {k: np.asarray(v, dtype=float).tolist() for k, v in self.std.items()},
            "uncertainty": {
                "sources": list(self.sources),
                "contributions": [{"quantity": c.quantity, "source": c.source,
                                   "fraction": c.fraction} for c in self.contributions],
            },
        }
        if self.ci95:
            out["ci95"] = {k: np.asarray(v, dtype=float).tolist() for k, v in self.ci95.items()}
        return out


@dataclass(frozen=True)
class IdentificationResult:
    """Everything identified, with the evidence. All SI, global frame of the input."""

    method: Method
    theta: NDArray[np.float64]
    M: NDArray[np.float64]
    K: NDArray[np.float64]
    C: NDArray[np.float64]
    properties: InertiaProperties
    mass_band: tuple[float, float]
    stiffness_band: tuple[float, float]
    mass_lines: NDArray[np.float64]
    stiffness_lines: NDArray[np.float64]
    iterations: int
    converged: bool
    geometry: GeometryReport
    elastic_modes: tuple[ElasticPeak, ...]
    rigid_modes_hz: NDArray[np.float64]
    reconstruction_error: NDArray[np.float64]
    synthesis: SynthesisFit
    #: FRF values of the bands' lines under ``coherence_threshold`` (weighted down), of
    #: ``coherence_values``
    coherence_low: int
    #: whether the coherence check could fail: coherence measured over more records a
    #: point than forces driven at once (``coherence_unchecked`` says why not, else "")
    coherence_checked: bool
    coherence_min: float
    physical_enforced: bool
    warnings: tuple[str, ...] = ()
    stiffness_per_line: NDArray[np.complex128] | None = field(default=None, repr=False)
    #: estimated response-point location errors (n_resp, 3), m, when refined
    point_corrections: NDArray[np.float64] | None = None
    #: frequency ranges (f_low, f_high), Hz, of the lines of the mass and stiffness bands
    #: where some FRF's coherence is below ``coherence_threshold``
    coherence_ranges_hz: tuple[tuple[float, float], ...] = ()
    coherence_values: int = 0
    coherence_threshold: float = 0.8
    #: which bands were chosen and why, in words
    band_reason: str = ""
    #: how the mass-line model was chosen (upper residual or not), in words
    model_note: str = ""
    #: standard deviations and intervals of the identified numbers, when computed
    uncertainty: Uncertainty | None = None
    #: structural (hysteretic) damping at O of ``K* = K + j w C + j D`` (same units as K;
    #: zero for the viscous model)
    D: NDArray[np.float64] = field(default_factory=lambda: np.zeros((6, 6)))
    #: the damping model of K*: "viscous" (C), "hysteretic" (D) or "both"
    damping_model: str = "viscous"
    #: how the damping model was chosen, in words
    damping_note: str = ""
    #: why the coherence check is not made ("no coherence in the input", "one hit a
    #: point": a coherence of 1 by definition), or "" when it is
    coherence_unchecked: str = ""
    #: the mounts' stiffening with frequency, ``K(f) = K (f / f_k)^alpha`` (K and D then
    #: hold at ``f_k``), None for a constant K
    stiffening: Stiffening | None = None
    #: how the stiffness's frequency dependence was chosen, in words
    stiffening_note: str = ""
    #: each response channel's delay against the force, taken out of the FRFs before the
    #: fit (in the FRFs' response order), None when none was
    channel_delays: ChannelDelays | None = None
    #: how the channel delays were read, in words
    channel_delays_note: str = ""

    @property
    def fit_notes(self) -> tuple[str, ...]:
        """How the damping model, the stiffening (when any) and the channel delays (when
        taken out) were chosen, in words, as every view prints them."""
        return tuple(n for n in (self.damping_note,
                                 self.stiffening_note if self.stiffening else "",
                                 self.channel_delays_note if self.channel_delays is not None
                                 else "") if n)

    @property
    def coherence_low_fraction(self) -> float:
        """Fraction of the bands' FRF values under the coherence threshold (0 unchecked)."""
        return self.coherence_low / self.coherence_values if self.coherence_values else 0.0

    def checks(self) -> dict[str, dict[str, Any]]:
        """Named pass/fail checks with their figures (result JSON ``checks``); a check that
        could not fail has ``pass`` None and says why in ``not_checked`` (the coherence of
        one record a point is 1 by definition)."""
        p = self.properties
        rel = self.reconstruction_error
        return {
            "geometry": {
                "pass": self.geometry.ok and self.geometry.cond_T <= DEFAULT_MAX_COND_T,
                "rank_E": self.geometry.rank_E,
                "cond_E": self.geometry.cond_E,
                "rank_T": self.geometry.rank_T,
                "cond_T": self.geometry.cond_T,
            },
            "coherence": {
                # None (JSON null): not checked, the check could not fail
                "pass": (self.coherence_low_fraction <= COHERENCE_LOW_PASS
                         if self.coherence_checked else None),
                "checked": self.coherence_checked,
                **({} if self.coherence_checked else {
                    "not_checked": self.coherence_unchecked or "no coherence in the input"}),
                "threshold": self.coherence_threshold,
                "min_in_mass_band": self.coherence_min,
                "low_values": self.coherence_low,
                "low_fraction": self.coherence_low_fraction,
                "low_ranges_hz": [list(r) for r in self.coherence_ranges_hz],
            },
            "rigidity": {
                "pass": bool(np.max(rel) < 0.1) if rel.size else True,
                "max_reconstruction_error_in_mass_band": float(np.max(rel)) if rel.size else 0.0,
                "mean_reconstruction_error_in_mass_band": float(np.mean(rel)) if rel.size else 0.0,
            },
            "physical_consistency": {
                "pass": p.physically_consistent,
                "positive_definite": p.positive_definite,
                "triangle_inequality": p.triangle_inequality,
                "triangle_margin": p.triangle_margin,
                "enforced": self.physical_enforced,
            },
            "reconstruction_error": {
                "pass": self.synthesis.overall < 0.1,
                "synthesis_error_overall": self.synthesis.overall,
                "synthesis_error_max_frf": float(np.max(self.synthesis.per_frf)),
                "band": list(self.synthesis.band),
            },
            "convergence": {"pass": self.converged, "iterations": self.iterations},
        }

    def to_json(self) -> dict[str, Any]:
        """The result JSON of docs/conventions.md (plus extra keys)."""
        p = self.properties
        return {
            "mass": p.mass,
            "cog": p.cog.tolist(),
            "inertia_cog": p.inertia_cog.tolist(),
            "inertia_origin": p.inertia_origin.tolist(),
            "principal_moments": p.principal_moments.tolist(),
            "principal_axes": p.principal_axes.tolist(),
            "stiffness": self.K.tolist(),
            "damping": self.C.tolist(),
            "structural_damping": self.D.tolist(),
            "damping_model": self.damping_model,
            "damping_choice": self.damping_note,
            "stiffening": (None if self.stiffening is None else {
                "per_decade": self.stiffening.per_decade,
                "exponent": self.stiffening.alpha,
                "stiffness_at_hz": self.stiffening.reference_hz}),
            "stiffening_choice": self.stiffening_note,
            "channel_delays": (None if self.channel_delays is None else {
                "seconds": self.channel_delays.seconds.tolist(),
                "std": self.channel_delays.std.tolist(),
                "lines": self.channel_delays.lines}),
            "channel_delays_choice": self.channel_delays_note,
            "bands": {"mass_line": list(self.mass_band), "stiffness": list(self.stiffness_band)},
            "band_choice": self.band_reason,
            "mass_line_model": self.model_note,
            "checks": _jsonable(self.checks()),
            "theta": self.theta.tolist(),
            "method": self.method,
            "rigid_modes_hz": self.rigid_modes_hz.tolist(),
            "elastic_modes": [
                {"frequency_hz": e.frequency, "damping_ratio": e.damping}
                for e in self.elastic_modes
            ],
            "lines_used": {
                "mass_line": len(self.mass_lines), "stiffness": len(self.stiffness_lines)
            },
            "warnings": list(self.warnings),
            "response_point_corrections": (None if self.point_corrections is None
                                           else self.point_corrections.tolist()),
            "modes": _modes_json(self.M, self.K, self.C, self.D),
            **(_jsonable(self.uncertainty.to_json()) if self.uncertainty else {}),
        }


def _modes_json(M: NDArray[np.float64], K: NDArray[np.float64], C: NDArray[np.float64],
                D: NDArray[np.float64]) -> list[dict[str, Any]]:
    """The six rigid-body modes (docs/conventions.md key ``modes``); empty when M is not positive
    definite (no modes exist)."""
    try:
        return rigid_body_modes(M, K, C, D).to_json()
    except ValueError:
        return []


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj
