"""Low-level writer of the UFF datasets this package produces (164, 15, 2411, 2420, 58/58b).

The layout is the one pyuff reads and writes (fixed-width fields, 80-column header
lines, ``D`` exponents in double-precision geometry records). pyuff's own writer is
not used: it rescans the whole file after every dataset (quadratic time) and leaks a
file handle on each binary 58b record.

Precision: geometry and unit factors are written with 17 significant digits (exact
doubles); ASCII function values as E20.12 fields (12 significant digits, relative
error <= 5e-12); abscissa minimum and increment in record 7 as E13.5 (6 significant
digits). Binary 58b values are IEEE doubles, little endian.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from app.io._uff_common import UnitFactors
from app.io.replace import replacing
from processing.data import Geometry

_LINE = "%-80s\n"
#: labels of the coordinate systems written for nodes with their own frame start above this
CS_LABEL_BASE = 1000
_START = b"    -1\n"
_END = b"    -1\n"


def _d(values: Sequence[float]) -> str:
    """Values as %25.16e with a Fortran D exponent (1P3D25.16)."""
    return "".join(f"{v:25.16e}".replace("e", "D") for v in values) + "\n"


def _header(number: int) -> bytes:
    return (_LINE % f"{number:6d}").encode("ascii")


@dataclass(frozen=True)
class AxisInfo:
    """Records 8-11 of dataset 58: specific data type, exponents, labels."""

    data_type: int = 0
    length_exp: int = 0
    force_exp: int = 0
    label: str = "NONE"
    units: str = "NONE"

    def line(self) -> str:
        return (
            f"{self.data_type:10d}{self.length_exp:5d}{self.force_exp:5d}{0:5d} "
            f"{self.label[:20]:<20s} {self.units[:20]:<20s}\n"
        )


def exact_in_header(x0: float, dx: float, x: NDArray[np.float64]) -> bool:
    """Whether ``x0 + k dx`` with x0, dx printed as E13.5 reproduces ``x`` exactly."""
    a, d = float(f"{x0:13.5e}"), float(f"{dx:13.5e}")
    return bool(np.array_equal(a + np.arange(x.size) * d, x))


def evenly_spaced(x: NDArray[np.float64]) -> bool:
    if x.size < 2:
        return False
    step = np.diff(x)
    return bool(step[0] > 0 and np.allclose(step, step[0], rtol=1e-9, atol=0.0))


class UffWriter:
    """Append datasets to an open binary file object."""

    def __init__(self, fh: BinaryIO) -> None:
        self._fh = fh

    def _text(self, text: str) -> None:
        self._fh.write(text.encode("ascii"))

    def units(self, u: UnitFactors) -> None:
        """Dataset 164."""
        self._fh.write(_START + _header(164))
        self._text(f"{u.code:10d}{u.description[:20]:>20s}{1:10d}\n")
        self._text(_d([u.length, u.force, u.temperature]) + _d([u.temperature_offset]))
        self._fh.write(_END)

    def nodes(
        self,
        dataset: int,
        ids: NDArray[np.int64],
        xyz: NDArray[np.float64],
        disp_cs: NDArray[np.int64],
    ) -> None:
        """Dataset 2411 (double precision) or 15 (E13.5: 6 significant digits)."""
        self._fh.write(_START + _header(dataset))
        rows = []
        for n, p, cs in zip(ids.tolist(), xyz.tolist(), disp_cs.tolist(), strict=True):
            if dataset == 2411:
                rows.append(f"{n:10d}{0:10d}{cs:10d}{1:10d}\n" + _d(p))
            else:
                rows.append(f"{n:10d}{0:10d}{cs:10d}{1:10d}{p[0]:13.5e}{p[1]:13.5e}{p[2]:13.5e}\n")
        self._text("".join(rows))
        self._fh.write(_END)

    def coordinate_systems(
        self, labels: Sequence[int], frames: Sequence[NDArray[np.float64]], names: Sequence[str]
    ) -> None:
        """Dataset 2420, Cartesian systems at the origin; frames hold local axes as columns."""
        self._fh.write(_START + _header(2420))
        self._text(f"{1:10d}\n" + _LINE % "insitu")
        for label, R, name in zip(labels, frames, names, strict=True):
            self._text(f"{label:10d}{0:10d}{8:10d}\n" + _LINE % name[:80])
            rows = np.vstack([np.asarray(R, dtype=float).T, np.zeros(3)])
            self._text("".join(_d(r) for r in rows.tolist()))
        self._fh.write(_END)

    def geometry(
        self,
        geometry: Geometry,
        frames: dict[int, NDArray[np.float64]],
        length_factor: float,
        dataset: int = 2411,
    ) -> None:
        """Dataset 2420 for the nodes that have a frame, then the nodes (2411 or 15)."""
        labels = {node: CS_LABEL_BASE + k for k, node in enumerate(frames, start=1)}
        if frames:
            self.coordinate_systems(
                list(labels.values()),
                list(frames.values()),
                [f"node {node} displacement frame" for node in frames],
            )
        disp = np.array([labels.get(int(n), 0) for n in geometry.node_ids], dtype=np.int64)
        self.nodes(dataset, geometry.node_ids, geometry.xyz * length_factor, disp)

    def function(
        self,
        *,
        func_type: int,
        func_id: int,
        load_case: int,
        response: tuple[int, int],
        reference: tuple[int, int],
        x: NDArray[np.float64],
        data: NDArray[np.float64] | NDArray[np.complex128],
        abscissa: AxisInfo,
        ordinate: AxisInfo,
        denominator: AxisInfo,
        ids: Sequence[str],
        binary: bool,
        even: bool | None = None,
    ) -> None:
        """One dataset 58 (ASCII) or 58b (binary) record, double precision.

        ``even=None`` chooses even abscissa spacing when ``x`` is evenly spaced and, for
        binary records, its E13.5 header reproduces ``x`` exactly; otherwise every
        abscissa value is stored. ``even=True`` forces the start/increment header.
        """
        x = np.asarray(x, dtype=float)
        values = np.asarray(data)
        is_complex = np.iscomplexobj(values)
        n = values.size
        if even is None:
            even = evenly_spaced(x) and (not binary or exact_in_header(x[0], x[1] - x[0], x))
        columns = [values.real, values.imag] if is_complex else [values]
        if not even:
            columns.insert(0, x)
        flat = np.column_stack([np.asarray(c, dtype=float) for c in columns]).ravel()
        head = "    58" + (
            f"b{1:6d}{2:6d}{11:12d}{flat.size * 8:12d}{0:6d}{0:6d}{0:12d}{0:12d}" if binary else ""
        )
        lines = [head.ljust(80) + "\n"]
        lines += [_LINE % (s[:80] if s.strip() else "NONE") for s in (list(ids) + ["NONE"] * 5)[:5]]
        r_node, r_dir = response
        f_node, f_dir = reference
        lines.append(
            f"{func_type:5d}{func_id:10d}{0:5d}{load_case:10d} {'NONE':>10s}{r_node:10d}{r_dir:4d}"
            f" {'NONE':>10s}{f_node:10d}{f_dir:4d}\n"
        )
        x0, dx = (x[0], x[1] - x[0]) if even else (0.0, 0.0)
        lines.append(f"{6 if is_complex else 4:10d}{n:10d}{int(even):10d}"
                     f"{x0:13.5e}{dx:13.5e}{0.0:13.5e}\n")
        lines += [abscissa.line(), ordinate.line(), denominator.line(), AxisInfo().line()]
        self._fh.write(_START + "".join(lines).encode("ascii"))
        if binary:
            self._fh.write(flat.astype("<f8").tobytes())
        else:
            self._text(_ascii_values(flat, even, is_complex))
        self._fh.write(_END)


def _ascii_values(flat: NDArray[np.float64], even: bool, is_complex: bool) -> str:
    """Record 12 of dataset 58 in the double-precision layouts (cases 5-8)."""
    if even:  # 4E20.12
        cells = ["%20.11e"] * 4
    elif is_complex:  # E13.5, 2E20.12: one point (x, re, im) a line
        cells = ["%13.5e", "%20.11e", "%20.11e"]
    else:  # 2(E13.5, E20.12): two points (x, y) a line
        cells = ["%13.5e", "%20.11e"] * 2
    per = len(cells)
    full = flat.size // per
    line = "".join(cells) + "\n"
    out = (line * full) % tuple(flat[: full * per].tolist()) if full else ""
    rest = flat.size - full * per
    if rest:
        out += ("".join(cells[:rest]) + "\n") % tuple(flat[full * per :].tolist())
    return out


@contextlib.contextmanager
def open_for_writing(path: str | Path) -> Iterator[UffWriter]:
    """Write to a temporary file beside ``path`` and move it into place on success
    (:func:`app.io.replace.replacing`)."""
    with replacing(path) as tmp:
        # os.open applies the umask to 0o666, as a plain open() would (mkstemp: 0o600)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "wb") as fh:
            yield UffWriter(fh)
