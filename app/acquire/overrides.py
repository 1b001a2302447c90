"""Operator overrides applied to a stored run, after the acquisition (no device needed).

:func:`override_run` sets the override column of some records, then recomputes
the FRFs and the identification from the raw records through the replay's code
(:func:`app.acquire.analysis.run_measurement`) and stores them when every point has
the hits (or blocks) the plan asks for: ``insitu replay`` then gives the same
FRFs and result. A run that lacks hits after the change is left for
``insitu acquire --resume`` to complete.

Example
-------
>>> out = override_run("run.h5", {2: "accept", 4: "reject"})  # doctest: +SKIP
>>> out.complete, out.message  # doctest: +SKIP
(True, '')
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.acquire.analysis import (
    analyse_blocks,
    analyse_records,
    anti_aliased,
    check_identifiable,
    run_measurement,
)
from app.acquire.plan import parse_plan
from app.io.runfile import OVERRIDES, RunData, RunFileError, RunWriter, read_run
from processing.data import InputError
from processing.geometry import GeometryError, check_geometry
from processing.identify import fit
from processing.measurement import Measurement

__all__ = ["OverrideOutcome", "override_run", "parse_override"]


@dataclass(frozen=True)
class OverrideOutcome:
    """What :func:`override_run` did.

    ``changed`` maps record index to (old, new) override; ``complete`` says whether every
    point has enough accepted records (then FRFs and the result were stored);
    ``missing`` lists ``(point index, accepted, needed)`` of the others; ``message`` is the
    identification failure or refusal, if any; ``result`` is None when not identified
    (as in the live run: a partial plan whose excitations cannot span 6 DOFs).
    """

    run: RunData
    changed: dict[int, tuple[str, str]]
    complete: bool
    missing: list[tuple[int, int, int]]
    message: str
    result: dict[str, Any] | None


def parse_override(text: str) -> tuple[int, str]:
    """``"HIT=accept|reject|clear"`` (HIT 1-based, as printed) -> (0-based index, override).

    Examples
    --------
    >>> parse_override("3=accept")
    (2, 'accept')
    >>> parse_override("7=clear")
    (6, '')
    """
    hit, sep, what = text.partition("=")
    what = what.strip().lower()
    try:
        n = int(hit)
    except ValueError:
        n = 0
    if not sep or n < 1 or what not in ("accept", "reject", "clear"):
        raise ValueError(f"--override {text!r}: give HIT=accept, HIT=reject or HIT=clear "
                         "(HIT the record number as printed, from 1)")
    return n - 1, "" if what == "clear" else what


def _needed(run: RunData) -> tuple[list[int], int]:
    plan = parse_plan(run.plan_data, f"{run.path}:/plan")
    if run.method == "shaker":
        _, blocks = analyse_blocks(run)
        return [blocks.n_used(d) for d in range(len(plan.drives))], plan.shaker.averages
    _, ana = analyse_records(run)
    return [ana.n_used(j) for j in range(len(plan.excitations))], plan.hits


def _spans_six_dofs(run: RunData) -> bool:
    plan = parse_plan(run.plan_data, f"{run.path}:/plan")
    g = run.geometry
    resp = run.channels[plan.n_references:]
    try:
        rep = check_geometry(g.coordinates(np.array([c.node for c in resp])),
                             np.array([c.direction for c in resp]),
                             g.coordinates(plan.exc_nodes), plan.exc_dirs)
    except (GeometryError, InputError):
        return False
    return rep.ok


def override_run(path: str | Path, overrides: Mapping[int, str],
                 identify: bool = True) -> OverrideOutcome:
    """Apply operator overrides (record index 0-based -> ``accept``, ``reject`` or ``""``).

    Raises
    ------
    RunFileError
        The file is not a readable run, an index is out of range, an override unknown,
        or a record with lost samples is to be accepted (one line each).
    """
    p = Path(path)
    run = read_run(p)
    rec = run.records
    new = list(rec.override)
    changed: dict[int, tuple[str, str]] = {}
    for i, ov in sorted(overrides.items()):
        if ov not in OVERRIDES:
            raise RunFileError(f"{p}: override {ov!r}: choose accept, reject or clear")
        if not 0 <= i < len(rec):
            raise RunFileError(f"{p}: no record {i + 1}: the run holds {len(rec)}")
        if ov == "accept" and not np.all(np.isfinite(rec.data[i])):
            raise RunFileError(f"{p}: record {i + 1} lost samples ({rec.reason[i]}): it "
                               "cannot be used, whatever the override")
        changed[i] = (new[i], ov)
        new[i] = ov
    amended = dataclasses.replace(run, records=dataclasses.replace(rec, override=tuple(new)))
    used, need = _needed(amended)
    missing = [(j, n, need) for j, n in enumerate(used) if n < need]
    measurement: Measurement | None = None
    result: dict[str, Any] | None = None
    message = ""
    if not missing:
        measurement, _ = run_measurement(amended)
        if identify and _spans_six_dofs(amended):  # as the live run: not a partial plan
            try:
                check_identifiable(amended)
                result = fit(anti_aliased(measurement)).to_json()
            except (InputError, GeometryError) as err:
                message = f"identification failed: {err}"
    state = "finished" if not missing else (
        "stopped" if run.state in ("interrupted", "running") else run.state)
    if missing:
        message = run.message or "points lack accepted records: insitu acquire --resume"
    writer = RunWriter.resume(p)
    try:
        for i in changed:
            writer.set_override(i, new[i])
    finally:
        writer.finish(state, message, measurement, result)
    return OverrideOutcome(read_run(p), changed, not missing, missing, message, result)
