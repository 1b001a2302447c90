"""The mounts file (``insitu identify FILE --mounts mounts.toml``; docs/conventions.md)::

    crank_axis = [1.0, 0.0, 0.0]        # unit vector, global frame (for the torque roll axis)
    [[mount]]
    name = "front left"
    position = [-0.15, 0.05, -0.05]     # m, global frame, the mount's elastic centre
    axes = [[1,0,0],[0,1,0],[0,0,1]]    # rows: the mount's local u, v, w axes, global frame

``crank_axis`` is normalised; ``axes`` rows must be orthonormal (to 1e-6) and are used as
given. ``name`` defaults to ``mount N``. Every problem raises :class:`MountsFileError` with
one line naming the file, the mount and what to fix.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from processing.mounts import MountGeometry

__all__ = ["MountsFile", "MountsFileError", "load_mounts", "mounts_from_dict"]


class MountsFileError(ValueError):
    """The mounts file is missing, not TOML, or describes the mounts wrongly (one line)."""


@dataclass(frozen=True)
class MountsFile:
    """The crankshaft axis (unit vector) and the mounts, in the file's order."""

    crank_axis: tuple[float, float, float]
    mounts: tuple[MountGeometry, ...]
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The same content as the TOML file (for JSON, the run file and a TOML writer)."""
        return {
            "crank_axis": list(self.crank_axis),
            "mount": [{"name": m.name, "position": m.position.tolist(),
                       "axes": m.axes.tolist()} for m in self.mounts],
        }


def _vector(value: Any, where: str, what: str) -> list[float]:
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
            or not all(math.isfinite(float(v)) for v in value)):
        raise MountsFileError(f"{where}: {what} must be a list of 3 finite numbers, got "
                              f"{value!r}")
    return [float(v) for v in value]


def mounts_from_dict(data: Mapping[str, Any], source: str = "mounts file") -> MountsFile:
    """Validate the parsed TOML (or the equal JSON of :meth:`MountsFile.to_dict`)."""
    unknown = set(data) - {"crank_axis", "mount"}
    if unknown:
        raise MountsFileError(f"{source}: unknown key(s) {', '.join(sorted(unknown))}: the file "
                              "has crank_axis and [[mount]] tables")
    if "crank_axis" not in data:
        raise MountsFileError(f"{source}: crank_axis is missing: give the crankshaft direction, "
                              "e.g. crank_axis = [1.0, 0.0, 0.0]")
    t = np.array(_vector(data["crank_axis"], source, "crank_axis"))
    if np.linalg.norm(t) < 1e-9:
        raise MountsFileError(f"{source}: crank_axis must not be zero")
    t = t / np.linalg.norm(t)
    raw = data.get("mount")
    if not isinstance(raw, list) or not raw:
        raise MountsFileError(f"{source}: no [[mount]] table: give each mount's name, position "
                              "and axes")
    mounts = []
    names: set[str] = set()
    for i, m in enumerate(raw, start=1):
        if not isinstance(m, Mapping):
            raise MountsFileError(f"{source}: mount {i} is not a table")
        name = str(m.get("name", f"mount {i}"))
        where = f"{source}: mount {i} ({name!r})"
        extra = set(m) - {"name", "position", "axes"}
        if extra:
            raise MountsFileError(f"{where}: unknown key(s) {', '.join(sorted(extra))}: a mount "
                                  "has name, position and axes")
        if name in names:
            raise MountsFileError(f"{where}: the name is used twice: give each mount its own")
        names.add(name)
        if "position" not in m:
            raise MountsFileError(f"{where}: position is missing (m, global frame)")
        pos = _vector(m["position"], where, "position")
        axes = m.get("axes", [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
        if not isinstance(axes, list) or len(axes) != 3:
            raise MountsFileError(f"{where}: axes must be 3 rows (u, v, w) of 3 numbers")
        A = np.array([_vector(a, where, f"axes row {k + 1}") for k, a in enumerate(axes)])
        if not np.allclose(A @ A.T, np.eye(3), atol=1e-6):
            lengths = np.round(np.linalg.norm(A, axis=1), 4).tolist()
            dots = np.round([A[0] @ A[1], A[0] @ A[2], A[1] @ A[2]], 4).tolist()
            raise MountsFileError(f"{where}: axes must be orthonormal unit rows (u, v, w); got "
                                  f"lengths {lengths} and dot products {dots}")
        mounts.append(MountGeometry(name, np.array(pos), A))
    return MountsFile((float(t[0]), float(t[1]), float(t[2])), tuple(mounts), source)


def load_mounts(path: str | Path) -> MountsFile:
    """Read and validate a mounts file; raises :class:`MountsFileError` (one line)."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise MountsFileError(f"{p}: not valid TOML: {err}") from err
    except OSError as err:
        raise MountsFileError(f"{p}: cannot read the mounts file: {err.strerror or err}") from err
    return mounts_from_dict(data, str(p))
