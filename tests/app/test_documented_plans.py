"""The plans the docs give (docs/*.toml) take at least 3 records a point: with one hit or
block a point the coherence is 1 by definition and its check cannot fail."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.acquire import load_plan

DOCS = Path(__file__).resolve().parents[2] / "docs"


@pytest.mark.parametrize("path", sorted(DOCS.glob("*.toml")), ids=lambda p: p.name)
def test_documented_plans_take_three_records_a_point(path: Path) -> None:
    plan = load_plan(path)
    if plan.method == "hammer":
        assert plan.hits >= 3
    else:
        assert plan.shaker.averages >= 3 and plan.shaker.averages > plan.shaker.shakers
