"""The built-in benches' hammer: a hard tip whose force reaches their band, and an operator
who lets the bench ring out between hits."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest

from app.mockbench.bench import plan_for_bench
from hardware_mocks.benches import BENCHES, get_bench
from hardware_mocks.operator import MockOperator
from hardware_mocks.physics import BenchPhysics, Hit, pulse_band, sampled_pulse
from processing.impact import FORCE_DROP, force_band_top


def _spectrum(hit: Hit, fs: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Lines (Hz) and auto-spectrum of one pulse sampled as the mock devices sample it."""
    t = np.arange(round(length * fs)) / fs
    f = sampled_pulse(t, 1.0 / fs, [hit])
    return np.fft.rfftfreq(t.size, 1.0 / fs), np.abs(np.fft.rfft(f)) ** 2


@pytest.mark.parametrize("duration", [0.004, 0.001, 0.0005])
def test_pulse_band_is_where_the_pulse_falls_20_db(duration: float) -> None:
    # sampled at 1 MHz (the sampling's own box filter takes off under 0.01 dB there),
    # 5 Hz lines: the first line 20 dB under the 0 Hz value is within a line of the formula
    freq, S = _spectrum(Hit(0.01, 0, 1.0, duration), 1e6, 0.2)
    first = freq[np.argmax(S < FORCE_DROP * S[0])]
    assert pulse_band(duration) <= first < pulse_band(duration) + 5.0


def test_the_built_in_hammer_reaches_every_built_in_band() -> None:
    fs = 1024.0  # the built-in plans' front end; their band is fs / 2.56
    for name in BENCHES:
        hit = BenchPhysics(get_bench(name)).hit(exc=0, delay=0.0)[0]  # the benches' own tip
        assert pulse_band(hit.duration) > fs / 2
        freq, S = _spectrum(Hit(0.1, 0, hit.peak, hit.duration), fs, 2.0)
        keep = (freq > 0) & (freq <= fs / 2.56)
        assert force_band_top(freq[keep], S[None, keep]) is None, name


class _Arm:
    """Records when each hit lands (host s)."""

    def __init__(self) -> None:
        self.t0: list[float] = []

    def hit(self, exc: int = 0, peak: float = 0.0, *, duration: float = 0.0,
            delay: float = 0.05, double: Any = None) -> None:
        self.t0.append(time.monotonic() + delay)


@pytest.mark.parametrize("settle", [0.0, 1.0])
def test_the_operator_lets_the_bench_ring_out(settle: float) -> None:
    plan = plan_for_bench("engine-rigid", points=[0, 1], hits=1)
    arm = _Arm()
    op = MockOperator(arm, bench=get_bench("engine-rigid"), patience=0.0, settle=settle)
    t = time.monotonic()
    op.on_next_point(plan.excitations[0])
    op.on_next_point(plan.excitations[1])  # asked for at once: waits for the ring-out
    assert arm.t0[0] - t == pytest.approx(op.pause, abs=0.05)
    assert arm.t0[1] - arm.t0[0] == pytest.approx(settle, abs=0.05)
