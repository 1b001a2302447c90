"""Tolerances of the identifications run on the mock bench's noise-free data, and the
documented plans cut to fewer points for the real-time runs."""

from __future__ import annotations

import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_allclose

from app.acquire.plan import plan_toml
from processing.inertia import inertia_properties

#: positions, in the documented plans' nine (or ten) excitations, of the engine's six forces
#: that span the rigid-body motions (engine excitations 0, 1, 4, 8, 12, 15): the least
#: that identifies, so that a real-time run on the mock bench takes two thirds of the time
SIX = [0, 1, 3, 5, 7, 8]


def cut_plan(src: Path, keep: Sequence[int], dest: Path) -> Path:
    """Plan file ``src`` with its excitations ``keep`` only (positions, in that order), all
    else as in ``src``, written at ``dest``."""
    with src.open("rb") as fh:
        data = tomllib.load(fh)
    data["excitation"] = [data["excitation"][k] for k in keep]
    dest.write_text(plan_toml(data, f"{src.name}, excitations {list(keep)}"), encoding="utf-8")
    return dest


def assert_identifies(res: dict[str, Any], model: Any) -> None:
    """Result JSON ``res`` against bench ``model``'s truth: mass within 0.5 %, CoG 2 mm,
    inertia at the CoG 1 % and K 2 % of their largest entries."""
    truth = inertia_properties(model.theta)
    assert res["mass"] == pytest.approx(truth.mass, rel=0.005)
    assert_allclose(res["cog"], truth.cog, atol=0.002)
    assert_allclose(res["inertia_cog"], truth.inertia_cog,
                    atol=0.01 * np.abs(truth.inertia_cog).max())
    assert_allclose(res["stiffness"], model.K, atol=0.02 * np.abs(model.K).max())
