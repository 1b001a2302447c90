"""``drivers.sync.fit_clock``: a device clock from frame arrival times, whatever the host's load."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import SyncError
from drivers.sync import check_alignment, fit_clock

FS = 2048.0
FRAME = 32  # samples per frame


def _pairs(seed: int, *, ppm: float = 0.0, seconds: float = 1.0, jitter: float = 0.3e-3,
           stalls: tuple[tuple[float, float], ...] = ()) -> tuple[list[tuple[float, int]], float]:
    """Arrival pairs of a steady clock: each frame leaves when its last sample is taken and
    arrives 0.2 ms plus an exponential delay later; during a stall ``(start s, length s)`` the
    host reads nothing, and the frames queued meanwhile all arrive when it ends."""
    rng = np.random.default_rng(seed)
    rate = FS * (1 + ppm * 1e-6)
    t_start = 5000.0 + rng.uniform(0, 100)
    count = np.arange(FRAME, int(seconds * FS), FRAME)
    t = t_start + (count - 1) / rate + 0.2e-3 + rng.exponential(jitter, count.size)
    for start, length in stalls:
        lo, hi = t_start + start, t_start + start + length
        t = np.where((t >= lo) & (t < hi), hi + rng.exponential(0.05e-3, t.size), t)
    return [(float(a), int(b)) for a, b in zip(t, count, strict=True)], t_start


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), ppm=st.floats(-8000, 8000),
       stall=st.floats(0.0, 0.7), length=st.floats(0.01, 0.12), tail=st.booleans())
def test_host_stalls_do_not_move_the_clock(seed: int, ppm: float, stall: float, length: float,
                                           tail: bool) -> None:
    # a stall anywhere (or over the last 60 ms, the frames of a run's end read late) leaves the
    # prompt frames' envelope, and so the clock, where it is. 63 frames with 0.3 ms of
    # random lateness fix the line to a few tens of us at its ends: over 3000 random cases
    # the rate was within 309 ppm (99 %: 138), t0 within 184 us, the residual under 333 us
    stalls = ((stall, length),) + (((0.94, 0.06),) if tail else ())
    pairs, t_start = _pairs(seed, ppm=ppm, stalls=stalls)
    fit = fit_clock(pairs, FS)
    assert fit.ppm == pytest.approx(ppm, abs=600.0)
    assert fit.t0 - t_start == pytest.approx(0.2e-3, abs=0.6e-3)
    assert fit.residual < 1e-3
    check_alignment({"hammer": fit})


def test_a_stall_at_the_end_of_a_short_run_is_not_a_clock_error() -> None:
    # 0.6 s of frames, the last 80 ms queued behind a busy host: a least-squares line through
    # the pairs (or through its earliest quarter) tilts by thousands of ppm; the envelope does not
    pairs, _ = _pairs(7, seconds=0.6, stalls=((0.52, 0.08),))
    t, k = np.array(pairs).T
    ls_ppm = (1 / np.polyfit(k - 1, t, 1)[0] / FS - 1) * 1e6
    assert abs(ls_ppm) > 2000
    fit = fit_clock(pairs, FS)
    assert abs(fit.ppm) < 300 and fit.residual < 1e-3
    check_alignment({"fe": fit})


@pytest.mark.parametrize("bend", ["jump", "rate"])
def test_a_clock_that_bends_is_not_measurable(bend: str) -> None:
    # samples lost unmarked (the second half 40 ms late) or a rate that changes by 6 % halfway:
    # no straight line fits the prompt frames, and the run is refused
    pairs, _ = _pairs(3)
    t, k = np.array(pairs).T
    half = k > FS / 2
    t = t + (0.04 if bend == "jump" else 0.06 * (k - FS / 2) / FS) * half
    fit = fit_clock(list(zip(t, k.astype(int), strict=True)), FS)
    assert fit.residual > 5e-3
    with pytest.raises(SyncError, match=r"fe: frame timing scatters by .* clock not measurable"):
        check_alignment({"fe": fit})


def test_exact_pairs_give_the_exact_clock() -> None:
    pairs = [(10.0 + k / 1000 / (1 + 250e-6), k) for k in range(1, 4000, 37)]
    fit = fit_clock(pairs, 1000)
    assert fit.ppm == pytest.approx(250.0, abs=1e-4)
    assert fit.t0 == pytest.approx(10.0 + 1e-3 / (1 + 250e-6), abs=1e-9)
    assert fit.residual < 1e-9 and fit.n_pairs == len(pairs)


@pytest.mark.parametrize(("pairs", "match"), [
    ([(0.0, 1)] * 5, "only 5 timing pairs: stream too short"),
    ([(0.01 * i, 64) for i in range(12)], "cover no samples"),
    ([(float("nan"), 32 * i) for i in range(1, 13)], "not finite"),
])
def test_unusable_pairs_are_refused(pairs: list[tuple[float, int]], match: str) -> None:
    with pytest.raises(SyncError, match=match):
        fit_clock(pairs, 1024)
