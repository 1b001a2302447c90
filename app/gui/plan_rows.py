"""The test plan as the Plan view edits it: one row per measured or excited DOF.

A row is a response DOF (an accelerometer axis) or an excitation DOF (a hit or shaker
direction) with its node, coordinates (m) and unit direction in the global frame. Rows come
from a CSV file, a UFF FRF file, an acquisition plan (TOML, with its station for the
response directions) or the table itself; :func:`check_rows_geometry` checks them with
:func:`processing.geometry.check_geometry` before any hit is made.

CSV format (header required, one row per DOF)::

    role,node,x,y,z,dx,dy,dz
    response,1,0.20,0.00,0.26,1,0,0
    excitation,101,0.25,0.10,0.20,1,0,0
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from app.acquire.plan import TestPlan
from drivers.station import StationConfig
from processing.data import FRFSet, InputError
from processing.geometry import GeometryReport, check_geometry

__all__ = [
    "CSV_HEADER",
    "PlanRow",
    "check_rows_geometry",
    "read_csv_rows",
    "rows_from_frf",
    "rows_from_plan",
    "write_csv_rows",
]

Role = Literal["response", "excitation"]
CSV_HEADER = ("role", "node", "x", "y", "z", "dx", "dy", "dz")


@dataclass(frozen=True)
class PlanRow:
    """One DOF of the plan: role, node, coordinates (m), unit direction, optional label."""

    role: Role
    node: int
    xyz: tuple[float, float, float]
    direction: tuple[float, float, float]
    label: str = ""


def _unit(d: Sequence[float], where: str) -> tuple[float, float, float]:
    a = np.asarray(d, dtype=float)
    n = float(np.linalg.norm(a))
    if not np.isfinite(n) or n == 0:
        raise InputError(f"{where}: the direction must be a non-zero vector, got {list(d)}")
    a = a / n
    return (float(a[0]), float(a[1]), float(a[2]))


def rows_from_frf(frf: FRFSet) -> list[PlanRow]:
    """The DOFs of an FRF set (response DOFs first, then excitations, in the set's order)."""
    rows = [PlanRow("response", int(n), tuple(map(float, x)), tuple(map(float, d)))  # type: ignore[arg-type]
            for n, x, d in zip(frf.resp_nodes, frf.resp_xyz, frf.resp_dirs, strict=True)]
    rows += [PlanRow("excitation", int(n), tuple(map(float, x)), tuple(map(float, d)))  # type: ignore[arg-type]
             for n, x, d in zip(frf.exc_nodes, frf.exc_xyz, frf.exc_dirs, strict=True)]
    return rows


def rows_from_plan(plan: TestPlan, station: StationConfig | None) -> list[PlanRow]:
    """The DOFs of an acquisition plan; response directions from the station's channels.

    Without a station, or a channel it does not know, responses are assumed triaxial along
    the global axes in the order of the point's channels (x, y, z).
    """
    by_name = ({c.name: c for d in station.devices.values() for c in d.channels}
               if station is not None else {})
    rows: list[PlanRow] = []
    axes = np.eye(3)
    for r in plan.responses:
        for k, name in enumerate(r.channels):
            ch = by_name.get(name)
            d = ch.direction if ch is not None and ch.direction is not None else axes[k % 3]
            rows.append(PlanRow("response", r.node, r.xyz, _unit(d, name), name))
    rows += [PlanRow("excitation", e.node, e.xyz, e.direction, f"point {e.index + 1}")
             for e in plan.excitations]
    return rows


def read_csv_rows(path: str | Path) -> list[PlanRow]:
    """Rows of a plan CSV file; raises InputError naming the line and the column."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as err:
        raise InputError(f"{p.name}: cannot read: {err.strerror or err}") from err
    reader = csv.DictReader(text.splitlines())
    missing = [c for c in CSV_HEADER if c not in (reader.fieldnames or [])]
    if missing:
        raise InputError(f"{p.name}: missing column(s) {', '.join(missing)}; the header must be "
                         f"{','.join(CSV_HEADER)}")
    rows: list[PlanRow] = []
    for line, rec in enumerate(reader, start=2):
        where = f"{p.name} line {line}"
        role = (rec["role"] or "").strip().lower()
        if role not in ("response", "excitation"):
            raise InputError(f"{where}: role must be response or excitation, got {role!r}")
        try:
            node = int(rec["node"])
            xyz = tuple(float(rec[c]) for c in ("x", "y", "z"))
            d = tuple(float(rec[c]) for c in ("dx", "dy", "dz"))
        except (TypeError, ValueError) as err:
            raise InputError(f"{where}: node must be an integer and x..dz numbers") from err
        if not all(np.isfinite(xyz)):
            raise InputError(f"{where}: coordinates must be finite")
        rows.append(PlanRow(role, node, xyz, _unit(d, where)))  # type: ignore[arg-type]
    if not rows:
        raise InputError(f"{p.name}: no rows below the header")
    return rows


def write_csv_rows(path: str | Path, rows: Sequence[PlanRow]) -> None:
    """Write rows in the CSV format of this module."""
    with Path(path).open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_HEADER)
        for r in rows:
            w.writerow([r.role, r.node, *(f"{v:.6g}" for v in r.xyz),
                        *(f"{v:.6g}" for v in r.direction)])


def check_rows_geometry(rows: Sequence[PlanRow]) -> GeometryReport:
    """Rank and condition of E and T of the plan (see :func:`check_geometry`).

    Raises
    ------
    InputError
        When a node has two different coordinate sets, or a role has no rows.
    """
    where: dict[int, tuple[float, float, float]] = {}
    for r in rows:
        if r.node in where and not np.allclose(where[r.node], r.xyz, atol=1e-9):
            raise InputError(f"node {r.node} has two different coordinates: give one per node")
        where[r.node] = r.xyz
    resp = [r for r in rows if r.role == "response"]
    exc = [r for r in rows if r.role == "excitation"]
    if not resp or not exc:
        raise InputError("the plan needs response rows and excitation rows")
    return check_geometry([r.xyz for r in resp], [r.direction for r in resp],
                          [r.xyz for r in exc], [r.direction for r in exc])
