"""The uncertainty structure of a result and its result-JSON keys (METHOD.md ``std``/``ci95``)."""

from __future__ import annotations

import numpy as np
import pytest

from processing.results import UNCERTAIN_KEYS, Contribution, Uncertainty


def test_json_mirrors_the_keys_with_their_shapes() -> None:
    std = {k: np.full(shape, 0.5) for k, shape in UNCERTAIN_KEYS.items()}
    u = Uncertainty(std=std, ci95={"mass": np.array([9.0, 11.5])}, sources=("fit covariance",),
                    contributions=(Contribution("cog z", "point 3 location", 0.7),))
    out = u.to_json()
    assert set(out["std"]) == set(UNCERTAIN_KEYS)
    assert np.shape(out["std"]["stiffness"]) == (6, 6) and out["std"]["mass"] == 0.5
    assert out["ci95"] == {"mass": [9.0, 11.5]}
    assert out["uncertainty"]["contributions"] == [
        {"quantity": "cog z", "source": "point 3 location", "fraction": 0.7}]


@pytest.mark.parametrize(("std", "ci95", "message"), [
    ({"cog": np.ones(2)}, {}, "'cog' has shape (2,), expected (3,)"),
    ({"weight": np.ones(1)}, {}, "unknown key 'weight'"),
    ({}, {"mass": np.ones(3)}, "'mass' has shape (3,), expected (2,)"),
])
def test_wrong_shapes_and_keys_refused(std: dict, ci95: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Uncertainty(std=std, ci95=ci95)
