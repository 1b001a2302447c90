"""Errors of an identified result against a reference truth (the benchmark's four figures)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from hardware_mocks.reference.system import Truth

__all__ = ["METRICS", "errors"]

#: name, unit of each error figure
METRICS = (("mass", "%"), ("cog", "mm"), ("inertia", "%"), ("stiffness", "%"))


def errors(truth: Truth, mass: float, cog: ArrayLike, inertia_origin: ArrayLike,
           inertia_cog: ArrayLike, stiffness: ArrayLike) -> dict[str, float]:
    """The four error figures of one identification.

    Returns
    -------
    dict with ``mass`` (|dm| / m, %), ``cog`` (distance between the identified and true
    centres of gravity, mm), ``inertia`` (worst entry of the tensors about O and about the
    CoG, % of the largest true principal moment) and ``stiffness`` (worst entry of K at O,
    |dK_ij| / sqrt(K_ii K_jj), %).
    """
    dJ = max(float(np.max(np.abs(np.asarray(inertia_origin) - truth.inertia_origin))),
             float(np.max(np.abs(np.asarray(inertia_cog) - truth.inertia_cog))))
    d = np.sqrt(np.abs(np.diag(truth.K)))
    dK = np.abs(np.asarray(stiffness) - truth.K) / np.outer(d, d)
    return {
        "mass": abs(mass - truth.mass) / truth.mass * 100,
        "cog": float(np.linalg.norm(np.asarray(cog) - truth.cog)) * 1000,
        "inertia": dJ / float(truth.principal_moments.max()) * 100,
        "stiffness": float(np.max(dK)) * 100,
    }
