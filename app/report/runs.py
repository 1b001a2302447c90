"""FRFs of a recorded run file (HDF5): the stored ones, else recomputed from the records."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.acquire.analysis import analyse_run
from app.io.runfile import read_run
from processing.data import FRFSet

__all__ = ["read_run_frfs", "usable_lines"]


def usable_lines(frf: FRFSet) -> FRFSet:
    """A run's FRFs on the lines the identification uses: above 0 Hz and up to fs / 2.56
    (above it the front ends' anti-alias filters shape the data), as ``insitu identify``
    and the acquisition's own identification (:func:`app.acquire.analysis.identify_frfs`)."""
    keep = (frf.freq > 0) & (frf.freq <= frf.freq[-1] / 1.28)
    coh = None if frf.coherence is None else np.nan_to_num(frf.coherence[..., keep])
    return FRFSet(frf.freq[keep], frf.H[..., keep], frf.resp_nodes, frf.resp_dirs,
                  frf.exc_nodes, frf.exc_dirs, frf.geometry, coh, dict(frf.meta))


def read_run_frfs(path: str | Path) -> FRFSet:
    """The FRF set of a run (see :func:`usable_lines`): as stored when the run finished, else
    from its raw records.

    Raises
    ------
    RunFileError, InputError
        A foreign or damaged file; a run with a point that has no accepted hit yet.
    """
    run = read_run(path)
    frf = usable_lines(run.frf if run.frf is not None else analyse_run(run)[0])
    frf.meta.update({"file": Path(path).name, "run_state": run.state})
    if run.mounts is not None:
        frf.meta["mounts"] = run.mounts
    return frf
