"""Format detection reads headers only, and a time UFF is parsed once on its way to FRFs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import app.io._uff_common as uff_common
from app.io.uff import write_frf_uff
from app.io.uff_time import read_time_file, write_time_uff
from app.pipeline import FRF_UFF, TIME_UFF, Settings, detect_format, load
from hardware_mocks.benches import get_bench
from tests.app.test_uff import engine_runs


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_a_time_uff_is_told_by_its_first_record_header(tmp_path: Path, binary: bool) -> None:
    runs, geometry = engine_runs(1024.0)
    path = tmp_path / "t.uff"
    write_time_uff(path, runs, geometry, binary=binary)
    assert detect_format(path) == TIME_UFF
    # the data after the first record's header are never read: spoil them
    raw = path.read_bytes()
    head = raw.index(b"\n    58")
    cut = head + 2000
    path.write_bytes(raw[:cut] + b"\x00garbage\n" * 10)
    assert detect_format(path) == TIME_UFF


def test_an_frf_uff_is_no_time_uff(tmp_path: Path) -> None:
    path = tmp_path / "f.uff"
    write_frf_uff(path, get_bench("block").frfset())
    assert detect_format(path) == FRF_UFF
    assert detect_format(tmp_path / "missing.uff") == FRF_UFF  # its reader says what is wrong


def test_a_time_uff_is_indexed_once_and_its_responses_read_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    runs, geometry = engine_runs(1024.0)
    path = tmp_path / "t.uff"
    write_time_uff(path, runs, geometry)
    indexed: list[str] = []
    reads: list[int] = []  # the dataset of each read of samples (headers not counted)
    real = uff_common.pyuff.UFF

    class Counted(real):  # type: ignore[misc, valid-type]
        def __init__(self, filename: str) -> None:
            indexed.append(filename)
            super().__init__(filename)

        def read_sets(self, setn: int, header_only: bool = False) -> object:
            if not header_only:
                reads.append(setn)
            return super().read_sets(setn=setn, header_only=header_only)

    monkeypatch.setattr(uff_common.pyuff, "UFF", Counted)
    m = load(path, Settings(excitation="random", nperseg=64))
    assert indexed == [str(path)]  # detection read headers only; the file indexed once
    assert m.frf.H.shape[:2] == (12, 3) and m.provenance.estimated
    # units and geometry first, then per run its force and 12 responses: the settings read
    # the forces alone, the spectra each run whole, once
    types = list(real(str(path)).get_set_types())
    first = types.index(58)
    assert types[first:] == [58] * 39
    forces = [first + 13 * k for k in range(3)]
    assert sorted(reads) == sorted([*range(first), *forces, *range(first, first + 39)])
    data = read_time_file(path)
    assert data.load_cases == (1, 2, 7)
    assert [data.read_run(lc).load_case for lc in data.load_cases] == [1, 2, 7]
    np.testing.assert_allclose(data.geometry().xyz, geometry.xyz, atol=1e-15)
