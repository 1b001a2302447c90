"""Tolerances of the identifications run on the mock bench's noise-free data."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_allclose

from processing.inertia import inertia_properties


def assert_identifies(res: dict[str, Any], model: Any) -> None:
    """Result JSON ``res`` against bench ``model``'s truth: mass within 0.5 %, CoG 2 mm,
    inertia at the CoG 1 % and K 2 % of their largest entries."""
    truth = inertia_properties(model.theta)
    assert res["mass"] == pytest.approx(truth.mass, rel=0.005)
    assert_allclose(res["cog"], truth.cog, atol=0.002)
    assert_allclose(res["inertia_cog"], truth.inertia_cog,
                    atol=0.01 * np.abs(truth.inertia_cog).max())
    assert_allclose(res["stiffness"], model.K, atol=0.02 * np.abs(model.K).max())
