"""The UFF readers on damaged files: an FRF set or one InputError line, never another exception.

Damage: cut anywhere, datasets reordered, dropped or duplicated (written back by pyuff),
bytes flipped, a line replaced by noise.
"""

from __future__ import annotations

import random
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import pyuff
from _fuzz import FUZZ, FUZZ_SLOW, no_hang
from hypothesis import given
from hypothesis import strategies as st

from app.io import read_frf_uff, read_time_uff, write_frf_uff
from app.pipeline import FRF_UFF, load
from hardware_mocks.benches import get_bench
from processing.data import InputError


def _small(binary: bool, path: Path) -> bytes:
    fs = get_bench("block").frfset()
    r, e = np.arange(3, 9), np.array([0, 7, 8])
    fs = replace(fs, freq=fs.freq[:16], H=fs.H[np.ix_(r, e)][:, :, :16],
                 resp_nodes=fs.resp_nodes[r], resp_dirs=fs.resp_dirs[r],
                 exc_nodes=fs.exc_nodes[e], exc_dirs=fs.exc_dirs[e])
    write_frf_uff(path, fs, binary=binary)
    return path.read_bytes()


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    d = tmp_path_factory.mktemp("uff")
    return {"ascii": _small(False, d / "a.uff"), "binary": _small(True, d / "b.uff")}


def _loaded_frfs(path: Path) -> object:
    return load(path, fmt=FRF_UFF).frf


def _read(path: Path) -> None:
    """Both readers and the pipeline's load: whatever the file, an answer or an InputError;
    the FRFs loaded are finite (NaN or infinite values named and left out, or refused)."""
    with no_hang():
        for reader in (read_frf_uff, _loaded_frfs, read_time_uff):
            try:
                out = reader(path)
            except InputError as err:
                assert str(err) and "\n" not in str(err).strip()
                continue
            if reader is _loaded_frfs:
                assert np.isfinite(out.H).all()  # type: ignore[attr-defined]


@FUZZ
@given(kind=st.sampled_from(["ascii", "binary"]), cut=st.floats(0.0, 1.0),
       flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)), max_size=4),
       noise_line=st.none() | st.tuples(st.floats(0.0, 1.0), st.binary(max_size=90)))
def test_damaged_bytes(files: dict[str, bytes], tmp_path_factory: pytest.TempPathFactory,
                       kind: str, cut: float, flips: list[tuple[float, int]],
                       noise_line: tuple[float, bytes] | None) -> None:
    data = bytearray(files[kind])
    data = data[: max(1, round(cut * len(data)))] if cut < 0.98 else data
    for where, value in flips:
        data[min(len(data) - 1, int(where * len(data)))] = value
    if noise_line is not None:
        lines = bytes(data).split(b"\n")
        lines[min(len(lines) - 1, int(noise_line[0] * len(lines)))] = noise_line[1]
        data = bytearray(b"\n".join(lines))
    path = tmp_path_factory.mktemp("cut") / "f.uff"
    path.write_bytes(bytes(data))
    _read(path)


@FUZZ_SLOW
@given(kind=st.sampled_from(["ascii", "binary"]), seed=st.integers(0, 2**32 - 1),
       drop=st.integers(0, 3), dup=st.integers(0, 3))
def test_datasets_reordered_dropped_duplicated(files: dict[str, bytes],
                                               tmp_path_factory: pytest.TempPathFactory,
                                               kind: str, seed: int, drop: int, dup: int
                                               ) -> None:
    d = tmp_path_factory.mktemp("sets")
    src = d / "src.uff"
    src.write_bytes(files[kind])
    sets = list(pyuff.UFF(str(src)).read_sets())
    rng = random.Random(seed)
    rng.shuffle(sets)
    for _ in range(min(drop, len(sets) - 1)):
        sets.pop(rng.randrange(len(sets)))
    for _ in range(dup):
        sets.insert(rng.randrange(len(sets) + 1), rng.choice(sets))
    out = d / "f.uff"
    with warnings.catch_warnings():  # pyuff's 58b writer leaks a file handle (closed, and
        warnings.simplefilter("ignore", ResourceWarning)  # warned of, as its call returns)
        pyuff.UFF(str(out)).write_sets(sets, mode="overwrite")
    _read(out)
