"""Plan and station files with any value anywhere: a plan or station, or one line naming the key."""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

from _fuzz import FUZZ
from hypothesis import given
from hypothesis import strategies as st

from app.acquire.plan import PlanError, parse_plan
from drivers.station import StationConfigError, parse_station

PLAN = tomllib.loads((Path(__file__).resolve().parents[2] / "docs" / "mock_bench_plan.toml")
                     .read_text())
STATION = tomllib.loads("""
[station]
name = "bench"
[devices.frontend]
backend = "frontend-can"
fs = 1024
transport = { interface = "virtual", channel = "fuzz", fd = true }
options = { frame = "fd" }
[[devices.frontend.channels]]
name = "F"
input = 12
quantity = "force"
sensitivity = 2.25
range = 5.0
[[devices.frontend.channels]]
name = "a1x"
input = 0
quantity = "acceleration"
sensitivity = 10.2
range = 5.0
iepe = true
[devices.hammer]
backend = "hammer-serial"
fs = 4096
transport = { url = "/dev/ttyUSB0", baudrate = 921600 }
[[devices.hammer.channels]]
name = "hammer"
input = 0
quantity = "force"
sensitivity = 2.25
range = 5.0
""")

values = st.recursive(
    st.integers(-(2**63), 2**63 - 1) | st.floats() | st.text(max_size=12) | st.booleans(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                 max_size=3),
    max_leaves=8)


def _places(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [path]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _places(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _places(v, (*path, i))
    return out


@st.composite
def mutated(draw: st.DrawFn, base: dict[str, Any]) -> dict[str, Any]:
    data = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(_places(data)))
        if not path:
            continue
        parent: Any = data
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = draw(values)
        elif action == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(st.text(max_size=6))] = draw(values)
        else:
            parent.append(draw(values))
    return data


def _one_line(err: ValueError) -> None:
    text = str(err)
    assert text and "\n" not in text.strip() and "Traceback" not in text


@FUZZ
@given(mutated(PLAN))
def test_plan(data: dict[str, Any]) -> None:
    try:
        plan = parse_plan(data, "plan.toml")
    except PlanError as err:
        _one_line(err)
        return
    assert plan.record.fs > 0 and plan.record.n_samples > 0 and plan.excitations


@FUZZ
@given(mutated(STATION))
def test_station(data: dict[str, Any]) -> None:
    try:
        station = parse_station(data, "station.toml")
    except StationConfigError as err:
        _one_line(err)
        return
    assert station.devices
