"""Universal File Format (UFF) FRF files: read and write :class:`FRFSet`.

A file holds dataset 164 (units, optional: SI when absent), dataset 15 or 2411 (nodes,
with 2420 coordinate systems where a node refers to one) and one dataset 58 record of
function type 4 (FRF) per response DOF x reference DOF; coherence records (type 6)
are optional. See ``docs/conventions.md``.

Reading gives SI accelerance (m/s^2)/N in the global frame: velocity (ordinate type
11) and displacement (8) FRFs are converted, units follow dataset 164 and the
records' unit exponents, direction codes +-1..+-3 are read in each node's
displacement coordinate system. Time records are in :mod:`app.io.uff_time`.

Examples
--------
>>> from hardware_mocks.benches import get_bench  # doctest: +SKIP
>>> write_frf_uff("engine.uff", get_bench("engine").frfset(), binary=True)  # doctest: +SKIP
>>> frf = read_frf_uff("engine.uff")  # doctest: +SKIP
"""

from __future__ import annotations

import logging
from datetime import datetime
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from app.io._uff_common import (
    DATA_TYPE_NAMES,
    Dataset,
    UnitFactors,
    dof_direction,
    exponents,
    load_sets,
    read_units,
    record_label,
    sample_axis,
    type_name,
)
from app.io._uff_write import AxisInfo, UffWriter, open_for_writing
from app.io.uff_geometry import assign_node_frames, read_geometry, read_geometry_uff
from app.io.uff_time import TimeRun, read_time_uff, write_time_uff
from processing.data import FRFSet, InputError
from processing.measurement import Measurement, Provenance

__all__ = [
    "TimeRun",
    "UnitFactors",
    "read_frf_measurement_uff",
    "read_frf_uff",
    "read_geometry",
    "read_geometry_uff",
    "read_time_uff",
    "read_units",
    "write_frf_uff",
    "write_time_uff",
]

log = logging.getLogger(__name__)

_FRF, _COHERENCE = 4, 6
_FRF_ORDINATES = (12, 11, 8)


class _DofIndex:
    """DOFs in order of first appearance, keyed by (node, axis of its displacement frame).

    The same axis with the opposite sign is the same DOF: its data are negated.
    """

    def __init__(self, what: str, rotations: dict[int, NDArray[np.float64]]) -> None:
        self.what = what
        self.rotations = rotations
        self.keys: dict[tuple[int, int], int] = {}
        self.nodes: list[int] = []
        self.dirs: list[NDArray[np.float64]] = []
        self.codes: list[int] = []

    def add(self, node: int, code: int, where: str) -> tuple[int, int]:
        """(index, sign relative to the stored DOF), adding the DOF when new."""
        axis, _, vec = dof_direction(node, code, self.rotations, self.what, where)
        k = self.keys.get((node, axis))
        if k is None:
            k = self.keys[(node, axis)] = len(self.nodes)
            self.nodes.append(node)
            self.dirs.append(vec)
            self.codes.append(code)
        return k, 1 if (code > 0) == (self.codes[k] > 0) else -1

    def find(self, node: int, code: int, where: str) -> tuple[int, int] | None:
        """Like :meth:`add` but None for a DOF not seen before."""
        axis = dof_direction(node, code, self.rotations, self.what, where)[0]
        k = self.keys.get((node, axis))
        if k is None:
            return None
        return k, 1 if (code > 0) == (self.codes[k] > 0) else -1

    def label(self, k: int) -> str:
        return f"{self.nodes[k]}:{self.codes[k]:+d}"


def _same_axis(x: NDArray[np.float64], ref: NDArray[np.float64]) -> bool:
    scale = float(np.max(np.abs(ref))) or 1.0
    return x.size == ref.size and bool(np.allclose(x, ref, rtol=1e-9, atol=1e-12 * scale))


def _axis_text(x: NDArray[np.float64]) -> str:
    return f"{x.size} lines from {x[0]:g} to {x[-1]:g} Hz"


def _accelerance(
    ds: Dataset, x: NDArray[np.float64], units: UnitFactors, where: str
) -> NDArray[np.complex128]:
    """One FRF record's values as SI accelerance, (m/s^2)/N."""
    num = int(ds.get("ordinate_spec_data_type", 0) or 0)
    den = int(ds.get("orddenom_spec_data_type", 0) or 0)
    absc = int(ds.get("abscissa_spec_data_type", 0) or 0)
    if absc not in (0, 18):
        raise InputError(
            f"{where}: abscissa type {type_name(absc)} is not frequency (18): export FRFs "
            "against frequency in Hz"
        )
    if num not in _FRF_ORDINATES:
        raise InputError(
            f"{where}: unknown FRF ordinate type {type_name(num)}: expected 12 (acceleration), "
            "11 (velocity) or 8 (displacement) in record 9 field 1"
        )
    if den != 13:
        raise InputError(
            f"{where}: FRF denominator type {type_name(den)}; only force (13) is supported: "
            "export FRFs per unit force"
        )
    data = np.asarray(ds.get("data"))
    if not np.iscomplexobj(data):
        raise InputError(f"{where}: FRF values are real; complex FRFs are needed: re-export them")
    ln, fn = exponents(ds, "ordinate")
    ld, fd = exponents(ds, "orddenom")
    w = 2.0 * np.pi * x
    with np.errstate(invalid="ignore"):  # an infinite value stays undefined: load names it
        H = data.astype(np.complex128) * (units.to_si(ln, fn) / units.to_si(ld, fd))
        if num == 11:
            H = H * (1j * w)
        elif num == 8:
            H = H * -(w**2)
    return H


def _coherence(
    records: list[tuple[int, Dataset]],
    resp: _DofIndex,
    exc: _DofIndex,
    freq: NDArray[np.float64],
) -> tuple[NDArray[np.float64] | None, str]:
    """Coherence grid when the file has a type-6 record for every FRF pair."""
    if not records:
        return None, "absent"
    C = np.zeros((len(resp.nodes), len(exc.nodes), freq.size))
    seen = np.full(C.shape[:2], -1)
    for i, ds in records:
        where = record_label(i, ds)
        r = resp.find(int(ds.get("rsp_node", 0)), int(ds.get("rsp_dir", 0)), where)
        e = exc.find(int(ds.get("ref_node", 0)), int(ds.get("ref_dir", 0)), where)
        if r is None or e is None:
            log.debug("%s: coherence of a pair without FRF, ignored", where)
            continue
        x = sample_axis(ds, where)
        if not _same_axis(x, freq):
            raise InputError(
                f"{where}: coherence has {_axis_text(x)} but the FRFs have {_axis_text(freq)}: "
                "export coherence on the FRF frequency axis"
            )
        values = np.real(np.asarray(ds.get("data")))
        if seen[r[0], e[0]] >= 0:
            raise InputError(
                f"{where}: second coherence record for response {resp.label(r[0])} and "
                f"reference {exc.label(e[0])} (first: dataset #{seen[r[0], e[0]] + 1}): keep one"
            )
        seen[r[0], e[0]] = i
        C[r[0], e[0]] = values
    n_seen = int(np.sum(seen >= 0))
    if n_seen < seen.size:
        log.info("coherence present for %d of %d FRF pairs only: not used", n_seen, seen.size)
        return None, f"incomplete ({n_seen} of {seen.size} pairs)"
    return C, "complete"


def read_frf_uff(path: str | Path) -> FRFSet:
    """The FRFs of a self-contained UFF FRF file (:func:`read_frf_measurement_uff` without
    the file's notes)."""
    return read_frf_measurement_uff(path).frf


def read_frf_measurement_uff(path: str | Path) -> Measurement:
    """Read a self-contained UFF FRF file: its FRFs, given (an analyser's: their coherence
    stands for their noise), and what the file said about them.

    Parameters
    ----------
    path : file name (ASCII 58 or binary 58b records, any mix)

    Returns
    -------
    Measurement
        FRFs: ``freq`` in Hz; ``H`` (n_resp, n_exc, n_f) accelerance in (m/s^2)/N;
        response and excitation DOFs in order of first appearance, directions as unit
        vectors in the global frame (sign of the direction code included; a DOF seen again
        with the opposite sign has its data negated); geometry in m with every node of the
        file; ``coherence`` when a type-6 record exists for every pair, else None. The
        provenance's ``notes`` give the file's units, its ordinate types and the coherence
        found (``"coherence: absent"``, ``"complete"``, ``"incomplete (k of n pairs)"``);
        ``source`` is the file's name. NaN or infinite FRF or coherence values are kept as
        the file holds them (:func:`app.pipeline.load` names them and leaves them out).

    Raises
    ------
    InputError
        Missing or unparsable file; no nodes; a DOF node without coordinates; no FRF
        records; a response/reference pair missing or given twice; frequency axes that
        differ; an ordinate type other than acceleration (12),
        velocity (11) or displacement (8); a denominator other than force (13).
    """
    p = Path(path)
    sets = load_sets(p)
    units = read_units(sets)
    geometry, rotations = read_geometry(sets)
    functions = [(i, ds) for i, ds in enumerate(sets) if ds.get("type") == 58]
    frf = [(i, ds) for i, ds in functions if ds.get("func_type") == _FRF]
    coh = [(i, ds) for i, ds in functions if ds.get("func_type") == _COHERENCE]
    if not frf:
        raise InputError(
            f"{p.name} has no FRF records (dataset 58 with function type 4): "
            "export FRFs (time data go through 'insitu frf')"
        )
    geometry.coordinates(np.array([int(ds["rsp_node"]) for _, ds in frf]), "response")
    geometry.coordinates(np.array([int(ds["ref_node"]) for _, ds in frf]), "excitation")
    resp, exc = _DofIndex("response", rotations), _DofIndex("reference", rotations)
    freq = sample_axis(frf[0][1], record_label(*frf[0]))
    entries, ordinates = _frf_entries(frf, resp, exc, freq, units)
    H = _frf_grid(entries, resp, exc, freq, p.name)
    coherence, coh_status = _coherence(coh, resp, exc, freq)
    log.info("%s: %d x %d FRFs, %d lines, units %s", p.name, H.shape[0], H.shape[1],
             freq.size, units.description or units.code)
    notes = (f"units: {units.describe()}",
             "ordinates: " + ", ".join(sorted(DATA_TYPE_NAMES[t] for t in ordinates)),
             f"coherence: {coh_status}")
    return Measurement(FRFSet(
        freq=freq,
        H=H,
        resp_nodes=np.array(resp.nodes, dtype=np.int64),
        resp_dirs=np.array(resp.dirs),
        exc_nodes=np.array(exc.nodes, dtype=np.int64),
        exc_dirs=np.array(exc.dirs),
        geometry=geometry,
        coherence=coherence,
    ), Provenance(notes=notes), p.name)


#: one FRF record read: response and reference DOF indices, the sign that brings the
#: record's directions to the stored DOFs', the dataset index and the SI accelerance
_FrfEntry = tuple[int, int, int, int, NDArray[np.complex128]]


def _frf_entries(frf: list[tuple[int, Dataset]], resp: _DofIndex, exc: _DofIndex,
                 freq: NDArray[np.float64], units: UnitFactors,
                 ) -> tuple[list[_FrfEntry], set[int]]:
    """Each FRF record's DOFs (added to ``resp`` and ``exc``) and accelerance, and the
    ordinate types met; InputError for a record off the first one's frequency axis."""
    entries: list[_FrfEntry] = []
    ordinates: set[int] = set()
    for i, ds in frf:
        where = record_label(i, ds)
        r = resp.add(int(ds["rsp_node"]), int(ds["rsp_dir"]), where)
        e = exc.add(int(ds["ref_node"]), int(ds["ref_dir"]), where)
        x = sample_axis(ds, where)
        if not _same_axis(x, freq):
            raise InputError(
                f"{where} has {_axis_text(x)} but {record_label(*frf[0])} has "
                f"{_axis_text(freq)}: export every FRF on one frequency axis"
            )
        entries.append((r[0], e[0], r[1] * e[1], i, _accelerance(ds, freq, units, where)))
        ordinates.add(int(ds.get("ordinate_spec_data_type", 0)))
    return entries, ordinates


def _frf_grid(entries: list[_FrfEntry], resp: _DofIndex, exc: _DofIndex,
              freq: NDArray[np.float64], name: str) -> NDArray[np.complex128]:
    """H (n_resp, n_exc, n_f) from the records; InputError for a pair given twice or
    missing (file ``name``)."""
    H = np.zeros((len(resp.nodes), len(exc.nodes), freq.size), dtype=np.complex128)
    owner = np.full(H.shape[:2], -1)
    for ri, ei, sign, i, values in entries:
        if owner[ri, ei] >= 0:
            raise InputError(
                f"FRF of response {resp.label(ri)} and reference {exc.label(ei)} is given twice "
                f"(datasets #{owner[ri, ei] + 1} and #{i + 1}): keep one record per pair"
            )
        owner[ri, ei] = i
        H[ri, ei] = values if sign > 0 else -values  # no product: inf stays inf
    missing = np.argwhere(owner < 0)
    if missing.size:
        ri, ei = (int(v) for v in missing[0])
        raise InputError(
            f"{name} lacks the FRF of {missing.shape[0]} of {owner.size} response/reference "
            f"pairs, e.g. response {resp.label(ri)} with reference {exc.label(ei)}: "
            "the file must hold every response x reference combination"
        )
    return H


def _unique_dofs(nodes: NDArray[np.int64], codes: NDArray[np.int64], what: str) -> None:
    key = nodes * 8 + np.abs(codes)
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    if np.any(counts > 1):
        k = int(first[np.argmax(counts > 1)])
        raise InputError(
            f"{what} DOF at node {nodes[k]} along axis {abs(int(codes[k]))} of its frame appears "
            f"{int(counts.max())} times: give each {what} DOF once"
        )


def _check_axis(freq: NDArray[np.float64]) -> None:
    if freq.size < 2 or not np.all(np.isfinite(freq)) or np.any(np.diff(freq) <= 0):
        raise InputError(
            "UFF FRFs need at least 2 finite, strictly increasing frequency lines"
        )


def write_frf_uff(
    path: str | Path,
    frfset: FRFSet,
    *,
    binary: bool = False,
    length_unit: Literal["m", "mm"] = "m",
    coherence: bool = True,
    node_dataset: Literal[2411, 15] = 2411,
) -> None:
    """Write an :class:`FRFSet` as a self-contained UFF file.

    Datasets: 164 (SI, or mm with length factor 1000 and newtons), 2420 for the
    nodes whose directions are not the global axes, 2411 (or 15) nodes, one 58
    record per response x reference DOF (function type 4, acceleration over force,
    complex double), reference-major, then coherence records (type 6) when
    ``coherence`` and ``frfset.coherence`` is not None.

    Parameters
    ----------
    path : output file, replaced atomically
    frfset : accelerances in (m/s^2)/N, geometry in m
    binary : write 58b records (IEEE doubles) instead of ASCII 58
    length_unit : "m" or "mm" for coordinates and accelerations in the file
    coherence : also write the coherence records
    node_dataset : 2411 (double precision, default) or 15 (E13.5: 6 significant digits)

    Notes
    -----
    Round-trip precision: binary files reproduce every value to rounding (1e-15
    relative); ASCII files store FRF values with 12 significant digits (relative
    error <= 5e-12 per real/imaginary part). The frequency axis is stored as start
    and increment with 6 significant digits when evenly spaced; binary files store
    every frequency instead when those 6 digits would not reproduce it exactly.

    Raises
    ------
    InputError
        NaN/infinite values; fewer than 2 or unordered frequency lines; a DOF node
        without coordinates; directions at one node that are not along the axes of
        one orthonormal frame; a DOF given twice; an unknown ``length_unit``.
    """
    coh = frfset.coherence if coherence else None
    _check_writable(frfset, coh, length_unit, node_dataset)
    factor = 1000.0 if length_unit == "mm" else 1.0
    units = (
        UnitFactors()
        if length_unit == "m"
        else UnitFactors(length=1000.0, code=9, description="mm (newton)")
    )
    n_r, n_e = frfset.H.shape[:2]
    frames, codes = assign_node_frames(
        np.concatenate([frfset.resp_nodes, frfset.exc_nodes]),
        np.concatenate([frfset.resp_dirs, frfset.exc_dirs]),
    )
    r_codes, e_codes = codes[:n_r], codes[n_r:]
    _unique_dofs(frfset.resp_nodes, r_codes, "response")
    _unique_dofs(frfset.exc_nodes, e_codes, "excitation")
    stamp = datetime.now().strftime("%d-%b-%y %H:%M:%S")
    acc = AxisInfo(12, 1, 0, "Acceleration", f"{length_unit}/s^2")
    force = AxisInfo(13, 0, 1, "Force", "N")
    kinds: list[_FunctionKind] = [(4, frfset.H * factor, acc, force, "FRF")]
    if coh is not None:
        kinds.append((6, coh, AxisInfo(1, 0, 0, "Coherence", "1"), AxisInfo(), "Coherence"))
    with open_for_writing(path) as w:
        w.units(units)
        w.geometry(frfset.geometry, frames, factor, node_dataset)
        func_id = 0
        for kind in kinds:
            func_id = _write_functions(w, frfset, kind, r_codes, e_codes, func_id, stamp, binary)
    log.info("wrote %d FRFs to %s (%s, %s)", n_r * n_e, path, "58b" if binary else "58",
             length_unit)


#: the records of one function type: type, values (n_resp, n_exc, n_f), ordinate and
#: denominator axes, name in the record's ID line
_FunctionKind = tuple[int, NDArray[np.float64] | NDArray[np.complex128], AxisInfo, AxisInfo, str]


def _check_writable(frfset: FRFSet, coh: NDArray[np.float64] | None, length_unit: str,
                    node_dataset: int) -> None:
    """InputError unless :func:`write_frf_uff` can write ``frfset`` (and ``coh``) as asked."""
    if length_unit not in ("m", "mm"):
        raise InputError(f"length_unit must be 'm' or 'mm', got {length_unit!r}")
    if node_dataset not in (2411, 15):
        raise InputError(f"node_dataset must be 2411 or 15, got {node_dataset!r}")
    _check_axis(frfset.freq)
    if not np.all(np.isfinite(frfset.H)):
        raise InputError("the FRFs hold NaN or infinite values: drop those lines before writing")
    if coh is not None and not np.all(np.isfinite(coh)):
        raise InputError("the coherence holds NaN or infinite values: drop those lines first")
    frfset.geometry.coordinates(frfset.resp_nodes, "response")  # InputError if a node lacks one
    frfset.geometry.coordinates(frfset.exc_nodes, "excitation")


def _write_functions(w: UffWriter, frfset: FRFSet, kind: _FunctionKind,
                     r_codes: NDArray[np.int64], e_codes: NDArray[np.int64], func_id: int,
                     stamp: str, binary: bool) -> int:
    """Write one 58 record per response x reference DOF, reference-major, numbered on from
    ``func_id``; the last number used."""
    func_type, values, ordinate, denominator, name = kind
    freq_axis = AxisInfo(18, 0, 0, "Frequency", "Hz")
    n_r, n_e = frfset.H.shape[:2]
    for j in range(n_e):
        ref = (int(frfset.exc_nodes[j]), int(e_codes[j]))
        for i in range(n_r):
            rsp = (int(frfset.resp_nodes[i]), int(r_codes[i]))
            func_id += 1
            w.function(
                func_type=func_type,
                func_id=func_id,
                load_case=0,
                response=rsp,
                reference=ref,
                x=frfset.freq,
                data=values[i, j],
                abscissa=freq_axis,
                ordinate=ordinate,
                denominator=denominator,
                ids=[f"{name} {rsp[0]}:{rsp[1]:+d} / {ref[0]}:{ref[1]:+d}", "insitu", stamp],
                binary=binary,
            )
    return func_id
