"""The reference model's time-data generator: exact to the model, labelled defects, UFF."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from app.io.uff import read_time_uff
from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import (
    HIT_LEAD,
    Budget,
    HammerSpec,
    Hit,
    ShakerSpec,
    good_and_bad,
    hammer_test,
    shaker_test,
    write_uff,
)
from hardware_mocks.reference.timedata import _clipped_hits as label_clipped


@cache
def _scenario(seed: int = 1, rigid: bool = True, damping: str = "hysteretic") -> Scenario:
    return build_scenario(ScenarioSpec(seed=seed, n_forces=6, n_sensors=3,
                                       elastic_ratio=None if rigid else 6.0,
                                       damping=damping))  # type: ignore[arg-type]


@pytest.mark.parametrize(("rigid", "damping"), [(True, "hysteretic"), (True, "viscous")])
def test_responses_are_the_exact_frf_times_the_force(rigid: bool, damping: str) -> None:
    """Noise-free, heavily damped, one hit a run: the recording's DFT ratio is the model's FRF
    wherever the pulse has force (the record holds the whole decay)."""
    sc = _scenario(2, rigid, damping)
    t = hammer_test(sc, HammerSpec(seed=3, hits=1, spacing=12.0, noise_force=0.0,
                                   noise_response=0.0, offset=0.0, settling=0.0, drift=0.0,
                                   damping=3.0, fs=512))
    r = t.runs[0]
    F = np.fft.rfft(r.forces[0])
    X = np.fft.rfft(r.responses, axis=-1)
    freq = np.fft.rfftfreq(r.n_samples, 1 / t.fs)
    keep = (freq > 0.5) & (freq < t.fs / 2.56)
    H = t.exact_frf(freq[keep])[:, 0]
    err = np.abs(X[:, keep] / F[keep] - H) / np.max(np.abs(H), axis=-1, keepdims=True)
    assert err.max() < 1e-4


def test_defects_are_labelled_and_placed() -> None:
    sc = _scenario()
    t = hammer_test(sc, HammerSpec(seed=4, hits=4, n_double=2, n_clipped=1, fs=512))
    assert len(t.runs) == sc.forces.nodes.size
    good, bad = good_and_bad(t.hits)
    assert (good, bad) == (4 * len(t.runs) - 3, 3)
    assert sum(h.double for h in t.hits) == 2 and sum(h.clipped for h in t.hits) == 1
    clipped = next(r for r in t.runs if any(h.clipped for h in r.hits))
    top = np.max(np.abs(clipped.responses), axis=1)
    # the clipped channel holds a flat top: several samples exactly at its range
    assert np.max(np.sum(np.abs(clipped.responses) == top[:, None], axis=1)) >= 3
    for r in t.runs:  # hits at the drawn times: the force peaks there
        for h in r.hits:
            k = round(h.time * t.fs)
            w = slice(k, k + round(3 * h.width * t.fs) + 2)
            assert np.max(r.forces[0, w]) > 0.3 * h.peak


def test_light_damping_rings_past_the_next_hit() -> None:
    sc = _scenario()
    light = hammer_test(sc, HammerSpec(seed=5, hits=2, damping=0.2, fs=512, noise_force=0.0,
                                       noise_response=0.0, settling=0.0, offset=0.0,
                                       drift=0.0))
    heavy = hammer_test(sc, HammerSpec(seed=5, hits=2, damping=3.0, fs=512, noise_force=0.0,
                                       noise_response=0.0, settling=0.0, offset=0.0,
                                       drift=0.0))

    def before_next(t: object) -> float:
        r = t.runs[0]  # type: ignore[attr-defined]
        k = round(r.hits[1].time * 512)
        return float(np.max(np.abs(r.responses[:, k - 256:k - 64]))
                     / np.max(np.abs(r.responses)))

    assert before_next(light) > 10 * before_next(heavy)
    assert light.system.truth.mass == sc.truth.mass
    assert_allclose(light.system.truth.K_loss, 0.2 * sc.truth.K_loss, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("kind", ["random", "burst", "chirp"])
def test_shaker_force_drops_at_resonances(kind: str) -> None:
    sc = _scenario()
    quiet = {"noise_force": 0.0, "noise_response": 0.0, "offset": 0.0, "settling": 0.0,
             "drift": 0.0}
    t = shaker_test(sc, ShakerSpec(seed=6, kind=kind, duration=16.0, armature=5.0, fs=256,
                                   **quiet))  # type: ignore[arg-type]
    free = shaker_test(sc, ShakerSpec(seed=6, kind=kind, duration=16.0, armature=0.0, fs=256,
                                      **quiet))  # type: ignore[arg-type]
    r = t.runs[0]
    assert r.forces.shape == (1, round(16.0 * 256)) and r.responses.shape[0] == 9
    # the same drive: the applied force over the free one is 1 / (1 + m_a H_dd)
    freq = np.fft.rfftfreq(r.n_samples, 1 / 256)
    band = (freq > 2) & (freq < 30)
    ratio = np.abs(np.fft.rfft(r.forces[0]) / np.fft.rfft(free.runs[0].forces[0]))[band]
    e = r.excitations
    Hdd = t.system.accelerance(freq[band], sc.forces.nodes[e], sc.forces.vectors[e],
                               sc.forces.nodes[e], sc.forces.vectors[e])[0, 0]
    want = np.abs(1 / (1 + 5.0 * Hdd))
    assert want.min() < 0.9  # a drop-out there is
    assert np.median(np.abs(ratio - want)) < 0.02


def test_two_shakers_are_correlated_and_not_writable(tmp_path: Path) -> None:
    sc = _scenario()
    t = shaker_test(sc, ShakerSpec(seed=7, shakers=2, correlation=0.5, duration=8.0, fs=256))
    r = t.runs[0]
    assert r.forces.shape[0] == 2 and r.excitations.tolist() == [0, 1]
    c = np.corrcoef(r.forces)[0, 1]
    assert 0.3 < c < 0.7
    with pytest.raises(ValueError, match="2 forces"):
        write_uff(t, tmp_path / "two.uff")


@pytest.mark.parametrize("binary", [True, False])
def test_uff_reads_back(tmp_path: Path, binary: bool) -> None:
    sc = _scenario()
    t = hammer_test(sc, HammerSpec(seed=8, hits=2, spacing=2.0, fs=512))
    path = tmp_path / "t.uff"
    write_uff(t, path, binary=binary)
    runs = read_time_uff(path)
    assert len(runs) == len(t.runs)
    for got, want in zip(runs, t.runs, strict=True):
        assert got.fs == 512.0 and got.load_case == want.load_case
        rtol = 0 if binary else 1e-10
        assert_allclose(got.force, want.forces[0], rtol=rtol,
                        atol=1e-10 * np.abs(want.forces).max())
        assert_allclose(got.responses, want.responses, rtol=rtol,
                        atol=1e-10 * np.abs(want.responses).max())
        e = int(want.excitations[0])
        assert got.exc_node == sc.forces.ids[e]
        assert_allclose(got.exc_dir, sc.forces.reported_dirs[e])
        assert_allclose(got.resp_dirs, sc.sensors.reported_dirs)


_QUIET = {"noise_force": 0.0, "noise_response": 0.0, "offset": 0.0, "settling": 0.0,
          "drift": 0.0}


def test_skewed_channels_are_the_exact_frf_delayed() -> None:
    """Skew up to a sample: each response's DFT ratio is the model's FRF times the delay
    ``exp(-j w tau)`` of its channel, tau within the drawn bound, the force undelayed."""
    sc = _scenario(2)
    spec = HammerSpec(seed=3, hits=1, spacing=12.0, damping=3.0, fs=512, **_QUIET)
    t0 = hammer_test(sc, spec)
    t = hammer_test(sc, HammerSpec(**{**spec.__dict__, "budget": Budget(skew=1.0)}))
    r, r0 = t.runs[0], t0.runs[0]
    assert_allclose(r.forces, r0.forces, rtol=0, atol=0)
    F = np.fft.rfft(r.forces[0])
    freq = np.fft.rfftfreq(r.n_samples, 1 / t.fs)
    keep = (freq > 0.5) & (freq < t.fs / 2.56)
    H = t.exact_frf(freq[keep])[:, 0]
    ratio = (np.fft.rfft(r.responses, axis=-1)[:, keep] / F[keep]) / H
    w = 2 * np.pi * freq[keep]
    tau = -(np.angle(ratio) @ w) / (w @ w)  # each channel's delay: the phase's slope
    assert np.all(np.abs(tau) <= 1.0 / t.fs) and np.ptp(tau) > 0.1 / t.fs
    err = np.abs(ratio - np.exp(-1j * w[None] * tau[:, None])) * np.abs(H) / np.max(
        np.abs(H), axis=-1, keepdims=True)
    assert err.max() < 1e-4


def test_converter_codes_clip_and_label_the_hits() -> None:
    """A 16-bit converter over fixed ranges: every sample a multiple of its channel's step;
    two channels sit at their range on 1-5 samples of the test, and exactly the hits that
    reach a range are labelled clipped."""
    sc = _scenario()
    b = Budget(bits=16, headroom=(2.0, 50.0), clip_channels=2, clip_samples=(1, 5))
    t = hammer_test(sc, HammerSpec(seed=5, hits=4, fs=512, budget=b))
    ranges = t.ranges
    assert ranges is not None
    over = [np.sum(np.abs(r.responses) >= ranges[:, None] * (1 - 1e-12), axis=1)
            for r in t.runs]  # samples at each channel's range, each run
    at_top = np.sum(over, axis=0)
    assert np.count_nonzero(at_top) == 2 and np.all(at_top <= 5)
    clipped_hits = 0
    for r in t.runs:
        at = [max(round(h.time * t.fs) - HIT_LEAD, 0) for h in r.hits] + [r.n_samples]
        for h, a, z in zip(r.hits, at[:-1], at[1:], strict=True):
            reach = np.any(np.abs(r.responses[:, a:z]) >= ranges[:, None] * (1 - 1e-12))
            assert h.clipped == bool(reach)
            clipped_hits += h.clipped
    assert 1 <= clipped_hits < 4 * len(t.runs)
    # codes: each channel's samples are whole multiples of one step, at most 2^16 of them
    for x in (x for r in t.runs for x in r.responses):
        levels = np.unique(x)
        step = np.min(np.diff(levels))
        assert_allclose(levels / step, np.round(levels / step), rtol=0, atol=1e-6)
        assert levels.size <= 2**16


def test_a_clip_just_before_a_hit_is_that_hits() -> None:
    """A sample at a range a sample before a hit's start (its zero-phase filtered response
    leads the force) labels that hit, not the one before, whose record never holds it (as
    in a budget test whose third hit's first clipped sample came 3 ms before its start)."""
    fs = 256.0
    hits = (Hit(1.0, 100.0, 0.01), Hit(5.0, 100.0, 0.01), Hit(9.0, 100.0, 0.01))
    full = np.zeros(12 * 256, dtype=bool)
    full[round(9.0 * fs) - 1] = True
    assert [h.clipped for h in label_clipped(hits, full, fs)] == [False, False, True]
    full[:] = False
    full[round(5.0 * fs) + 200] = True  # the second hit's ringing, 0.8 s after it
    assert [h.clipped for h in label_clipped(hits, full, fs)] == [False, True, False]
    assert [h.clipped for h in label_clipped(hits, np.zeros_like(full), fs)] == [False] * 3


def test_mains_hum_sits_at_the_mains_lines() -> None:
    """Hum on the responses at 50 Hz and its harmonics, at the drawn fraction of each
    channel's RMS; the force has none."""
    sc = _scenario()
    spec = ShakerSpec(seed=2, duration=8.0, fs=512, **_QUIET)
    t0 = shaker_test(sc, spec)
    t = shaker_test(sc, ShakerSpec(**{**spec.__dict__, "budget": Budget(hum=0.05)}))
    r, r0 = t.runs[0], t0.runs[0]
    assert_allclose(r.forces, r0.forces, rtol=0, atol=0)
    d = r.responses - r0.responses
    D = np.abs(np.fft.rfft(d, axis=-1))
    freq = np.fft.rfftfreq(r.n_samples, 1 / t.fs)
    lines = [int(np.argmin(np.abs(freq - f))) for f in (50.0, 100.0, 150.0)]
    assert set(np.argsort(D, axis=-1)[:, -3:].ravel()) <= set(lines)
    rms0 = np.sqrt(np.mean(r0.responses**2, axis=1))
    amp = np.sqrt(2) * np.sqrt(np.mean(d**2, axis=1)) / np.sqrt(1 + 0.5**2 + 0.3**2)
    assert_allclose(amp, 0.05 * rms0, rtol=0.02)
