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


def test_a_time_uff_is_parsed_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    runs, geometry = engine_runs(1024.0)
    path = tmp_path / "t.uff"
    write_time_uff(path, runs, geometry)
    calls: list[object] = []
    real = uff_common.load_sets

    def counted(*args: object, **kwargs: object) -> object:
        calls.append(args)
        return real(*args, **kwargs)  # type: ignore[arg-type]

    for module in ("app.io.uff_time", "app.io.uff_geometry", "app.io.uff"):
        monkeypatch.setattr(f"{module}.load_sets", counted)
    m = load(path, Settings(excitation="random", nperseg=64))
    assert len(calls) == 1  # detection read headers only; runs and geometry in one parse
    assert m.frf.H.shape[:2] == (12, 3) and m.provenance.estimated
    data = read_time_file(path)
    assert [r.load_case for r in data.runs] == [1, 2, 7] and data.problems == []
    np.testing.assert_allclose(data.geometry().xyz, geometry.xyz, atol=1e-15)
