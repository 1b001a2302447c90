"""The live shaker analysis (app/acquire/blocks.py) on the offline path's parallel kernel:
its sums are the one-shot accumulator's, bit for bit, with one thread or two, live and
rebuilt, and scipy's cross-spectra to rounding."""

from __future__ import annotations

import os

import numba
import numpy as np
import pytest
import scipy.signal
from numpy.testing import assert_allclose, assert_array_equal
from numpy.typing import NDArray

from app.acquire.blocks import REBUILD_BLOCKS, WINDOWS, WORKERS, BlockAnalysis
from app.acquire.plan import TestPlan
from app.mockbench.bench import plan_for_bench
from processing.spectral import CrossSpectra, SpectralAccumulator

FS, NPS = 1024.0, 256
NAMES = ["F", *(f"a{i}" for i in range(12))]


def _plan(waveform: str) -> TestPlan:
    return plan_for_bench("engine-rigid", points=[0, 1], fs=FS, method="shaker", shaker={
        "waveform": waveform, "nperseg": NPS, "averages": 4, "f_start": 2.0,
        "f_stop": 400.0})


def _blocks(n: int) -> list[NDArray[np.float64]]:
    rng = np.random.default_rng(7)
    out = []
    for _ in range(n):
        f = rng.standard_normal(NPS)
        x = np.cumsum(f)[None, :] * np.arange(1, 13)[:, None] * 1e-2
        out.append(np.vstack([f, x + 0.1 * rng.standard_normal((12, NPS))]))
    return out


def _offline(plan: TestPlan, blocks: list[NDArray[np.float64]], workers: int) -> CrossSpectra:
    acc = SpectralAccumulator(FS, NPS, 0, window=WINDOWS[plan.shaker.waveform],
                              detrend=False, workers=workers)
    acc.update(np.concatenate(blocks, axis=1))  # the whole recording at once
    return acc.spectra()


def _same(a: CrossSpectra, b: CrossSpectra) -> None:
    for name in ("Sff", "Sfx", "Sxx"):
        assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.n_averages == b.n_averages


def test_the_live_analysis_runs_on_both_cores_as_the_offline_path() -> None:
    ana = BlockAnalysis(_plan("random"), NAMES, None)
    assert ana.workers == WORKERS == min(2, os.cpu_count() or 1)
    assert ana._accumulator().workers == min(WORKERS, numba.config.NUMBA_NUM_THREADS)


@pytest.mark.parametrize("waveform", ["random", "burst-random", "chirp"])
@pytest.mark.parametrize("workers", [1, 2])
def test_live_and_rebuilt_sums_equal_the_offline_ones(waveform: str, workers: int) -> None:
    plan = _plan(waveform)
    n = REBUILD_BLOCKS + 5  # a rebuild in two calls
    blocks = _blocks(n + 1)
    blocks[3][4, 100] = np.nan  # lost samples: never used
    stored = dict(enumerate(blocks))
    ana = BlockAnalysis(plan, NAMES, None, workers=workers,
                        loader=lambda ids: ((i, stored[i]) for i in ids))
    for i, b in enumerate(blocks):
        v = ana.add(i, 0, b)
        ana.set_used(i, v is not None and v[0])
    used = [b for i, b in enumerate(blocks) if i != 3]
    live = ana.point(0)
    assert live is not None and live.n_accepted == n
    offline = _offline(plan, used, 1)
    _same(live.spectra, offline)
    _same(live.spectra, _offline(plan, used, 2))
    # an older block rejected: the point is rebuilt from the stored blocks, in batches
    ana.add(1, 0, blocks[1], "reject")
    ana.set_used(1, False)
    rebuilt = ana.point(0)
    assert rebuilt is not None and rebuilt.n_accepted == n - 1
    kept = [b for i, b in enumerate(blocks) if i not in (1, 3)]
    _same(rebuilt.spectra, _offline(plan, kept, 1))
    # and scipy's Welch cross-spectra of the same blocks, to rounding
    x = np.concatenate(kept, axis=1)
    kw = {"fs": FS, "nperseg": NPS, "noverlap": 0, "window": WINDOWS[waveform],
          "detrend": False}
    _, Pfx = scipy.signal.csd(x[0], x[1:], **kw)
    _, Pff = scipy.signal.welch(x[0], **kw)
    assert_allclose(rebuilt.spectra.Sfx[0], Pfx, rtol=1e-10, atol=1e-12 * np.abs(Pfx).max())
    assert_allclose(rebuilt.spectra.Sff[0, 0].real, Pff, rtol=1e-10,
                    atol=1e-12 * Pff.max())
