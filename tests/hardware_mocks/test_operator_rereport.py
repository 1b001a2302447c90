"""The mock operator's arm hits once per reported hit, not again when a hit is re-reported."""

from __future__ import annotations

from types import SimpleNamespace

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
        assert op._timer is None  # nothing left to repeat the reported hit
    finally:
        op.shutdown()
