"""Independent reference model for validating the identification (imports no project code).

A flexible lattice body (:mod:`.body`) on inclined mounts (:mod:`.mounts`), assembled with
exact FRFs and a truth from its own primitives (:mod:`.system`, :mod:`.kinematics`); sensor
and test errors (:mod:`.measurement`); random scenarios from fixed seeds
(:mod:`.scenarios`); the article's plain method written independently (:mod:`.article`).
Only numpy, scipy and the standard library are used (an import-linter contract checks it).
"""

from hardware_mocks.reference.body import SHAPES, LatticeBody, make_body
from hardware_mocks.reference.mounts import Mount
from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario, suite
from hardware_mocks.reference.system import ReferenceSystem, Truth

__all__ = [
    "SHAPES",
    "LatticeBody",
    "Mount",
    "ReferenceSystem",
    "Scenario",
    "ScenarioSpec",
    "Truth",
    "build_scenario",
    "make_body",
    "suite",
]
