"""``process_impacts(force_accept=True)``: an operator's override of a rejected hit."""

from __future__ import annotations

import numpy as np
import pytest

from hardware_mocks.benches import get_bench
from hardware_mocks.signals import frf_laplace, half_sine, impulse_response, simulate
from processing.impact import ImpactSettings, process_impacts

FS = 2048.0
L = 2048
PRE = 64
TAU = 0.1
PULSE = 0.003


@pytest.fixture(scope="module")
def double_hit():
    b = get_bench("engine")
    g = b.geometry
    rx, rd = g.coordinates(b.resp_nodes), b.resp_dirs
    ex, ed = g.coordinates(b.exc_nodes[:1]), b.exc_dirs[:1]
    ir = impulse_response(b.model, FS, rx, rd, ex, ed)
    n = int(3 * FS)
    f = half_sine(n, FS, 1.0, PULSE, 200.0) + half_sine(n, FS, 1.03, PULSE, 80.0)
    He = None
    data = np.vstack([f, simulate(ir, f[None])])
    return data, (b.model, rx, rd, ex, ed), He


def test_rejected_double_hit_is_accepted_with_its_reason_and_the_rebound_in_the_window(
        double_hit) -> None:
    data, (model, rx, rd, ex, ed), _ = double_hit
    s = ImpactSettings(20.0, L, PRE, exp_tau=TAU)
    auto = process_impacts(data, FS, s)
    assert not auto.verdicts[0].accepted and auto.H is None
    assert auto.verdicts[0].reason.startswith("double hit")
    forced = process_impacts(data, FS, s, force_accept=True)
    v = forced.verdicts[0]
    assert v.accepted and v.reason == f"accepted by override: {auto.verdicts[0].reason}"
    assert forced.H is not None and forced.n_accepted == 1
    # both impacts are inside the force window: H1 is the windowed model's FRF
    He = frf_laplace(model, 2j * np.pi * forced.freq + 1 / TAU, rx, rd, ex, ed)
    band = (forced.freq >= 5.0) & (forced.freq < 300.0)
    err = np.abs(forced.H[..., band] - He[..., band]) / np.abs(He[..., band])
    assert np.median(err) < 1e-3
    # the normal window (cut after the first pulse) would lose the rebound's force: that
    # FRF is off by tens of percent, so the extension is what makes the override usable
    short = process_impacts(data, FS, ImpactSettings(20.0, L, PRE, exp_tau=TAU,
                                                     double_hit_ratio=0.5))
    assert short.H is not None
    err_short = np.abs(short.H[..., band] - He[..., band]) / np.abs(He[..., band])
    assert np.median(err_short) > 0.1


def test_clean_hit_is_unchanged_and_incomplete_records_stay_rejected(double_hit) -> None:
    data, *_ = double_hit
    clean = data.copy()
    clean[0] = half_sine(clean.shape[1], FS, 1.0, PULSE, 200.0)
    s = ImpactSettings(20.0, L, PRE, exp_tau=TAU)
    a = process_impacts(clean, FS, s)
    b = process_impacts(clean, FS, s, force_accept=True)
    assert a.H is not None and b.H is not None
    assert np.array_equal(a.H, b.H) and b.verdicts[0].reason == ""
    cut = data[:, : int(1.5 * FS)]  # the record runs past the end
    res = process_impacts(cut, FS, s, force_accept=True)
    assert not res.verdicts[0].accepted and "incomplete" in res.verdicts[0].reason
