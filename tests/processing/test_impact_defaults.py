"""Defaults read from hammer and shaker data, checked on the reference model's generated tests
(known hits, damping and excitation)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import (
    HammerSpec,
    ShakerSpec,
    TimeTest,
    hammer_test,
    shaker_test,
)
from processing.impact import (
    ImpactSettings,
    excitation_type,
    impact_defaults,
    process_impacts,
)


@cache
def _scenario(seed: int) -> Scenario:
    return build_scenario(ScenarioSpec(seed=seed, n_forces=4, n_sensors=2, elastic_ratio=None))


@cache
def _hammer(seed: int, damping: float = 1.0) -> TimeTest:
    rng = np.random.default_rng(seed)
    return hammer_test(_scenario(seed % 5), HammerSpec(
        seed=seed, hits=4, spacing=float(rng.uniform(2.5, 4.5)), n_double=1, n_clipped=1,
        damping=damping, noise_force=float(rng.uniform(2e-4, 2e-3)), fs=512))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_excitation_type(seed: int) -> None:
    for r in _hammer(seed).runs:
        assert excitation_type(r.forces[0]).kind == "impact"
    for kind in ("random", "burst", "chirp"):
        t = shaker_test(_scenario(seed), ShakerSpec(seed=seed, kind=kind,  # type: ignore[arg-type]
                                                    duration=12.0, fs=256))
        assert {excitation_type(r.forces[0]).kind for r in t.runs} == {"random"}


def test_all_bad_hits_rejected_and_no_good_one_over_20_tests() -> None:
    counts = {"bad rejected": 0, "bad accepted": 0, "good rejected": 0, "good accepted": 0}
    for seed in range(20):
        t = _hammer(seed, damping=float(np.exp(np.random.default_rng(seed).uniform(-1.5, 1))))
        for r in t.runs:
            d = impact_defaults(r.forces[0], r.responses, t.fs)
            s = ImpactSettings(d.level, round(d.record * t.fs), round(0.01 * t.fs),
                               exp_tau=d.exp_tau)
            res = process_impacts(np.vstack([r.forces, r.responses]), t.fs, s)
            assert len(res.verdicts) == len(r.hits)  # one trigger a hit
            for v, h in zip(res.verdicts, r.hits, strict=True):
                assert abs(v.trigger / t.fs - h.time) < 0.02
                key = ("good " if h.good else "bad ") + ("accepted" if v.accepted else "rejected")
                counts[key] += 1
    assert counts["bad rejected"] == 40 and counts["bad accepted"] == 0
    assert counts["good rejected"] == 0 and counts["good accepted"] == 20 * 4 * 4 - 40


def test_record_and_window_follow_spacing_and_decay() -> None:
    light, heavy = _hammer(30, damping=0.2), _hammer(30, damping=3.0)
    gaps = np.diff([h.time for h in light.runs[0].hits])
    dl = impact_defaults(light.runs[0].forces[0], light.runs[0].responses, light.fs)
    dh = impact_defaults(heavy.runs[0].forces[0], heavy.runs[0].responses, heavy.fs)
    assert dl.n_hits == dh.n_hits == 4
    assert dl.spacing is not None and abs(dl.spacing - gaps.min()) < 0.02
    # light: rings past the next hit: the longest record the spacing allows, and a window
    assert dl.decay > gaps.min() and dl.record == pytest.approx(0.95 * gaps.min(), abs=0.011)
    assert dl.exp_tau is not None and dl.exp_tau < dl.record
    # heavy: decays within the record: no window, the record shorter than the spacing
    assert dh.exp_tau is None and dh.record < 0.95 * gaps.min() and dh.decay < dh.record
    # the pulse width and the level read from the force
    widths = [h.width for h in light.runs[0].hits]
    assert min(widths) - 2 / light.fs < dl.pulse_width < max(widths) + 2 / light.fs
    assert 0 < dl.level < 0.1 * min(h.peak for h in light.runs[0].hits)


def test_soft_tips_double_hit_is_no_spacing() -> None:
    """A soft tip (pulses 2x the band's width, about 16 ms at 256 Hz) rebounds 2.5-8 widths
    after its first pulse: 40-130 ms, past the 0.1 s within which two impacts are one. The
    record was then cut to that rebound's gap (0.12 s for hits 4 s apart)."""
    sc = _scenario(1)
    for seed in range(4):
        t = hammer_test(sc, HammerSpec(seed=seed, hits=4, spacing=3.0, n_double=4, tip=2.0,
                                       fs=256))
        for r in t.runs:
            gaps = np.diff([h.time for h in r.hits])
            d = impact_defaults(r.forces[0], r.responses, t.fs)
            assert d.spacing is not None and abs(d.spacing - gaps.min()) < 0.05, (seed, d)
            assert d.record > 0.5 * gaps.min()
