"""Time data to identification with default options against the exact FRFs of the same
scenario (a fast subset of ``benchmarks/timedata.py``): two hammer tests and a
periodic-chirp shaker test of the reference model, each identified from its UFF time
records by ``insitu identify`` and from its exact accelerances on the same lines.

Measured: hammer case 7 (time / exact) mass 0.33 / 0.31 %, CoG 1.17 / 0.99 mm, inertia
1.73 / 1.92 %, K 3.5 / 3.7 %; hammer case 15 (lightly damped: an exponential window,
tau 2.2 s) mass 0.094 / 0.13 %, CoG 0.40 / 0.28 mm, inertia 0.63 / 0.82 %, K 2.7 / 2.9 %
(K 6.6 % while the windowed stiffness step was eq. 14's line-by-line mean); shaker case 2
(periodic chirp) mass 4.0 / 1.7 %, CoG 24.6 / 19.3 mm, inertia 14.7 / 10.8 %, K 10.5 /
7.7 % (its mass over the 1.5x: a strict xfail while issue 13 is open; 1.55 % before the
band and weighting changes of an earlier session). Before the defaults read the shaker's
records from the force and the rigid band could start past noisy lowest lines, the time
data gave mass errors of 3.9 % (hammer) and 70 % (chirp: Hann-windowed Welch segments of
two periods)."""

from __future__ import annotations

import pytest

from benchmarks.timedata import evaluate

#: allowed time-data error: 1.5x the exact FRFs' plus this much (mass %, CoG mm, inertia %,
#: K %)
SLACK = {"mass": 0.1, "cog": 0.5, "inertia": 0.5, "stiffness": 1.0}


@pytest.mark.parametrize(("case", "kind"), [
    (7, "hammer"),
    (15, "hammer"),
    pytest.param(2, "shaker", marks=pytest.mark.xfail(
        strict=True, reason="periodic chirp case 2: mass 4.0 % against 1.7 % from the exact "
        "FRFs (2.4x; the suite's shaker median is 1.0x, p95 1.15x)")),
])
def test_time_data_within_1_5x_of_the_exact_frfs(case: int, kind: str) -> None:
    row = evaluate(case, kind)
    assert row["detected"] == ("impact" if kind == "hammer" else "random")
    assert "errors" in row["time"], row["time"]
    assert "errors" in row["exact"], row["exact"]
    t, e = row["time"]["errors"], row["exact"]["errors"]
    for fig, slack in SLACK.items():
        assert t[fig] <= 1.5 * e[fig] + slack, (fig, t[fig], e[fig])
    if kind == "hammer":  # the double and the clipped hit rejected, no good one
        assert row["hits"].get("double rejected") == 1
        assert row["hits"].get("clipped rejected") == 1
        assert "good rejected" not in row["hits"]
    else:
        assert any(ln.startswith("shaker force periodic") for ln in row["defaults"])
