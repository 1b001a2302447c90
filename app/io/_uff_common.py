"""Shared pieces of the UFF readers: loading a file through pyuff, units, DOF codes.

A file is indexed once by pyuff (:func:`open_uff`) and its datasets parsed one at a time
(:func:`read_set`) or all together (:func:`load_sets`); the rest works on the dictionaries
pyuff returns. Unit factors follow dataset 164: a file value divided by the factor of its
dimension gives the SI value (a file in mm has length factor 1000).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyuff
from numpy.typing import NDArray

from processing.data import InputError

__all__ = ["UnitFactors", "read_units"]

log = logging.getLogger(__name__)

Dataset = dict[str, Any]

#: Specific data types of dataset 58 records 8-11 that this package handles.
DATA_TYPE_NAMES: dict[int, str] = {
    0: "unknown",
    1: "general",
    8: "displacement",
    11: "velocity",
    12: "acceleration",
    13: "force",
    17: "time",
    18: "frequency",
}

#: Length and force exponents UFF implies for a translational DOF of a specific data type
#: (dataset 58, addendum A); used when a record leaves its exponent fields at zero.
_IMPLIED_EXPONENTS: dict[int, tuple[int, int]] = {
    2: (-2, 1),  # stress
    8: (1, 0),  # displacement
    9: (0, 1),  # reaction force
    11: (1, 0),  # velocity
    12: (1, 0),  # acceleration
    13: (0, 1),  # excitation force
    15: (-2, 1),  # pressure
    16: (-1, 1),  # mass
}


@dataclass(frozen=True)
class UnitFactors:
    """Unit factors of a universal file (dataset 164).

    SI value = file value / factor, for each dimension: ``length`` is file length
    units per metre (1000 for mm), ``force`` file force units per newton.

    Examples
    --------
    >>> UnitFactors(length=1000.0).to_si(1, 0)  # a length in mm -> m
    0.001
    """

    length: float = 1.0
    force: float = 1.0
    temperature: float = 1.0
    temperature_offset: float = 273.15
    code: int = 1
    description: str = "SI"

    def to_si(self, length_exp: int, force_exp: int) -> float:
        """Multiplier taking a file value of dimension length^a force^b to SI."""
        return float(1.0 / (self.length**length_exp * self.force**force_exp))

    @property
    def is_si(self) -> bool:
        return self.length == 1.0 and self.force == 1.0

    def describe(self) -> str:
        """The file's unit system in words, with its factors to SI."""
        name = self.description or f"code {self.code}"
        return ("SI" if self.is_si else
                f"{name} (lengths x {1 / self.length:g}, forces x {1 / self.force:g} to SI)")


def as_list(sets: Any) -> list[Dataset]:
    """pyuff returns a lone dict for a one-set file; make it a list of dicts."""
    if isinstance(sets, dict):
        return [sets]
    return list(sets)


def _check_complete(p: Path) -> None:
    """Refuse a file cut short: a universal file ends with the '    -1' closing its last set."""
    size = p.stat().st_size
    with p.open("rb") as f:
        f.seek(max(0, size - 256))
        tail = f.read().rstrip()
    # the last set's closing delimiter, not the opening one of a set cut right after it
    if size and (not tail.endswith(b"    -1") or re.search(rb"    -1[ \t]*\r?\n    -1$", tail)):
        raise InputError(f"{p.name} is truncated: it ends in the middle of a dataset "
                         f"(after {size} bytes, without the closing '    -1'): copy or "
                         "export the file again")


def open_uff(path: str | Path) -> tuple[pyuff.UFF, list[int]]:
    """A universal file indexed by pyuff (its datasets' places and types, none parsed) and
    the type of each dataset; InputError for a missing, empty, truncated or unreadable file.

    pyuff holds the file's bytes only while it indexes them; read the datasets one at a time
    with :func:`read_set` to keep memory to one dataset.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"UFF file {p} not found: check the path")
    if not p.is_file():
        raise InputError(f"{p} is not a file: give the path of a .uff/.unv file")
    try:
        uff = pyuff.UFF(str(p))
        types = [int(t) for t in uff.get_set_types()]
    except Exception as err:  # pyuff raises bare Exception for every parse error
        raise _unreadable(p, err) from err
    if not types:
        raise InputError(
            f"{p.name} holds no UFF datasets (no '    -1' delimiters): "
            "is it a universal file?"
        )
    _check_complete(p)
    return uff, types


def _unreadable(p: Path, err: Exception) -> InputError:
    return InputError(
        f"cannot read UFF file {p.name}: {err} (pyuff could not parse it): "
        "check that it is a complete universal file"
    )


def read_set(uff: pyuff.UFF, index: int, header_only: bool = False) -> Dataset:
    """Dataset ``index`` (from 0) of a file :func:`open_uff` indexed, parsed by pyuff alone
    (``header_only``: a dataset 58's header, its ``x`` and ``data`` None); InputError when
    pyuff cannot parse it."""
    try:
        ds = uff.read_sets(setn=index, header_only=header_only)
    except Exception as err:  # pyuff raises bare Exception for every parse error
        raise _unreadable(Path(uff.get_file_name()), err) from err
    return as_list(ds)[0]


def load_sets(path: str | Path, only: Iterable[int] | None = None) -> list[Dataset]:
    """Read the datasets of a universal file, raising InputError on any failure.

    Parameters
    ----------
    path : file name
    only : dataset numbers to read (all when None); the others are skipped unread.
    """
    p = Path(path)
    uff, types = open_uff(p)
    wanted = set(only) if only is not None else None
    sets = [read_set(uff, i) for i, t in enumerate(types) if wanted is None or t in wanted]
    log.debug("read %d datasets from %s", len(sets), p)
    return sets


def read_units(datasets: Sequence[Dataset] | Dataset) -> UnitFactors:
    """Unit factors of dataset 164 (SI when the file has none).

    Parameters
    ----------
    datasets : the list of dicts ``pyuff.UFF(path).read_sets()`` returns (or one dict).

    Returns
    -------
    UnitFactors
        ``SI value = file value / factor``.

    Raises
    ------
    InputError
        Several datasets 164 that disagree, or factors that are not positive numbers.
    """
    found: list[UnitFactors] = []
    for ds in as_list(datasets):
        if int(ds.get("type", -1)) != 164:
            continue
        try:
            u = UnitFactors(
                length=float(ds["length"]),
                force=float(ds["force"]),
                temperature=float(ds.get("temp", 1.0)),
                temperature_offset=float(ds.get("temp_offset", 0.0)),
                code=int(ds.get("units_code", 9)),
                description=str(ds.get("units_description", "")).strip(),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise InputError(
                f"dataset 164 (units) is incomplete ({err}): re-export the file"
            ) from err
        if not all(np.isfinite([u.length, u.force])) or u.length <= 0 or u.force <= 0:
            raise InputError(
                f"dataset 164 has unusable unit factors (length {u.length}, force {u.force}): "
                "they must be positive numbers"
            )
        found.append(u)
    if not found:
        return UnitFactors()
    first = found[0]
    for u in found[1:]:
        if (u.length, u.force) != (first.length, first.force):
            raise InputError(
                f"the file has {len(found)} different unit systems (dataset 164: length factors "
                f"{first.length:g} and {u.length:g}, force {first.force:g} and {u.force:g}): "
                "keep one"
            )
    return first


def exponents(ds: Dataset, axis: str) -> tuple[int, int]:
    """Length and force exponents of a record axis ('ordinate' or 'orddenom').

    The record's own exponent fields win when any is non-zero; otherwise UFF implies
    them from the specific data type (translational DOF).
    """
    le = int(ds.get(f"{axis}_len_unit_exp", 0) or 0)
    fe = int(ds.get(f"{axis}_force_unit_exp", 0) or 0)
    if le or fe:
        return le, fe
    return _IMPLIED_EXPONENTS.get(int(ds.get(f"{axis}_spec_data_type", 0) or 0), (0, 0))


def type_name(code: int) -> str:
    return f"{code} ({DATA_TYPE_NAMES[code]})" if code in DATA_TYPE_NAMES else str(code)


def record_label(index: int, ds: Dataset) -> str:
    """'dataset #k (response 3:+2, reference 101:-1)' for messages; k counts from 1."""
    rsp = f"{int(ds.get('rsp_node', 0))}:{int(ds.get('rsp_dir', 0)):+d}"
    ref = f"{int(ds.get('ref_node', 0))}:{int(ds.get('ref_dir', 0)):+d}"
    return f"dataset #{index + 1} (response {rsp}, reference {ref})"


def dof_direction(
    node: int, code: int, rotations: dict[int, NDArray[np.float64]], what: str, where: str
) -> tuple[int, int, NDArray[np.float64]]:
    """Axis index (0-2), sign and global unit vector of a UFF direction code at ``node``.

    ``rotations[node]`` maps the node's displacement coordinate system to global
    (column k = local axis k); nodes without an entry use the global axes.
    """
    if code not in (1, 2, 3, -1, -2, -3):
        kind = "a rotation" if abs(code) in (4, 5, 6) else "not a translation"
        raise InputError(
            f"{where}: {what} direction code {code} is {kind}; only translations "
            "+-1, +-2, +-3 are supported: remove or re-export that record"
        )
    axis = abs(code) - 1
    sign = 1 if code > 0 else -1
    R = rotations.get(node)
    vec = np.eye(3)[:, axis] if R is None else R[:, axis]
    return axis, sign, sign * vec


def sample_axis(ds: Dataset, where: str) -> NDArray[np.float64]:
    """The abscissa values of a dataset 58 record, checked finite."""
    x = np.asarray(ds.get("x"), dtype=float).ravel()
    n = np.asarray(ds.get("data")).size
    if x.size != n or n == 0:
        raise InputError(f"{where}: {n} values but {x.size} abscissa values: re-export the record")
    if not np.all(np.isfinite(x)):
        raise InputError(f"{where}: abscissa has NaN or infinite values: re-export the record")
    return x


def snapped_rate(increment: float) -> float:
    """Sample rate 1/increment, snapped to the integer rate the 6-digit header implies.

    Record 7 of dataset 58 stores the increment as E13.5 (6 significant digits), so
    2048 Hz comes back as 1/4.88281e-4 = 2048.0016 Hz. When the integer nearest
    1/increment prints to the same 6 digits, that integer is the rate.
    """
    rate = 1.0 / increment
    r = round(rate)
    if r > 0 and f"{1.0 / r:.5e}" == f"{increment:.5e}":
        return float(r)
    return rate
