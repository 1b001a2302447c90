"""The mount-system analysis of one identification, for the CLI, the report and the GUI.

:func:`mount_system` takes an :class:`~processing.identify.IdentificationResult` and,
optionally, the mounts file; it returns the modes (always), the isolation against an
excitation frequency, the individual mount rates and the torque roll axis (with mounts),
their result-JSON keys (docs/conventions.md: ``modes``, ``mounts``, ``torque_roll_axis``) and the
text rows of their tables. Pure computation, no Qt.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.io.mounts import MountsFile
from app.report.tables import Z95, half_width
from processing.identify import IdentificationResult
from processing.modes import (
    Isolation,
    ModeSet,
    TorqueRollAxis,
    isolation,
    rigid_body_modes,
    torque_roll_axis,
)
from processing.mounts import MountRates, identify_mount_rates

__all__ = ["MountSystem", "default_loss_factor_hz", "mount_system"]


def default_loss_factor_hz(modes: ModeSet | None, stiffness_band: tuple[float, float]) -> float:
    """Geometric mean of the positive rigid-body mode frequencies, Hz (where the mounts'
    damping acts on the body); the stiffness band's centre without modes."""
    f = modes.frequency_hz[modes.frequency_hz > 0] if modes is not None else np.zeros(0)
    if f.size:
        return float(np.exp(np.mean(np.log(f))))
    return max(0.5 * (stiffness_band[0] + stiffness_band[1]), 1e-3)


@dataclass(frozen=True)
class MountSystem:
    """Modes, isolation, mount rates and torque roll axis of one identification.

    ``modes`` (and ``tra``) are None when the identified inertia is not positive definite;
    ``problems`` then says so in one line each.
    """

    modes: ModeSet | None
    isolation: Isolation | None
    mounts: MountsFile | None
    rates: MountRates | None
    tra: TorqueRollAxis | None
    problems: tuple[str, ...] = ()
    #: the identified centre of gravity, m
    cog: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))

    def to_json(self) -> dict[str, Any]:
        """``modes`` always (empty without a positive-definite M); ``mounts``,
        ``torque_roll_axis`` and ``mount_fit`` with mounts."""
        out: dict[str, Any] = {
            "modes": self.modes.to_json(self.isolation) if self.modes is not None else []}
        if self.problems:
            out["mount_system_problems"] = list(self.problems)
        if self.isolation is not None:
            out["excitation_hz"] = self.isolation.excitation_hz
        if self.rates is not None:
            k = self.rates.stiffness
            out["mounts"] = self.rates.to_json()
            out["mount_fit"] = {
                "rank": k.rank, "n_rates": int(k.rates.size),
                "cond": k.cond if np.isfinite(k.cond) else None,
                "relative_residual": k.residual, "residual_dof": k.dof,
                "undetermined": k.undetermined(),
            }
        if self.tra is not None:
            out["torque_roll_axis"] = self.tra.to_json()
        return out

    # --- table rows (text) ------------------------------------------------------------------
    def mode_rows(self) -> list[list[str]]:
        """Mode, frequency (Hz), damping (%), dominant DOF [, ratio, margin, transmissibility]."""
        m, iso = self.modes, self.isolation
        if m is None:
            return []
        rows = []
        for r in range(6):
            row = [str(r + 1), f"{m.frequency_hz[r]:.2f}", f"{m.damping_ratio[r] * 100:.2f}",
                   m.dominant()[r]]
            if iso is not None:
                row += [f"{iso.ratio[r]:.2f}", f"{iso.margin[r]:.2f}"
                        + ("" if iso.isolated[r] else " (NOT isolated)"),
                        f"{iso.transmissibility[r]:.3f}"]
            rows.append(row)
        return rows

    def mode_head(self) -> list[str]:
        head = ["mode", "frequency (Hz)", "damping (%)", "dominant"]
        if self.isolation is not None:
            head += [f"f_e / f ({self.isolation.excitation_hz:g} Hz)", "margin (÷√2)",
                     "T at f_e"]
        return head

    def energy_rows(self) -> list[list[str]]:
        """Mode, then the percentage of its kinetic energy in x, y, z, rx, ry, rz."""
        if self.modes is None:
            return []
        E = self.modes.energy
        return [[f"{r + 1} ({self.modes.frequency_hz[r]:.2f} Hz)",
                 *(f"{E[k, r] * 100:.1f}" for k in range(6))] for r in range(6)]

    def shape_rows(self) -> list[list[str]]:
        """Mode, then its mass-normalised shape at O (m, rad per sqrt(kg) m)."""
        if self.modes is None:
            return []
        V = self.modes.shapes
        return [[str(r + 1), *(f"{V[k, r]:+.4f}" for k in range(6))] for r in range(6)]

    def mount_rows(self) -> list[list[str]]:
        """Mount, axis, rate (N/m), its 95 % spread, loss factor, its 95 % spread, determined.

        The spreads are those of every other table (:func:`app.report.tables.spread`): the
        rate's 95 % interval (:meth:`processing.mounts.RateFit.ci95`) as ``± h``, or as
        ``[lo, hi]`` where it is clipped at 0; the loss factor's ``± 1.96 std``."""
        if self.rates is None:
            return []
        k, eta, eta_s = self.rates.stiffness, self.rates.loss_factors, self.rates.loss_factors_std
        ci = k.ci95()
        rows = []
        for i, name in enumerate(k.names):
            for a, axis in enumerate("uvw"):
                ok = bool(k.identifiable[i, a])
                rows.append([name if a == 0 else "", axis, f"{k.rates[i, a]:.4g}",
                             _rate_spread(k.rates[i, a], ci[i, a]), _num(eta[i, a], ".3f"),
                             _half(Z95 * eta_s[i, a]), "yes" if ok else "NO"])
        return rows

    def mount_head(self) -> list[str]:
        """Column titles of :meth:`mount_rows`; the loss factor is ``d / k`` when the damping
        is structural only (no frequency), else at the loss-factor frequency."""
        r = self.rates
        f = r.loss_factor_hz if r is not None else 0.0
        eta = ("loss factor d/k" if r is not None and r.damping is None
               and r.structural is not None else f"loss factor at {f:.3g} Hz")
        return ["mount", "axis", "rate (N/m)", "95 % (N/m)", eta, "95 %", "determined"]

    def mount_notes(self) -> list[str]:
        """Rank and condition of the fit and one line per undetermined combination."""
        if self.rates is None:
            return []
        k = self.rates.stiffness
        cond = f"{k.cond:.3g}" if np.isfinite(k.cond) else "inf"
        notes = [f"design 21 x {k.rates.size}: rank {k.rank}, condition {cond}; relative "
                 f"residual {k.residual:.2%} ({k.dof} residual degrees of freedom); 95 % "
                 + ("intervals from the identified K's uncertainty" if k.known_variance else
                    "intervals from the fit's residual (Student's t)")]
        return notes + k.undetermined()

    def tra_rows(self) -> list[list[str]]:
        """Quantity, value for the torque roll axis and the elastic axis."""
        t = self.tra
        if t is None:
            return []
        rows = [["crank axis", _vec(t.crank_axis)],
                ["torque roll axis: direction", _vec(t.direction)],
                ["torque roll axis: point (CoG), mm", _vec(t.point * 1e3, ".1f")],
                ["angle TRA to crank axis", f"{t.angle_to_crank_deg:.2f}°"]]
        ea = t.elastic_axis
        if ea is None:
            rows.append(["elastic axis", t.note])
        else:
            rows += [["elastic axis: direction", _vec(ea.direction)],
                     ["elastic axis: point nearest the CoG, mm", _vec(ea.point * 1e3, ".1f")],
                     ["elastic axis: pitch", f"{ea.pitch * 1e3:.3g} mm/rad"],
                     ["angle TRA to elastic axis", f"{t.angle_deg:.2f}°"],
                     ["distance CoG to elastic axis", f"{t.distance_m * 1e3:.1f} mm"]]
        return rows


def _num(v: float, fmt: str) -> str:
    return format(float(v), fmt) if np.isfinite(v) else "—"


def _half(h: float) -> str:
    return "± " + half_width(float(h)) if np.isfinite(h) else "—"


def _rate_spread(rate: float, interval: NDArray[np.float64]) -> str:
    """A rate's 95 % interval as ``± h``, or ``[lo, hi]`` where it was clipped at 0."""
    lo, hi = (float(v) for v in interval)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "—"
    if lo > 0:
        return _half(hi - float(rate))
    return f"[{lo:.4g}, {hi:.4g}]"


def _vec(v: np.ndarray, fmt: str = "+.4f") -> str:
    return "[" + ", ".join(format(float(x), fmt) for x in v) + "]"


def mount_system(
    result: IdentificationResult,
    mounts: MountsFile | None = None,
    excitation_hz: float | None = None,
    loss_factor_hz: float | None = None,
) -> MountSystem:
    """Analyse the identified M, K, C (and the mounts when given).

    Parameters
    ----------
    result : the identification
    mounts : the mounts file's content, or None (modes only)
    excitation_hz : excitation frequency for the isolation margin, Hz, or None
    loss_factor_hz : frequency of the mounts' loss factors, Hz (default
        :func:`default_loss_factor_hz`)

    Raises
    ------
    ValueError
        (:class:`~processing.mounts.MountGeometryError`) when the mounts determine no rate.
    """
    problems: list[str] = []
    modes: ModeSet | None = None
    try:
        modes = rigid_body_modes(result.M, result.K, result.C, result.D)
        problems += modes.warnings
    except ValueError as err:
        problems.append(f"no modes: {err}")
    iso = isolation(modes, excitation_hz) if excitation_hz is not None and modes else None
    if mounts is None:
        return MountSystem(modes, iso, None, None, None, tuple(problems),
                           result.properties.cog)
    f_eta = (loss_factor_hz if loss_factor_hz is not None
             else default_loss_factor_hz(modes, result.stiffness_band))
    # the damping model's parts only: C for viscous, D for structural, both for both
    C = result.C if np.any(result.C) else None
    cov = result.uncertainty.covariance if result.uncertainty is not None else None
    rates = identify_mount_rates(
        mounts.mounts, result.K, C, f_eta, D=result.D,
        K_cov=None if cov is None else cov[10:46, 10:46],
        C_cov=None if cov is None or C is None else cov[46:, 46:])
    tra: TorqueRollAxis | None = None
    try:
        tra = torque_roll_axis(result.M, result.K, mounts.crank_axis)
    except ValueError as err:
        problems.append(f"no torque roll axis: {err}")
    return MountSystem(modes, iso, mounts, rates, tra, tuple(problems), result.properties.cog)
