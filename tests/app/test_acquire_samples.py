"""``on_samples``: the procedures hand every read of their streams to the listeners, in
order and without gaps, so that a GUI can draw continuous traces; the hit and block records
are cut from the very samples streamed."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.acquire import HammerProcedure, Listener, RunState, SampleBlock, ShakerProcedure
from app.mockbench.bench import InProcessBench, plan_for_bench


class Samples(Listener):
    def __init__(self) -> None:
        self.blocks: list[SampleBlock] = []
        self.hits: list[Any] = []
        self.samples_before_first_hit = 0

    def on_samples(self, block: SampleBlock) -> None:
        self.blocks.append(block)

    def on_hit(self, hit: Any) -> None:
        if not self.hits:
            self.samples_before_first_hit = sum(b.data.shape[1] for b in self.blocks)
        self.hits.append(hit)

    def stream(self) -> NDArray[np.float64]:
        return np.hstack([b.data for b in self.blocks])


def _found_in(stream: NDArray[np.float64], record: NDArray[np.float64]) -> bool:
    """``record`` is a contiguous slice of ``stream`` (every row, bit for bit)."""
    n = record.shape[1]
    for k in np.flatnonzero(stream[0] == record[0, 0]):
        if k + n <= stream.shape[1] and np.array_equal(stream[:, k:k + n], record):
            return True
    return False


def test_hammer_streams_every_read_and_hits_are_cut_from_them(tmp_path: Path) -> None:
    plan = plan_for_bench("engine-rigid", points=[0, 1], length=0.5)
    rec = Samples()
    duck = object()  # a listener without on_samples is fine
    with InProcessBench("engine-rigid") as bench:
        proc = HammerProcedure(plan, bench.station, tmp_path / "run.h5", partial=True,
                               listeners=[bench.operator, rec, duck])
        t_start = time.monotonic()
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
    names = tuple(c.name for c in proc.rows)
    assert names[0] == "F_fe" and len(names) == 13
    assert all(b.names == names and b.fs == 1024.0 for b in rec.blocks)
    assert all(b.data.shape == (13, 102) for b in rec.blocks)  # 0.1 s reads
    t = np.array([b.t_read for b in rec.blocks])
    assert np.all(np.diff(t) >= 0)
    # each block's first sample was taken after the run started and before it was read
    t_first = np.array([b.t_first for b in rec.blocks], dtype=float)
    assert np.all((t_first >= t_start) & (t_first <= t))
    # the settling reads (0.7 s) came before the first hit, and nothing was skipped since:
    # every record (force and responses) is a slice of the streamed samples
    assert rec.samples_before_first_hit >= 0.7 * 1024
    stream = rec.stream()
    assert len(rec.hits) == 2
    for hit in rec.hits:
        assert _found_in(stream, hit.data)


def test_shaker_streams_ramps_and_blocks(tmp_path: Path) -> None:
    fs = 512.0
    plan = plan_for_bench("engine-rigid", points=[0], fs=fs, method="shaker", shaker={
        "waveform": "chirp", "level": 0.5, "f_start": 2.0, "f_stop": fs / 2.56,
        "averages": 2, "nperseg": 256, "ramp": 0.1, "settle": 0.3})
    rec = Samples()
    with InProcessBench("engine-rigid", fs_frontend=fs) as bench:
        proc = ShakerProcedure(plan, bench.station, tmp_path / "shaker.h5", partial=True,
                               listeners=[bench.shaker_operator, rec])
        proc.start()
        assert proc.wait(300) is RunState.FINISHED, proc.message
    assert all(b.data.shape == (13, 51) and b.fs == fs for b in rec.blocks)
    # ramp and settling were streamed too (dropped by the procedure, shown to listeners)
    assert rec.samples_before_first_hit >= (0.1 + 0.3) * fs
    stream = rec.stream()
    assert np.abs(stream[0]).max() > 1.0  # the shaker's force is in the force row
    assert len(rec.hits) == 2
    for hit in rec.hits:
        assert _found_in(stream, hit.data)
