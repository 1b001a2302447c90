"""Rows of the result tables and the checks, shared by the GUI's views and the report.

Values are converted for display here once: CoG in mm, inertia in kg m², products of
inertia with the article's sign (``Jxy = integral of x y dm``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.report.analysis import Analysis
from processing.geometry import DEFAULT_MAX_COND_T
from processing.identify import coherence_unchecked
from processing.inertia import InertiaProperties
from processing.results import Uncertainty

__all__ = ["COMPARISON", "PLANNED", "SPREADS", "CheckRow", "check_rows", "comparison_rows",
           "contribution_lines", "format_matrix", "half_width", "inertia_rows", "modes_text",
           "predicted_rows", "principal_rows", "quantity_label", "sources_line", "spread"]

#: half-width of a 95 % interval in standard deviations (normal distribution)
Z95 = 1.96

#: the one convention of every spread every view shows, stated once in its header
SPREADS = ("Spreads are 95 %: ± 1.96 standard deviations, or the [lo, hi] interval where "
           "it is not symmetric (the result JSON's std are standard deviations, its ci95 "
           "the intervals)")


def spread(u: Uncertainty | None, key: str, index: tuple[int, ...] = (), *,
           scale: float = 1.0, fmt: str = ".4g") -> str:
    """The 95 % spread of one identified number as text to append to its value.

    Parameters
    ----------
    u : the result's uncertainty, or None
    key : a key of :data:`processing.results.UNCERTAIN_KEYS` (``"cog"``, ``"stiffness"``, ...)
    index : the number's index in that key's array (``()`` for the mass)
    scale : display factor applied to the value (1e3 for m to mm, -1 for a product of
        inertia shown with the article's sign)
    fmt : format of the interval's ends (the value's own format)

    Returns
    -------
    str
        ``" [lo, hi]"`` when ``u.ci95`` holds the key, else ``" ± h"`` with
        ``h = 1.96 std`` (two significant digits), else ``""`` (no uncertainty known).
    """
    if u is None:
        return ""
    if key in u.ci95:
        lo, hi = sorted(float(v) * scale for v in np.asarray(u.ci95[key])[index])
        return f" [{lo:{fmt}}, {hi:{fmt}}]"
    if key in u.std:
        return " ± " + half_width(Z95 * float(np.asarray(u.std[key])[index]) * abs(scale))
    return ""


def half_width(h: float) -> str:
    """A 95 % half-width as text: two significant digits (``0.27``, ``36``, ``2.3e+05``)."""
    return f"{h:.2g}"


_QUANTITY = {"mass": "mass", "cog": "CoG", "inertia_cog": "J about the CoG",
             "inertia_origin": "J about O", "principal_moments": "principal moment",
             "stiffness": "K", "damping": "C", "rigid_modes_hz": "rigid mode"}


def quantity_label(quantity: str) -> str:
    """A contribution's quantity as the views show it: ``"cog z"`` -> ``"CoG z"``,
    ``"inertia_cog xy"`` -> ``"J_xy about the CoG"``; unknown names unchanged."""
    key, _, rest = quantity.partition(" ")
    if key in ("inertia_cog", "inertia_origin") and rest:
        return f"J_{rest} {_QUANTITY[key][2:]}"
    return f"{_QUANTITY.get(key, key)} {rest}".strip()


def contribution_lines(u: Uncertainty | None, top: int = 6) -> list[str]:
    """The largest contributions, one line each (``"CoG z: 70 % from point 3 location"``),
    at most ``top`` of them and a last line counting the others; empty without any."""
    if u is None or not u.contributions:
        return []
    lines = [f"{quantity_label(c.quantity)}: {c.fraction * 100:.0f} % from {c.source}"
             for c in u.contributions[:top]]
    if len(u.contributions) > top:
        lines.append(f"({len(u.contributions) - top} smaller contributions in the result JSON)")
    return lines

_PAIRS = (("J_xx", 0, 0, 1.0), ("J_yy", 1, 1, 1.0), ("J_zz", 2, 2, 1.0),
          ("J_xy", 0, 1, -1.0), ("J_xz", 0, 2, -1.0), ("J_yz", 1, 2, -1.0))


def modes_text(freq: NDArray[np.float64], u: Uncertainty | None = None, fmt: str = ".2f"
               ) -> str:
    """The rigid-body mode frequencies, Hz, comma-separated, each with its 95 % spread."""
    return ", ".join(f"{f:{fmt}}" + spread(u, "rigid_modes_hz", (k,), fmt=fmt)
                     for k, f in enumerate(np.asarray(freq)))


def sources_line(u: Uncertainty | None) -> str:
    """One sentence saying what the uncertainty propagates; empty without one."""
    if u is None:
        return ""
    what = "; ".join(u.sources) if u.sources else "sources not stated"
    return f"Uncertainty: {what}"


def inertia_rows(p: InertiaProperties, u: Uncertainty | None = None
                 ) -> list[tuple[str, str, str, str]]:
    """(parameter, unit, about the CoG, about the origin O) for the ten parameters.

    Mass and CoG are the same in both frames; the CoG column gives the CoG's coordinates
    in the global frame (it is the origin of the CoG frame). With ``u``, each value is
    followed by its 95 % spread (:func:`spread`).
    """
    m = f"{p.mass:.3f}" + spread(u, "mass", fmt=".3f")
    rows = [("mass m", "kg", m, m)]
    for k, axis in enumerate("xyz"):
        c = f"{p.cog[k] * 1e3:.2f}" + spread(u, "cog", (k,), scale=1e3, fmt=".2f")
        rows.append((f"CoG {axis}_c", "mm", c, c))
    for name, i, j, sign in _PAIRS:
        rows.append((name, "kg m²",
                     f"{sign * p.inertia_cog[i, j]:.4f}"
                     + spread(u, "inertia_cog", (i, j), scale=sign, fmt=".4f"),
                     f"{sign * p.inertia_origin[i, j]:.4f}"
                     + spread(u, "inertia_origin", (i, j), scale=sign, fmt=".4f")))
    return rows


def principal_rows(p: InertiaProperties, u: Uncertainty | None = None
                   ) -> list[tuple[str, str, str, str, str]]:
    """(name, moment kg m², axis x, axis y, axis z) of the principal moments about the CoG
    (with ``u``, each moment followed by its 95 % spread)."""
    ax = p.principal_axes
    return [
        (f"J_{k + 1}", f"{p.principal_moments[k]:.4f}"
         + spread(u, "principal_moments", (k,), fmt=".4f"),
         f"{ax[0, k]:+.4f}", f"{ax[1, k]:+.4f}", f"{ax[2, k]:+.4f}")
        for k in range(3)
    ]


def format_matrix(A: NDArray[np.float64], u: Uncertainty | None = None,
                  key: str = "stiffness") -> list[list[str]]:
    """6x6 matrix as text cells, four significant digits; with ``u``, each cell followed by
    its 95 % spread from ``u``'s ``key`` (``"stiffness"`` or ``"damping"``)."""
    A = np.asarray(A)
    return [[f"{A[i, j]:.4g}" + spread(u, key, (i, j)) for j in range(A.shape[1])]
            for i in range(A.shape[0])]


@dataclass(frozen=True)
class CheckRow:
    """One check: its name, verdict (None when it could not be made) and the figures."""

    name: str
    passed: bool | None
    detail: str

    @property
    def verdict(self) -> str:
        return {True: "PASS", False: "FAIL", None: "not checked"}[self.passed]


def check_rows(a: Analysis) -> list[CheckRow]:
    """The checks of the article (coherence, rigidity, synthesis) and ours, with verdicts."""
    rows: list[CheckRow] = []
    g = a.geometry
    if g is None:
        rows.append(CheckRow("geometry (rank, cond of E and T)", False, a.error or ""))
    else:
        ok = g.ok and g.cond_T <= DEFAULT_MAX_COND_T
        detail = (f"rank E {g.rank_E}, cond E {g.cond_E:.1f}; rank T {g.rank_T}, "
                  f"cond T {g.cond_T:.1f} (limit {DEFAULT_MAX_COND_T:g})")
        if g.messages:
            detail += ": " + "; ".join(g.messages)
        rows.append(CheckRow("geometry (rank, cond of E and T)", ok, detail))
    gate = a.gate
    thr = a.options.coherence_threshold
    unchecked = coherence_unchecked(a.measurement)
    if gate is None or unchecked:
        rows.append(CheckRow(f"coherence ≥ {thr:g}", None, unchecked + (
            "; it needs several hits or blocks a point" if gate is not None else "")))
    else:
        rows.append(CheckRow(f"coherence ≥ {thr:g}", gate.n_dropped == 0, gate.summary()))
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


_K_UNITS = ("N/m", "N/m", "N/m", "N m/rad", "N m/rad", "N m/rad")

#: the numbers a plan predicts and the report compares with the achieved ones: (parameter,
#: unit, key of the std, index, display scale); products of inertia have the same std in
#: either sign convention
PLANNED: tuple[tuple[str, str, str, tuple[int, ...], float], ...] = (
    ("mass m", "kg", "mass", (), 1.0),
    *((f"CoG {a}_c", "mm", "cog", (k,), 1e3) for k, a in enumerate("xyz")),
    *((f"{name} about the CoG", "kg m²", "inertia_cog", (i, j), 1.0)
      for name, i, j, _ in _PAIRS),
    *((f"K {d}", u, "stiffness", (k, k), 1.0)
      for k, (d, u) in enumerate(zip(("xx", "yy", "zz", "rx rx", "ry ry", "rz rz"), _K_UNITS,
                                     strict=True))),
)


def _std(std: Mapping[str, Any], key: str, index: tuple[int, ...], scale: float
         ) -> float | None:
    """One std in display units, or None when ``std`` lacks it."""
    if key not in std:
        return None
    a = np.asarray(std[key], dtype=float)
    try:
        return float(a[index]) * abs(scale)
    except IndexError:
        return None


def predicted_rows(std: Mapping[str, Any]) -> list[tuple[str, str, str, str]]:
    """(parameter, unit, predicted std, 95 % half-width) of :data:`PLANNED` for the std of a
    plan's prediction (SI; :attr:`processing.planning.Prediction.std` or a ``[prediction]``
    table); the half-width ``± 1.96 std`` as every view shows spreads."""
    rows = []
    for name, unit, key, index, scale in PLANNED:
        s = _std(std, key, index, scale)
        rows.append((name, unit, "—" if s is None else f"{s:.3g}",
                     "—" if s is None else "± " + half_width(Z95 * s)))
    return rows


def comparison_rows(prediction: Mapping[str, Any], u: Uncertainty | None
                    ) -> list[tuple[str, str, str, str, str]]:
    """(parameter, unit, predicted std, achieved std, achieved / predicted) of :data:`PLANNED`:
    the plan's ``[prediction]`` table beside the identification's own uncertainty
    (``u``, the result's; "—" where either is unknown)."""
    achieved: Mapping[str, Any] = {} if u is None else u.std
    rows = []
    for name, unit, key, index, scale in PLANNED:
        p, a = _std(prediction, key, index, scale), _std(achieved, key, index, scale)
        ratio = f"{a / p:.3g}" if p is not None and a is not None and p > 0 else "—"
        rows.append((name, unit, "—" if p is None else f"{p:.3g}",
                     "—" if a is None else f"{a:.3g}", ratio))
    return rows


#: the comparison's heading, as the report and ``insitu identify`` print it
COMPARISON = ("Predicted beside achieved: the standard deviations insitu plan predicted for "
              "this layout (the plan's [prediction]) and the identification's own; a ratio "
              "over 1 means the test knows the number less well than planned")
