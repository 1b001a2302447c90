"""The plans the docs give (docs/*_plan.toml) take at least 3 records a point: with one hit or
block a point the coherence is 1 by definition and its check cannot fail. The station files
they give (docs/*_station.toml) load."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.acquire import load_plan
from drivers.station import load_station

DOCS = Path(__file__).resolve().parents[2] / "docs"


def test_every_documented_toml_is_a_plan_or_a_station() -> None:
    names = {p.name for p in DOCS.glob("*.toml")}
    assert names == {p.name for p in [*DOCS.glob("*_plan.toml"), *DOCS.glob("*_station.toml")]}


@pytest.mark.parametrize("path", sorted(DOCS.glob("*_station.toml")), ids=lambda p: p.name)
def test_documented_stations_load(path: Path) -> None:
    assert load_station(path).devices


@pytest.mark.parametrize("path", sorted(DOCS.glob("*_plan.toml")), ids=lambda p: p.name)
def test_documented_plans_take_three_records_a_point(path: Path) -> None:
    plan = load_plan(path)
    if plan.method == "hammer":
        assert plan.hits >= 3
    else:
        assert plan.shaker.averages >= 3 and plan.shaker.averages > plan.shaker.shakers
