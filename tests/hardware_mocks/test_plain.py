"""The plain baseline of the time-data benchmark: its H1 is the model's FRF where the data
allow it, and it feeds the article's method."""

from __future__ import annotations

import numpy as np

from hardware_mocks.reference.article import ArticleResult
from hardware_mocks.reference.plain import ANTI_ALIAS, plain_frfs, plain_identify
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import HammerSpec, ShakerSpec, hammer_test, shaker_test


def _scenario():
    return build_scenario(ScenarioSpec(seed=8301, n_forces=6, n_sensors=3, elastic_ratio=None))


def _errors(t, freq, H):
    keep = (freq > 2.0) & (freq <= t.fs / ANTI_ALIAS)
    Hx = t.exact_frf(freq[keep])
    return np.abs(H[..., keep] - Hx) / np.abs(Hx)


def test_welch_h1_is_the_exact_frf() -> None:
    """Shaker (continuous random, low noise): Welch's H1 within 1 % of the model at the
    median, 5 % at the 90th percentile (Hann leakage at the resonances)."""
    t = shaker_test(_scenario(), ShakerSpec(seed=8302, kind="random", noise_force=1e-4,
                                            noise_response=1e-4))
    freq, H = plain_frfs(t)
    assert H.shape == (*t.exact_frf(freq[:1]).shape[:2], freq.size)
    err = _errors(t, freq, H)
    assert np.median(err) < 0.01 and np.percentile(err, 90) < 0.05


def test_hammer_h1_averages_every_hit() -> None:
    """Hammer, heavily damped (rung down within a hit): the rectangular windows' H1 within
    2 % of the model at the median; a double hit is averaged in, not rejected (the FRF moves
    away from the one without it)."""
    sc = _scenario()
    kw = {"hits": 3, "spacing": 6.0, "damping": 3.0, "noise_force": 1e-4,
          "noise_response": 1e-4}
    t = hammer_test(sc, HammerSpec(seed=8303, **kw))
    freq, H = plain_frfs(t)
    assert np.median(_errors(t, freq, H)) < 0.02
    t2 = hammer_test(sc, HammerSpec(seed=8303, n_double=1, **kw))
    f2, H2 = plain_frfs(t2)
    assert np.median(_errors(t2, f2, H2)) > np.median(_errors(t, freq, H))


def test_plain_identify_runs_the_article_on_the_plain_frfs() -> None:
    t = shaker_test(_scenario(), ShakerSpec(seed=8304, kind="random"))
    res = plain_identify(t)
    assert isinstance(res, ArticleResult)
    assert res.mass_band[1] <= t.fs / ANTI_ALIAS
    assert abs(res.mass / t.truth.mass - 1) < 0.2
