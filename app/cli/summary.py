"""Readable terminal summaries of identification results (rich tables)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rich.console import Console
from rich.table import Table

from app.report.mount_system import MountSystem
from app.report.tables import (
    COMPARISON,
    SPREADS,
    comparison_rows,
    contribution_lines,
    half_width,
    modes_text,
    sources_line,
    spread,
)
from processing.identify import IdentificationResult
from processing.inertia import InertiaProperties
from processing.results import Uncertainty

_DOF = ("x", "y", "z", "rx", "ry", "rz")


def _ten(p: InertiaProperties) -> list[tuple[str, str, float, float]]:
    """(label, unit, display value, display scale) for the ten parameters about O."""
    J = p.inertia_origin
    return [
        ("mass", "kg", p.mass, 1.0),
        ("x_c", "mm", p.cog[0] * 1e3, 1.0),
        ("y_c", "mm", p.cog[1] * 1e3, 1.0),
        ("z_c", "mm", p.cog[2] * 1e3, 1.0),
        ("J_xx (O)", "kg m²", J[0, 0], 1.0),
        ("J_yy (O)", "kg m²", J[1, 1], 1.0),
        ("J_zz (O)", "kg m²", J[2, 2], 1.0),
        ("J_xy (O)", "kg m²", -J[0, 1], 1.0),
        ("J_xz (O)", "kg m²", -J[0, 2], 1.0),
        ("J_yz (O)", "kg m²", -J[1, 2], 1.0),
    ]


#: (uncertainty key, index, display scale) of each row of :func:`_ten`
_TEN_KEYS: tuple[tuple[str, tuple[int, ...], float], ...] = (
    ("mass", (), 1.0), ("cog", (0,), 1e3), ("cog", (1,), 1e3), ("cog", (2,), 1e3),
    ("inertia_origin", (0, 0), 1.0), ("inertia_origin", (1, 1), 1.0),
    ("inertia_origin", (2, 2), 1.0), ("inertia_origin", (0, 1), -1.0),
    ("inertia_origin", (0, 2), -1.0), ("inertia_origin", (1, 2), -1.0))


def inertia_table(result: IdentificationResult, truth: InertiaProperties | None = None) -> Table:
    """The ten parameters about O and the principal moments; with ``result.uncertainty`` a
    column of 95 % spreads (± 1.96 std, or the [lo, hi] interval when the result has one)."""
    u = result.uncertainty
    t = Table(title=f"Inertia parameters ({result.method} method)")
    t.add_column("parameter")
    t.add_column("unit")
    t.add_column("identified", justify="right")
    if u is not None:
        t.add_column("95 %", justify="left")
    if truth is not None:
        t.add_column("truth", justify="right")
        t.add_column("error", justify="right")
    rows = _ten(result.properties)
    trows = _ten(truth) if truth is not None else None
    for n, (label, unit, value, _) in enumerate(rows):
        cells = [label, unit, f"{value:.4g}"]
        if u is not None:
            key, index, scale = _TEN_KEYS[n]
            cells.append(spread(u, key, index, scale=scale).strip())
        if trows is not None:
            tv = trows[n][2]
            err = (f"{value - tv:+.3f} mm" if unit == "mm"
                   else f"{(value - tv) / abs(tv) * 100:+.3f} %" if abs(tv) > 1e-9 else "")
            cells += [f"{tv:.4g}", err]
        t.add_row(*cells)
    p = result.properties
    t.add_row("principal moments (CoG)", "kg m²",
              ", ".join(f"{v:.4g}" for v in p.principal_moments),
              *((", ".join(spread(u, "principal_moments", (k,)).strip() for k in range(3)),)
                if u is not None else ()),
              *((", ".join(f"{v:.4g}" for v in truth.principal_moments), "")
                if truth is not None else ()))
    return t


def matrix_table(title: str, A: NDArray[np.float64], truth: NDArray[np.float64] | None = None,
                 std: NDArray[np.float64] | None = None,
                 ci95: NDArray[np.float64] | None = None) -> Table:
    """A 6x6 matrix; with ``std`` (6x6) each cell followed by ± 1.96 std, or with ``ci95``
    (6x6x2) by its [lo, hi] interval."""
    t = Table(title=title)
    t.add_column("")
    for d in _DOF:
        t.add_column(d, justify="right", overflow="fold")  # a narrow screen wraps, never cuts
    scale = np.sqrt(np.abs(np.outer(np.diag(truth if truth is not None else A),
                                    np.diag(truth if truth is not None else A))))
    for i, d in enumerate(_DOF):
        cells = []
        for j in range(6):
            c = f"{A[i, j]:.4g}"
            if ci95 is not None:
                c += f" [{ci95[i, j, 0]:.4g}, {ci95[i, j, 1]:.4g}]"
            elif std is not None:
                c += f" ± {half_width(1.96 * std[i, j])}"
            if truth is not None and scale[i, j] > 0:
                c += f" ({(A[i, j] - truth[i, j]) / scale[i, j] * 100:+.2f}%)"
            cells.append(c)
        t.add_row(d, *cells)
    return t


def checks_table(result: IdentificationResult) -> Table:
    t = Table(title="Checks")
    t.add_column("check")
    t.add_column("verdict")
    t.add_column("figures", overflow="fold")
    for name, c in result.checks().items():
        if c["pass"] is None:  # a check that could not fail: why, no figures
            t.add_row(name, "[yellow]not checked[/yellow]", str(c.get("not_checked", "")))
            continue
        figs = ", ".join(
            f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in c.items() if k not in ("pass", "low_ranges_hz")
        )
        t.add_row(name, "[green]pass[/green]" if c["pass"] else "[red]FAIL[/red]", figs)
    return t


def coherence_line(result: IdentificationResult) -> str:
    """How many FRF values of the bands have a low coherence (weighted down), and where."""
    if not result.coherence_checked:
        why = result.coherence_unchecked or "no coherence in the input"
        return f"Coherence: not checked, {why}; every value weighs the same"
    if result.coherence_low == 0:
        return f"Coherence >= {result.coherence_threshold:g} on every FRF value of the bands"
    ranges = result.coherence_ranges_hz
    where = ", ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in ranges[:8])
    more = f" and {len(ranges) - 8} more ranges" if len(ranges) > 8 else ""
    return (f"Coherence < {result.coherence_threshold:g}: {result.coherence_low} of "
            f"{result.coherence_values} FRF values of the bands "
            f"({result.coherence_low_fraction:.1%}), weighted by their noise, not dropped; "
            f"at {where}{more}")


def print_result(
    result: IdentificationResult,
    console: Console | None = None,
    *,
    truth: InertiaProperties | None = None,
    K_truth: NDArray[np.float64] | None = None,
    C_truth: NDArray[np.float64] | None = None,
) -> None:
    """Print the ten parameters, K and C, the bands and the checks."""
    con = console or Console()
    u = result.uncertainty
    if u is not None:
        con.print(SPREADS, markup=False)
    con.print(inertia_table(result, truth))
    at = ("" if result.stiffening is None
          else f", at {result.stiffening.reference_hz:.3g} Hz: K(f) = K (f / "
               f"{result.stiffening.reference_hz:.3g} Hz)^{result.stiffening.alpha:.4f}")
    con.print(matrix_table(f"Stiffness K at O (N/m, N/rad, N m/m, N m/rad{at})", result.K,
                           K_truth, *_spreads(u, "stiffness")))
    con.print(matrix_table("Damping C at O (N s/m, ...)", result.C, C_truth,
                           *_spreads(u, "damping")))
    if result.damping_model != "viscous":
        con.print(matrix_table("Structural damping D at O (K* = K + jwC + jD; N/m, ...)",
                               result.D, None))
    for note in result.fit_notes:
        con.print(f"{note[0].upper()}{note[1:]}")
    mb, sb = result.mass_band, result.stiffness_band
    con.print(
        f"Bands: mass line {mb[0]:.1f}-{mb[1]:.1f} Hz ({len(result.mass_lines)} lines), "
        f"stiffness {sb[0]:.1f}-{sb[1]:.1f} Hz ({len(result.stiffness_lines)} lines); "
        f"rigid-body modes {modes_text(result.rigid_modes_hz, u, '.1f')} Hz; "
        + (
            "elastic modes " + ", ".join(f"{e.frequency:.1f} Hz" for e in result.elastic_modes)
            if result.elastic_modes else "no elastic mode in the data"
        )
    )
    if u is not None:
        print_uncertainty(u, con)
    con.print(checks_table(result))
    con.print(coherence_line(result))
    for w in result.warnings:
        con.print(f"[yellow]warning:[/yellow] {w}")


def _spreads(u: Uncertainty | None, key: str
             ) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """(std, ci95) of ``key`` for :func:`matrix_table`, None where not known."""
    if u is None:
        return None, None
    return u.std.get(key), u.ci95.get(key)


def print_uncertainty(u: Uncertainty, console: Console | None = None, top: int = 6) -> None:
    """What the ± propagate and the inputs that contribute most, in one short block."""
    con = console or Console()
    con.print(sources_line(u), markup=False)
    lines = contribution_lines(u, top)
    if lines:
        con.print("Largest contributions to the variance:")
        for line in lines:
            con.print(f"  {line}", markup=False)


def print_comparison(prediction: Mapping[str, Any], u: Uncertainty | None,
                     console: Console | None = None) -> None:
    """The plan's predicted std beside the identification's own (as the HTML report)."""
    con = console or Console()
    con.print(_rich_table("Predicted and achieved uncertainty (standard deviations)",
                          ["parameter", "unit", "predicted std", "achieved std",
                           "achieved / predicted"],
                          [list(r) for r in comparison_rows(prediction, u)], left=2))
    con.print(COMPARISON, markup=False)


def _rich_table(title: str, head: list[str], rows: list[list[str]], left: int = 1) -> Table:
    t = Table(title=title)
    for i, h in enumerate(head):
        t.add_column(h, justify="left" if i < left else "right")
    for r in rows:
        t.add_row(*r)
    return t


def print_mount_system(ms: MountSystem, console: Console | None = None, *,
                       spreads: bool = False) -> None:
    """Print the modes, the energy decoupling, and with mounts the rates and the TRA (their
    spreads as :data:`~app.report.tables.SPREADS` says: printed here when ``spreads``, i.e.
    when :func:`print_result` did not)."""
    con = console or Console()
    if spreads and ms.rates is not None:
        con.print(SPREADS, markup=False)
    con.print(_rich_table("Rigid-body modes of the identified M, K, C (damping: modal "
                          "approximation)", ms.mode_head(), ms.mode_rows()))
    con.print(_rich_table("Kinetic-energy decoupling (% of each mode's energy, at the CoG)",
                          ["mode", *_DOF], ms.energy_rows()))
    if ms.modes is not None:
        con.print(f"Mode shapes at O (mass-normalised) are in the result JSON; largest "
                  f"off-diagonal modal damping coupling {ms.modes.damping_coupling:.3f} "
                  "(small: the modal damping approximation holds)")
    for w in ms.problems:
        con.print(f"[yellow]warning:[/yellow] {w}")
    if ms.rates is not None:
        rows = ms.mount_rows()
        for row in rows:
            if row[-1] == "NO":
                row[-1] = "[red]NO[/red]"
        con.print(_rich_table("Individual mount rates (non-negative least squares on K and C)",
                              ms.mount_head(), rows, left=2))
        for n in ms.mount_notes():
            con.print(n)
    if ms.tra is not None:
        con.print(_rich_table("Torque roll axis and the mounts' elastic axis",
                              ["quantity", "value"], ms.tra_rows(), left=2))
