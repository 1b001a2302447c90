"""A time UFF is read one run at a time: memory holds one run (and the spectra), never the
file's samples; a run found bad by its responses only leaves the settings as if it were
never in the file."""

from __future__ import annotations

import dataclasses
import weakref
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import app.io.uff_time as uff_time
from app.io.uff_time import TimeFile, TimeRun, write_time_uff
from app.pipeline import Settings, load
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import HammerSpec, hammer_test, write_uff
from tests.app.test_uff import engine_runs


class Held:
    """How many runs (:meth:`TimeFile.read_run`) and parsed records (pyuff's sample arrays)
    are alive at once, at most, while the reader is patched."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.alive = {"runs": 0, "records": 0}
        self.most = {"runs": 0, "records": 0}
        self.runs_read = 0
        read_run, read_set = TimeFile.read_run, uff_time.read_set

        def counted_run(f: TimeFile, load_case: int, force_only: bool = False) -> TimeRun:
            run = read_run(f, load_case, force_only)
            self.runs_read += 1
            self._track("runs", run)
            return run

        def counted_set(uff: object, index: int, header_only: bool = False) -> dict[str, object]:
            ds = read_set(uff, index, header_only)
            if isinstance(ds.get("data"), np.ndarray):
                self._track("records", ds["data"])
            return ds

        monkeypatch.setattr(TimeFile, "read_run", counted_run)
        monkeypatch.setattr(uff_time, "read_set", counted_set)

    def _track(self, kind: str, obj: object) -> None:
        self.alive[kind] += 1
        self.most[kind] = max(self.most[kind], self.alive[kind])
        weakref.finalize(obj, self._gone, kind)

    def _gone(self, kind: str) -> None:
        self.alive[kind] -= 1


def _shaker_file(tmp_path: Path, n_runs: int = 6) -> Path:
    runs, geometry = engine_runs(1024.0, n=4096)
    more = [dataclasses.replace(runs[k % 3], load_case=10 + k,
                                force=np.roll(runs[k % 3].force, 97 * k))
            for k in range(n_runs - 3)]
    path = tmp_path / "shaker.uff"
    write_time_uff(path, [*runs, *more], geometry, binary=True)
    return path


def test_a_shaker_file_is_held_one_run_at_a_time(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    path = _shaker_file(tmp_path)
    held = Held(monkeypatch)
    m = load(path, Settings())
    assert m.frf.H.shape[:2] == (12, 3)
    assert held.runs_read == 12  # the 6 forces for the settings, then the 6 runs whole
    assert held.most["runs"] == 1  # of 6 runs in the file
    assert held.most["records"] <= 2  # of 6 x 13: the record converted and the next one


def test_a_hammer_file_is_held_one_run_at_a_time(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    sc = build_scenario(ScenarioSpec(seed=3, n_forces=6, n_sensors=3, elastic_ratio=None))
    path = tmp_path / "hammer.uff"
    write_uff(hammer_test(sc, HammerSpec(seed=3, hits=2, spacing=3.0)), path)
    held = Held(monkeypatch)
    m = load(path, Settings())
    assert m.provenance.excitation == "impact" and m.frf.H.shape[1] == 6
    assert held.runs_read >= 18  # the forces, the runs whole for the defaults, then again
    assert held.most["runs"] == 1  # of 6 runs in the file
    assert held.most["records"] <= 2  # of 6 x 10


def _poisoned(path: Path, value: float) -> None:
    """Replace the one sample equal to ``value`` in a binary time UFF by NaN."""
    raw = path.read_bytes()
    mark = np.float64(value).tobytes()
    assert raw.count(mark) == 1
    path.write_bytes(raw.replace(mark, np.float64(np.nan).tobytes()))


def _impulsive(n: int) -> np.ndarray:
    f = np.random.default_rng(3).normal(0, 1e-3, n)
    f[::1024] += 100.0
    return f


def test_a_run_bad_in_its_responses_counts_in_no_setting(tmp_path: Path) -> None:
    """Runs 2 and 7 have impulsive forces and a NaN in a response: read first by their
    forces, they would make the file a hammer test (2 of 3 runs); left out, the one good
    run is random excitation, and the result is the one of the file without them."""
    runs, geometry = engine_runs(1024.0, n=4096)
    marked = 123.456789
    bad = []
    for r in runs[1:]:
        resp = r.responses.copy()
        resp[5, 100] = marked + r.load_case
        bad.append(dataclasses.replace(r, force=_impulsive(r.n_samples), responses=resp))
    path = tmp_path / "t.uff"
    write_time_uff(path, [runs[0], *bad], geometry, binary=True)
    for r in bad:
        _poisoned(path, marked + r.load_case)
    alone = tmp_path / "alone.uff"
    write_time_uff(alone, runs[:1], geometry, binary=True)

    m, ref = load(path, Settings()), load(alone, Settings())
    assert m.provenance.excitation == ref.provenance.excitation == "random"
    assert_array_equal(m.frf.H, ref.frf.H)
    skipped = [r.message for r in m.provenance.reports if r.skipped]
    assert [s.split(":")[0] for s in skipped] == ["load case 2", "load case 7"]
    assert all("1 NaN or infinite sample(s)" in s for s in skipped)
