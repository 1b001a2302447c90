"""Rows of the result tables and the checks, shared by the GUI's views and the report.

Values are converted for display here once: CoG in mm, inertia in kg m², products of
inertia with the article's sign (``Jxy = integral of x y dm``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from app.report.analysis import Analysis
from processing.inertia import InertiaProperties

__all__ = ["CheckRow", "check_rows", "format_matrix", "inertia_rows", "principal_rows"]

_PAIRS = (("J_xx", 0, 0, 1.0), ("J_yy", 1, 1, 1.0), ("J_zz", 2, 2, 1.0),
          ("J_xy", 0, 1, -1.0), ("J_xz", 0, 2, -1.0), ("J_yz", 1, 2, -1.0))


def inertia_rows(p: InertiaProperties) -> list[tuple[str, str, str, str]]:
    """(parameter, unit, about the CoG, about the origin O) for the ten parameters.

    Mass and CoG are the same in both frames; the CoG column gives the CoG's coordinates
    in the global frame (it is the origin of the CoG frame).
    """
    rows = [("mass m", "kg", f"{p.mass:.3f}", f"{p.mass:.3f}")]
    for k, axis in enumerate("xyz"):
        rows.append((f"CoG {axis}_c", "mm", f"{p.cog[k] * 1e3:.2f}", f"{p.cog[k] * 1e3:.2f}"))
    for name, i, j, sign in _PAIRS:
        rows.append((name, "kg m²", f"{sign * p.inertia_cog[i, j]:.4f}",
                     f"{sign * p.inertia_origin[i, j]:.4f}"))
    return rows


def principal_rows(p: InertiaProperties) -> list[tuple[str, str, str, str, str]]:
    """(name, moment kg m², axis x, axis y, axis z) of the principal moments about the CoG."""
    ax = p.principal_axes
    return [
        (f"J_{k + 1}", f"{p.principal_moments[k]:.4f}",
         f"{ax[0, k]:+.4f}", f"{ax[1, k]:+.4f}", f"{ax[2, k]:+.4f}")
        for k in range(3)
    ]


def format_matrix(A: NDArray[np.float64]) -> list[list[str]]:
    """6x6 matrix as text cells, four significant digits."""
    return [[f"{v:.4g}" for v in row] for row in np.asarray(A)]


@dataclass(frozen=True)
class CheckRow:
    """One check: its name, verdict (None when it could not be made) and the figures."""

    name: str
    passed: bool | None
    detail: str

    @property
    def verdict(self) -> str:
        return {True: "PASS", False: "FAIL", None: "n/a"}[self.passed]


def check_rows(a: Analysis) -> list[CheckRow]:
    """The checks of the article (coherence, rigidity, synthesis) and ours, with verdicts."""
    rows: list[CheckRow] = []
    g = a.geometry
    if g is None:
        rows.append(CheckRow("geometry (rank, cond of E and T)", False, a.error or ""))
    else:
        ok = g.ok and g.cond_T <= a.options.max_cond_T
        detail = (f"rank E {g.rank_E}, cond E {g.cond_E:.1f}; rank T {g.rank_T}, "
                  f"cond T {g.cond_T:.1f} (limit {a.options.max_cond_T:g})")
        if g.messages:
            detail += ": " + "; ".join(g.messages)
        rows.append(CheckRow("geometry (rank, cond of E and T)", ok, detail))
    gate = a.gate
    thr = a.options.coherence_threshold
    if gate is None:
        rows.append(CheckRow(f"coherence ≥ {thr:g}", None, "no coherence in the data"))
    else:
        detail = gate.summary()
        n_avg = np.asarray(a.frf.meta.get("n_averages", []), dtype=float)
        if n_avg.size and n_avg.max() <= 1:
            detail += ("; one average per point: coherence is 1 by definition, this check "
                       "needs several hits or blocks per point")
        rows.append(CheckRow(f"coherence ≥ {thr:g}", gate.n_dropped == 0, detail))
    rig = a.rigidity
    if rig is None:
        rows.append(CheckRow("rigidity (sensors predict each other)", None,
                             a.rigidity_error or ""))
    else:
        ok = rig.band is not None
        if ok and a.result is not None and rig.band is not None:
            ok = rig.band[1] >= a.result.mass_band[1]
            detail = rig.summary() + (
                "" if ok else f"; the mass line reaches {a.result.mass_band[1]:g} Hz")
        else:
            detail = rig.summary()
        rows.append(CheckRow("rigidity (sensors predict each other)", ok, detail))
    r = a.result
    if r is None:
        rows.append(CheckRow("identification", False, a.error or ""))
        return rows
    c = r.checks()
    rows.append(CheckRow("identification converged", r.converged,
                         f"{r.iterations} iterations, {len(r.mass_lines)} mass-line and "
                         f"{len(r.stiffness_lines)} stiffness lines"))
    pc = c["physical_consistency"]
    rows.append(CheckRow(
        "physical consistency of the inertia", bool(pc["pass"]),
        f"positive definite: {'yes' if pc['positive_definite'] else 'NO'}; "
        f"J1 + J2 ≥ J3: {'yes' if pc['triangle_inequality'] else 'NO'} "
        f"(margin {pc['triangle_margin']:+.3f})" + ("; enforced" if pc["enforced"] else "")))
    rows.append(CheckRow(
        "synthesised vs measured FRFs", r.synthesis.overall < 0.1,
        f"error {r.synthesis.overall:.2%} overall, worst FRF "
        f"{float(np.max(r.synthesis.per_frf)):.2%}, {r.synthesis.band[0]:.1f}-"
        f"{r.synthesis.band[1]:.1f} Hz (limit 10 %)"))
    return rows
