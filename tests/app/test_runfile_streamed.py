"""A run file is processed again reading its records one at a time: memory holds one record
(and the points' spectra), never the run's samples, and the FRFs are those of the records
held in memory at once."""

from __future__ import annotations

import weakref
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import app.pipeline.runs as runs
from app.acquire.analysis import run_measurement
from app.io.runfile import read_run
from app.pipeline import Settings, load
from tests.app.test_pipeline import FS, _run_file


def test_a_run_file_is_read_one_record_at_a_time(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    path = _run_file(tmp_path / "run.h5", [0, 1, 2, 0, 1, 2])
    alive, most, read = [0], [0], [0]

    def gone() -> None:
        alive[0] -= 1

    real = runs.iter_record_data

    def counted(p: Path, ids: Sequence[int] | None = None,
                ) -> Iterator[tuple[int, np.ndarray]]:
        for i, data in real(p, ids):
            read[0] += 1
            alive[0] += 1
            most[0] = max(most[0], alive[0])
            weakref.finalize(data, gone)
            yield i, data
            del data

    monkeypatch.setattr(runs, "iter_record_data", counted)
    for s in (Settings(), Settings(run_points="usable")):
        read[0] = 0
        m = load(path, s)
        assert m.frf.H.shape[1] == 3
        assert read[0] >= 6  # every record read through the one-at-a-time reader
    assert most[0] <= 2  # of 6: the record analysed and the one being read

    # the FRFs of the run's records held in memory at once, to the bit
    full = run_measurement(read_run(path))[0].frf
    keep = (full.freq > 0) & (full.freq <= FS / 2.56)
    assert_array_equal(load(path).frf.H, full.H[..., keep])
