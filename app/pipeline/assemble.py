"""Excitation columns -> one FRF set on its usable lines, and the checks reported on it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from app.pipeline.settings import OpenError, RunReport
from processing.coherence import coherence_gate
from processing.data import FRFSet, Geometry
from processing.geometry import GeometryError
from processing.rigidity import rigidity_check

__all__ = ["assemble", "check_reports"]


def assemble(freq: NDArray[np.float64], Hs: Sequence[NDArray[np.complex128]],
             cohs: Sequence[NDArray[np.float64]], resp_nodes: NDArray[np.int64],
             resp_dirs: NDArray[np.float64], exc_nodes: NDArray[np.int64],
             exc_dirs: NDArray[np.float64], geometry: Geometry, fmax: float,
             reports: list[RunReport]) -> tuple[FRFSet, NDArray[np.bool_]]:
    """Excitation columns -> FRF set on the lines above 0 Hz up to ``fmax`` Hz, and which
    columns were kept.

    A column with undefined values there (no force at those frequencies) is reported (one
    skipped :class:`RunReport` appended to ``reports``) and dropped. Raises
    :class:`OpenError` when fewer than 8 lines are left or no column is defined.
    """
    if np.count_nonzero((freq > 0) & (freq <= fmax)) < 8:
        raise OpenError(f"fewer than 8 lines between 0 and --fmax {fmax:g} Hz: raise --fmax "
                        "or the record length", reports)
    whole = FRFSet(freq=freq, H=np.concatenate(Hs, axis=1), resp_nodes=resp_nodes,
                   resp_dirs=resp_dirs, exc_nodes=exc_nodes, exc_dirs=exc_dirs,
                   geometry=geometry, coherence=np.concatenate(cohs, axis=1))
    cut = whole.select_lines(fmax)
    finite = np.all(np.isfinite(cut.H), axis=(0, 2))
    for j in np.flatnonzero(~finite):
        n = int(np.count_nonzero(~np.all(np.isfinite(cut.H[:, j]), axis=0)))
        reports.append(RunReport(f"excitation node {cut.exc_nodes[j]}: FRF undefined at {n} "
                                 "lines (no force there): excite the whole band", skipped=True))
    if not finite.any():
        raise OpenError("every FRF column is undefined somewhere (no force at some "
                        "frequencies): excite the whole band", reports)
    if finite.all():
        return cut, finite
    assert cut.coherence is not None
    return FRFSet(freq=cut.freq, H=cut.H[:, finite], resp_nodes=cut.resp_nodes,
                  resp_dirs=cut.resp_dirs, exc_nodes=cut.exc_nodes[finite],
                  exc_dirs=cut.exc_dirs[finite], geometry=geometry,
                  coherence=cut.coherence[:, finite]), finite


def check_reports(frf: FRFSet, threshold: float) -> list[RunReport]:
    """The coherence gate summary and the rigidity check of an FRF set, one report each."""
    assert frf.coherence is not None
    out = [RunReport(coherence_gate(frf.coherence, frf.freq, threshold).summary())]
    try:
        out.append(RunReport(rigidity_check(frf).summary()))
    except GeometryError as err:
        out.append(RunReport(f"rigidity check not possible: {err}"))
    return out
