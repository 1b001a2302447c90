"""Readable terminal summaries of identification results (rich tables)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from rich.console import Console
from rich.table import Table

from app.report.mount_system import MountSystem
from processing.identify import IdentificationResult
from processing.inertia import InertiaProperties

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


def inertia_table(result: IdentificationResult, truth: InertiaProperties | None = None) -> Table:
    t = Table(title=f"Inertia parameters ({result.method} method)")
    t.add_column("parameter")
    t.add_column("unit")
    t.add_column("identified", justify="right")
    if truth is not None:
        t.add_column("truth", justify="right")
        t.add_column("error", justify="right")
    rows = _ten(result.properties)
    trows = _ten(truth) if truth is not None else None
    for n, (label, unit, value, _) in enumerate(rows):
        cells = [label, unit, f"{value:.4g}"]
        if trows is not None:
            tv = trows[n][2]
            err = (f"{value - tv:+.3f} mm" if unit == "mm"
                   else f"{(value - tv) / abs(tv) * 100:+.3f} %" if abs(tv) > 1e-9 else "")
            cells += [f"{tv:.4g}", err]
        t.add_row(*cells)
    p = result.properties
    t.add_row("principal moments (CoG)", "kg m²",
              ", ".join(f"{v:.4g}" for v in p.principal_moments),
              *((", ".join(f"{v:.4g}" for v in truth.principal_moments), "")
                if truth is not None else ()))
    return t


def matrix_table(title: str, A: NDArray[np.float64], truth: NDArray[np.float64] | None = None
                 ) -> Table:
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
        figs = ", ".join(
            f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in c.items() if k not in ("pass", "dropped_ranges_hz")
        )
        t.add_row(name, "[green]pass[/green]" if c["pass"] else "[red]FAIL[/red]", figs)
    return t


def coherence_line(result: IdentificationResult) -> str:
    """How many (excitation, line) values the coherence gate dropped in the bands, and where."""
    if not result.coherence_checked:
        return "Coherence: not measured (no coherence in the input), nothing dropped"
    if result.coherence_dropped == 0:
        return f"Coherence >= {result.coherence_threshold:g} on every line of the bands"
    ranges = result.coherence_ranges_hz
    where = ", ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in ranges[:8])
    more = f" and {len(ranges) - 8} more ranges" if len(ranges) > 8 else ""
    return (f"Coherence < {result.coherence_threshold:g}: {result.coherence_dropped} "
            f"(excitation, line) values dropped from the bands, at {where}{more}")


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
    con.print(inertia_table(result, truth))
    con.print(matrix_table("Stiffness K at O (N/m, N/rad, N m/m, N m/rad)", result.K, K_truth))
    con.print(matrix_table("Damping C at O (N s/m, ...)", result.C, C_truth))
    if result.damping_model != "viscous":
        con.print(matrix_table("Structural damping D at O (K* = K + jwC + jD; N/m, ...)",
                               result.D, None))
    if result.damping_note:
        con.print(f"{result.damping_note[0].upper()}{result.damping_note[1:]}")
    mb, sb = result.mass_band, result.stiffness_band
    con.print(
        f"Bands: mass line {mb[0]:.1f}-{mb[1]:.1f} Hz ({len(result.mass_lines)} lines), "
        f"stiffness {sb[0]:.1f}-{sb[1]:.1f} Hz ({len(result.stiffness_lines)} lines); "
        f"rigid-body modes {', '.join(f'{f:.1f}' for f in result.rigid_modes_hz)} Hz; "
        + (
            "elastic modes " + ", ".join(f"{e.frequency:.1f} Hz" for e in result.elastic_modes)
            if result.elastic_modes else "no elastic mode in the data"
        )
    )
    con.print(checks_table(result))
    con.print(coherence_line(result))
    for w in result.warnings:
        con.print(f"[yellow]warning:[/yellow] {w}")


def _rich_table(title: str, head: list[str], rows: list[list[str]], left: int = 1) -> Table:
    t = Table(title=title)
    for i, h in enumerate(head):
        t.add_column(h, justify="left" if i < left else "right")
    for r in rows:
        t.add_row(*r)
    return t


def print_mount_system(ms: MountSystem, console: Console | None = None) -> None:
    """Print the modes, the energy decoupling, and with mounts the rates and the TRA."""
    con = console or Console()
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
