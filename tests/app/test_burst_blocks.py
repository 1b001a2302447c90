"""A live shaker run's burst blocks are completed with their own cut-off tail, as a file's
burst records are: a lightly damped response that still rings at the block's end leaks
nothing."""

from __future__ import annotations

import numpy as np
import scipy.signal

from app.acquire.blocks import BlockAnalysis
from app.mockbench.bench import plan_for_bench

FS, N, DUTY = 256.0, 512, 0.25


def _block(zeta: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One burst block (force, then 12 identical responses of a 9 Hz oscillator of damping
    ``zeta``) cut at N samples while the response still rings, and the exact FRF."""
    rng = np.random.default_rng(seed)
    f = np.zeros(4 * N)
    f[8:8 + int(DUTY * N)] = rng.standard_normal(int(DUTY * N))
    w0 = 2 * np.pi * 9.0
    sys = scipy.signal.cont2discrete(([w0**2, 0, 0], [1, 2 * zeta * w0, w0**2]), 1 / FS,
                                     method="bilinear")
    b, a = np.ravel(sys[0]), np.ravel(sys[1])
    x = scipy.signal.lfilter(b, a, f)  # accelerance of a unit-mass oscillator, at rest first
    data = np.vstack([f[None, :N], np.repeat(x[None, :N], 12, axis=0)])
    freq = np.fft.rfftfreq(N, 1 / FS)
    z = np.exp(2j * np.pi * freq / FS)
    exact = np.polyval(b[::-1], 1 / z) / np.polyval(a[::-1], 1 / z)
    return data, freq, exact


def test_a_burst_block_is_completed_with_its_own_tail() -> None:
    plan = plan_for_bench("engine-rigid", points=[0], fs=FS, method="shaker", shaker={
        "waveform": "burst-random", "level": 0.5, "f_start": 2.0, "f_stop": FS / 2.56,
        "averages": 1, "nperseg": N, "duty": DUTY})
    ana = BlockAnalysis(plan, [f"c{i}" for i in range(13)], None, workers=1)
    data, freq, exact = _block(zeta=0.01, seed=3)
    band = (freq > 3.0) & (freq < 60.0)
    errors = []
    for block in (data, ana.averaged(data)):
        X = np.fft.rfft(block, axis=-1)
        H = X[1] / X[0]
        errors.append(np.median(np.abs(H[band] / exact[band] - 1)))
    assert errors[0] > 0.05  # the cut tail leaks: several % off
    assert errors[1] < 0.01 * errors[0], errors  # completed: the leakage gone
    assert not np.shares_memory(ana.averaged(data), data)


def test_other_blocks_are_averaged_as_they_are() -> None:
    plan = plan_for_bench("engine-rigid", points=[0], fs=FS, method="shaker", shaker={
        "waveform": "random", "level": 0.5, "averages": 1, "nperseg": N})
    ana = BlockAnalysis(plan, [f"c{i}" for i in range(13)], None, workers=1)
    data = np.random.default_rng(0).standard_normal((13, N))
    assert ana.averaged(data) is data
