"""The simulated operator of a mock bench in another process, through its control channel."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from drivers.station import parse_station
from hardware_mocks.bench_control import BenchControl, BenchControlError, control_address
from hardware_mocks.bench_process import MockBench
from hardware_mocks.benches import get_bench
from hardware_mocks.operator import RemoteOperator, RemoteShakerOperator, check_points


def _point(index: int, node: int, direction: tuple[float, float, float]) -> SimpleNamespace:
    return SimpleNamespace(index=index, node=node, direction=direction,
                           label=f"point {index + 1} (node {node})")


def _hit(point: int, complete: bool, hit_id: int) -> SimpleNamespace:
    return SimpleNamespace(point=point, point_complete=complete, override="", hit_id=hit_id)


def test_remote_operator_hits_where_the_procedure_asks_and_keeps_errors() -> None:
    with MockBench("engine-rigid") as bench:
        station = parse_station(_toml(bench.station_toml()), "bench.toml")
        with BenchControl(*control_address(station)) as control:
            op = RemoteOperator(control, pause=0.05, patience=0)
            assert op.bench.name == "engine-rigid"
            op.on_next_point(_point(0, 104, (-1.0, 0.0, 0.0)))   # excitation 3
            op.on_hit(_hit(0, False, 0))                        # not complete: again
            op.on_hit(_hit(0, False, 0))                        # re-reported: ignored
            op.on_hit(_hit(0, True, 1))                         # complete: no more
            hits = bench.physics.hits()
            assert [h.exc for h in hits] == [3, 3] and [h.peak for h in hits] == [200.0, 200.0]
            shaker = RemoteShakerOperator(control)
            shaker.on_next_point(_point(2, 110, (0.0, 1.0, 0.0)))  # excitation 9
            assert bench.shaker.exc == 9 and shaker.points == [2]
            shaker.on_finished(None)
            assert bench.shaker.exc is None
            bench.shutdown()   # the bench goes away mid-run: kept, never raised
            op.on_next_point(_point(1, 101, (1.0, 0.0, 0.0)))
            assert "connection closed" in op.error or "mock bench control" in op.error
            assert op.hits_made == 3
            op.shutdown()


def test_check_points_names_the_point_the_bench_cannot_be_hit_at() -> None:
    bench = get_bench("engine")
    assert check_points(bench, [_point(0, 101, (1, 0, 0)), _point(1, 107, (0, -1, 0))]) == [0, 6]
    with pytest.raises(ValueError, match=r"point 2 \(node 999\): the bench has no excitation "
                                         r"node 999 \(it has 101, 102"):
        check_points(bench, [_point(0, 101, (1, 0, 0)), _point(1, 999, (1, 0, 0))])
    with pytest.raises(ValueError, match=r"point 1 \(node 107\): the bench excites node 107 "
                                         r"only along \[0, -1, 0\]$"):
        check_points(bench, [_point(0, 107, (0, 0, 1))])


def test_control_address_and_an_absent_bench_give_one_line() -> None:
    devices = {"shaker": {"backend": "shaker-scpi", "transport": {"url": "/dev/ttyUSB0"}}}
    real = parse_station({"devices": devices}, "real.toml")
    with pytest.raises(BenchControlError, match=r"real.toml: no \[extra.mock_bench\] control "):
        control_address(real)
    bad = parse_station({"devices": devices, "extra": {"mock_bench": {"control": "localhost"}}},
                        "bad.toml")
    with pytest.raises(BenchControlError, match=r"bad.toml: a bad \('localhost'\)"):
        control_address(bad)
    with MockBench("engine-rigid") as bench:
        port = bench.control_port
    with pytest.raises(BenchControlError, match=r"cannot connect \(is insitu mock-bench "
                                                r"running\?\)"):
        BenchControl("127.0.0.1", port, timeout=1.0)


def _toml(text: str) -> dict[str, object]:
    import tomllib

    return tomllib.loads(text)
