"""Time data to identification with default options against the exact FRFs of the same
scenario (a fast subset of ``benchmarks/timedata.py``): two hammer tests, a periodic-chirp
and a continuous-random shaker test of the reference model, each identified from its UFF
time records by ``insitu identify`` and from its exact accelerances on the same lines.

Measured: hammer case 7 (time / exact) mass 0.33 / 0.31 %, CoG 1.17 / 0.99 mm, inertia
1.74 / 1.92 %, K 3.5 / 3.7 % (0.14 / 0.20 %, 0.63 / 0.23 mm, 0.57 / 0.62 %, 2.4 / 2.3 % while
the mass line's model was chosen on the whole band alone); hammer case 15 (lightly damped: an
exponential window, tau 2.2 s) mass 0.094 / 0.13 %, CoG 0.40 / 0.28 mm, inertia 0.63 / 0.82 %,
K 2.7 / 2.8 % (K 6.6 % while the windowed stiffness step was eq. 14's line-by-line mean);
shaker case 2 (periodic chirp) mass 1.7 / 1.7 %, CoG 19.0 / 19.3 mm, inertia 10.7 / 10.8 %,
K 7.6 / 7.7 % (4.0 / 3.6 % mass while the model was chosen on the whole band); shaker case 45
(continuous random) mass 0.11 / 0.04 %, CoG 2.2 / 2.3 mm, inertia 1.15 / 1.28 %, K 3.2 / 3.2 %
(mass 2.9 %, inertia 6.5 %, K 9.4 % while each candidate mass line chose its own model: the
time data's mass line ended at its narrowest candidate, 16 lines, without the upper
residual). Before the defaults read the
shaker's records from the force and the rigid band could start past noisy lowest lines, the
time data gave mass errors of 3.9 % (hammer) and 70 % (chirp: Hann-windowed Welch segments of
two periods)."""

from __future__ import annotations

import pytest

from benchmarks.timedata import evaluate

#: allowed time-data error: 1.5x the exact FRFs' plus this much (mass %, CoG mm, inertia %,
#: K %)
SLACK = {"mass": 0.1, "cog": 0.5, "inertia": 0.5, "stiffness": 1.0}


@pytest.mark.parametrize(("case", "kind", "records"), [
    (7, "hammer", ""),
    (15, "hammer", ""),
    (2, "shaker", "shaker force periodic"),
    (45, "shaker", "shaker force continuous"),
])
def test_time_data_within_1_5x_of_the_exact_frfs(case: int, kind: str, records: str) -> None:
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
        assert any(ln.startswith(records) for ln in row["defaults"])


def test_lightly_damped_hammer_test_answers_where_the_rigid_lines_are_unclean() -> None:
    """Hammer case 107 (mount damping x0.23, records of 2.4 s, lines 0.42 Hz apart): its
    lightly damped rigid-body resonances make every line from 2.1 to 8.4 Hz unclean (a
    column's weight dips under a tenth of its median at its FRF's peak), leaving 4 lines
    under the rigidity check's limit (6.7 Hz) to read the rigid-body modes from; they gave
    0.36 Hz and a refusal ("stiffness band 0.42-0.54 Hz holds fewer than 2 lines"). All the
    lines there are now used: modes up to 11.4 Hz (9.5 Hz from the exact FRFs). Measured:
    mass 1.25 % (exact FRFs 0.05 %), CoG 5.8 mm, inertia 3.3 %, K 25 % (the FRFs are 4-9 %
    off at 5-30 Hz in this test)."""
    row = evaluate(107, "hammer")
    assert "errors" in row["time"], row["time"]
    t = row["time"]["errors"]
    assert t["mass"] < 2.0, t
    assert t["cog"] < 10.0, t
    assert t["inertia"] < 6.0, t
