"""Run files damaged anywhere: a run, or one RunFileError line, never another exception.

Damage at the HDF5 level (objects and attributes deleted, replaced by values of another type
or shape) and at the byte level (the file cut short).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from _fuzz import FUZZ, no_hang
from hypothesis import given
from hypothesis import strategies as st

from app.io.runfile import RunFileError, RunWriter, read_run
from drivers.base import ChannelConfig
from processing.data import FRFSet, Geometry
from processing.measurement import Measurement, Provenance


@pytest.fixture(scope="module")
def whole(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("run") / "run.h5"
    chans = [ChannelConfig("F", 0, "force", 2.25),
             ChannelConfig("a", 1, "acceleration", 10.0, node=1, direction=(1, 0, 0))]
    geo = Geometry(np.array([1, 101]), np.array([[0.1, 0, 0], [0, 0.1, 0]]))
    w = RunWriter.create(path, plan_data={"plan": {"hits": 1}}, station_data={}, channels=chans,
                         devices=["fe", "fe"], geometry=geo, fs=256.0, n_samples=32,
                         method="hammer")
    for k in range(2):
        w.add_record(k, np.full((2, 32), k + 1.0), time=k, peak_force=10.0,
                     auto_accepted=bool(k), reason="double hit" if not k else "")
    w.add_note("tip changed", 1.0)
    frf = FRFSet(np.arange(1.0, 5.0), np.ones((1, 1, 4), complex), np.array([1]),
                 np.array([[1.0, 0, 0]]), np.array([101]), np.array([[0, 1.0, 0]]), geo,
                 np.ones((1, 1, 4)))
    w.finish("finished", "", Measurement(frf, Provenance(origin="estimated", n_averages=(1,))),
             {"mass": 1.0})
    return path


def _objects(f: h5py.File) -> list[str]:
    names: list[str] = []
    f.visit(names.append)
    return sorted(names)


weird = (st.integers(-(2**63), 2**63 - 1) | st.floats() | st.text(max_size=8)
         | st.binary(max_size=8) | st.lists(st.floats(), max_size=4).map(np.array)
         | st.just(np.zeros((0, 3))) | st.just(np.ones((2, 2, 2), complex)))


@FUZZ
@given(ops=st.lists(st.tuples(st.sampled_from(["delete", "replace", "attr", "del-attr"]),
                              st.integers(0, 10_000), weird), min_size=1, max_size=3),
       cut=st.none() | st.floats(0.0, 1.0))
def test_damaged_run_file(whole: Path, tmp_path_factory: pytest.TempPathFactory,
                          ops: list[tuple[str, int, Any]], cut: float | None) -> None:
    path = tmp_path_factory.mktemp("damaged") / "run.h5"
    path.write_bytes(whole.read_bytes())
    with h5py.File(path, "a") as f, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numpy casts of odd values
        for op, i, value in ops:
            names = _objects(f)
            if not names:
                break
            name = names[i % len(names)]
            obj = f[name]
            try:
                if op == "delete":
                    del f[name]
                elif op == "replace" and isinstance(obj, h5py.Dataset):
                    del f[name]
                    f[name] = value
                elif op == "attr":
                    keys = ["format", "schema_version", "state", "fs", "units", "fs_raw",
                            "method"]
                    (obj if i % 2 else f).attrs[keys[i % len(keys)]] = value
                elif op == "del-attr" and obj.attrs:
                    del obj.attrs[sorted(obj.attrs)[i % len(obj.attrs)]]
            except (ValueError, TypeError):
                pass  # a value HDF5 cannot hold (a NUL in a string): no damage done
    if cut is not None:
        path.write_bytes(path.read_bytes()[: int(cut * path.stat().st_size)])
    with no_hang():
        try:
            run = read_run(path)
        except RunFileError as err:
            assert str(err) and "\n" not in str(err).strip()
            return
    assert len(run.records) <= 2 and run.records.data.shape[0] == len(run.records), (
        run.records.data.shape, run.records.point.shape, ops)
