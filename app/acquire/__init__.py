"""Acquisition: test plans, procedures in a worker thread, and their events.

Public API (stable; the GUI builds on it):

- plans: :class:`TestPlan`, :class:`ExcitationPoint`, :class:`ResponsePoint`,
  :class:`RecordSettings`, :class:`ShakerSettings`, :func:`load_plan`, :func:`parse_plan`,
  :class:`PlanError` (the built-in benches' plans and the in-process mock bench are in
  :mod:`app.mockbench`, kept apart with the simulators);
- procedures: :class:`HammerProcedure` and :class:`ShakerProcedure` (``start``, ``pause``,
  ``resume``, ``stop``, ``accept_hit``, ``reject_hit``, ``clear_override``, ``add_note``,
  ``wait``; both report through the same events and write the same run file; a shaker
  run's "hits" are its blocks);
- events: :class:`Listener` (``on_next_point``, ``on_hit``, ``on_frf``, ``on_progress``,
  ``on_paused``, ``on_resumed``, ``on_error``, ``on_finished``, and ``on_samples`` with a
  :class:`SampleBlock` after every read, for live traces), :class:`HitRecord`,
  :class:`PointFRF`, :class:`Progress`, :class:`RunState`;
- a run's measurement from its stored records: :func:`run_measurement` (every view opens
  run files through :func:`app.pipeline.load`); overrides of a stored run:
  :func:`override_run`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from app.acquire.analysis import run_measurement
    from app.acquire.events import HitRecord, Listener, PointFRF, Progress, RunState, SampleBlock
    from app.acquire.hammer import HammerProcedure
    from app.acquire.overrides import OverrideOutcome, override_run
    from app.acquire.plan import (
        ExcitationPoint,
        PlanError,
        RecordSettings,
        ResponsePoint,
        ShakerSettings,
        TestPlan,
        load_plan,
        parse_plan,
    )
    from app.acquire.procedure import Procedure
    from app.acquire.shaker import ShakerProcedure

# Each name loads its module when first used: reading a stored run (replay, identify,
# report) needs the analysis, not the procedures and their device drivers.
_WHERE = {
    "run_measurement": "analysis",
    "HitRecord": "events", "Listener": "events", "PointFRF": "events", "Progress": "events",
    "RunState": "events", "SampleBlock": "events",
    "HammerProcedure": "hammer",
    "OverrideOutcome": "overrides", "override_run": "overrides",
    "ExcitationPoint": "plan", "PlanError": "plan", "RecordSettings": "plan",
    "ResponsePoint": "plan", "ShakerSettings": "plan", "TestPlan": "plan", "load_plan": "plan",
    "parse_plan": "plan",
    "Procedure": "procedure",
    "ShakerProcedure": "shaker",
}


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    globals()[name] = value  # found once: the next use does not come here
    return value


__all__ = [
    "ExcitationPoint",
    "HammerProcedure",
    "HitRecord",
    "Listener",
    "OverrideOutcome",
    "PlanError",
    "PointFRF",
    "Procedure",
    "Progress",
    "RecordSettings",
    "ResponsePoint",
    "RunState",
    "SampleBlock",
    "ShakerProcedure",
    "ShakerSettings",
    "TestPlan",
    "load_plan",
    "override_run",
    "parse_plan",
    "run_measurement",
]
