"""The mock operator's arm hits once per reported hit, not again when a hit is re-reported, and
again only when the run has read its patience of data without reporting the hit."""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from app.mockbench.bench import plan_for_bench
from hardware_mocks.benches import get_bench
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.operator import MockOperator
from hardware_mocks.physics import BenchPhysics


def _hit(hit_id: int, override: str = "") -> SimpleNamespace:
    return SimpleNamespace(hit_id=hit_id, override=override, point_complete=False)


def test_rereported_hit_is_not_a_new_hit() -> None:
    plan = plan_for_bench("engine-rigid", points=[0], hits=3)
    with HammerDevice(BenchPhysics(get_bench("engine-rigid"))) as hammer:
        op = MockOperator(hammer, patience=60.0)
        try:
            op.on_next_point(plan.excitations[0])
            assert op.hits_made == 1
            op.on_hit(_hit(0))  # judged: the point needs more, hit again
            assert op.hits_made == 2
            op.on_hit(_hit(0, "reject"))  # the operator overrides hit 0
            op.on_hit(_hit(0))  # ... and clears the override: the same hit reported again
            assert op.hits_made == 2
            op.on_hit(_hit(1))
            assert op.hits_made == 3
        finally:
            op.shutdown()


class _ReportingHammer:
    """A hammer whose hit is reported, and the run finished, before ``hit`` returns: what a
    loaded machine does when it holds the operator's thread while the hit lands."""

    def __init__(self, op: list[MockOperator]) -> None:
        self.op = op
        self.physics = SimpleNamespace(bench=get_bench("engine-rigid"))

    def hit(self, **_: object) -> None:
        self.op[0].on_hit(SimpleNamespace(hit_id=0, override="", point_complete=True))
        self.op[0].on_finished("finished")


def test_a_hit_reported_before_the_operator_looks_up_is_not_repeated() -> None:
    """The wait for the report is armed before the hammer lands, so the report (and the run's
    end) cancel it; armed after, it would outlive the run and repeat the hit."""
    plan = plan_for_bench("engine-rigid", points=[0], hits=1)
    box: list[MockOperator] = []
    op = MockOperator(_ReportingHammer(box), bench=get_bench("engine-rigid"),  # type: ignore[arg-type]
                      patience=60.0)
    box.append(op)
    try:
        op.on_next_point(plan.excitations[0])
        assert op.hits_made == 1
        for _ in range(3):  # the run reads on, past the patience: nothing to repeat
            op.on_samples(_block(40.0))
        assert op.hits_made == 1 and op.repeats == 0
    finally:
        op.shutdown()


def _block(seconds: float, fs: float = 100.0, t_first: float | None = None) -> SimpleNamespace:
    """What the run read: ``seconds`` of samples at ``fs`` (an on_samples block), the first
    taken at host time ``t_first`` (None: not known)."""
    return SimpleNamespace(data=np.zeros((2, round(seconds * fs))), fs=fs, t_first=t_first)


def test_a_hit_never_reported_is_repeated_after_the_patience_in_data() -> None:
    plan = plan_for_bench("engine-rigid", points=[0], hits=2)
    with HammerDevice(BenchPhysics(get_bench("engine-rigid"))) as hammer:
        op = MockOperator(hammer, patience=1.0)
        try:
            op.on_next_point(plan.excitations[0])
            for _ in range(3):  # 1.2 s read: the third read crossed the patience ...
                op.on_samples(_block(0.4))
            assert op.hits_made == 1  # ... and may hold the hit: the run judges it first
            op.on_samples(_block(0.4))  # the next read: nothing reported, hit again
            assert op.hits_made == 2 and op.repeats == 1
            op.on_hit(_hit(0))  # the repeat reported: the point needs one more
            assert op.hits_made == 3
            op.on_samples(_block(0.9))
            op.on_hit(_hit(1))  # reported within the patience: the next hit, no repeat
            assert op.hits_made == 4 and op.repeats == 1
            op.on_samples(_block(5.0))  # one long read past the patience: not yet
            assert op.hits_made == 4
            op.on_paused("the front end stopped")  # no hitting while the run waits
            for _ in range(3):
                op.on_samples(_block(5.0))
            assert op.hits_made == 4 and op.repeats == 1
        finally:
            op.shutdown()


def test_a_backlog_read_after_the_hit_does_not_count_against_it() -> None:
    """A loaded machine that held the run reads seconds of samples taken before the hit at
    once: only the samples taken after the hit landed count towards the patience."""
    plan = plan_for_bench("engine-rigid", points=[0], hits=2)
    with HammerDevice(BenchPhysics(get_bench("engine-rigid"))) as hammer:
        op = MockOperator(hammer, patience=1.0, pause=0.2)
        try:
            t = time.monotonic()
            op.on_next_point(plan.excitations[0])  # lands 0.2 s after t
            for k in range(4):  # 12 s of backlog, all taken before the hit
                op.on_samples(_block(3.0, t_first=t - 12.0 + 3.0 * k))
            op.on_samples(_block(0.4, t_first=t))  # 0.2 s of it after the hit
            assert op.hits_made == 1 and op.repeats == 0
            op.on_samples(_block(0.9, t_first=t + 0.4))  # 1.1 s after: crossed ...
            assert op.hits_made == 1
            op.on_samples(_block(0.1, t_first=t + 1.3))  # ... and the next read: hit again
            assert op.hits_made == 2 and op.repeats == 1
        finally:
            op.shutdown()
