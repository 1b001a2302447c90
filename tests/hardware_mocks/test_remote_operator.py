"""The simulated operator of a mock bench in another process, through its control channel."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from drivers.station import parse_station
from hardware_mocks.bench_control import BenchControl, BenchControlError, control_address
from hardware_mocks.bench_process import MockBench
from hardware_mocks.benches import get_bench
from hardware_mocks.operator import RemoteOperator, RemoteShakerOperator, check_points
from hardware_mocks.physics import TIP_PEAK


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
            assert [h.exc for h in hits] == [3, 3] and [h.peak for h in hits] == [TIP_PEAK] * 2
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


def test_a_bench_with_two_shakers_addresses_each() -> None:
    with MockBench("engine-rigid", shakers=2) as bench:
        station = parse_station(_toml(bench.station_toml()), "bench.toml")
        assert [n for n in station.devices if n.startswith("shaker")] == ["shaker", "shaker2"]
        assert station.devices["shaker2"].transport.url == bench.shakers[1].path
        forces = [(c.name, c.input) for c in station.devices["frontend"].channels
                  if c.quantity == "force"]
        assert forces == [("F1", 12), ("F2", 13)] and station.extra["mock_bench"]["shakers"] == 2
        # one generator, two signals: one time origin, two seeds, two force sensors
        a, b = bench.shakers
        assert a._t_origin == b._t_origin and (a._seed, b._seed) == (0, 1)
        assert (a.sensor, b.sensor) == (0, 1) and a.serial_number != b.serial_number
        with BenchControl(*control_address(station)) as control:
            control.request(cmd="attach-shaker", exc=4)          # the one-shaker request
            control.attach_shaker(7, shaker=2)
            assert (a.exc, b.exc) == (4, 7)
            status = control.status()
            assert status["shaker"]["exc"] == 4
            assert [s["exc"] for s in status["shakers"]] == [4, 7]
            with pytest.raises(BenchControlError, match=r"attach-shaker: no shaker 3: the bench "
                                                        r"has shakers 1\.\.2"):
                control.attach_shaker(1, shaker=3)
            control.fault("shaker2", "silent", True)
            assert b.faults.silent and not a.faults.silent
            with pytest.raises(BenchControlError, match="one of hammer, shaker, shaker2, "
                                                        "frontend"):
                control.fault("shaker3", "silent", True)
            # a drive of two points: shaker 1 at the first, shaker 2 at the second
            op = RemoteShakerOperator(control, shakers=2)
            op.on_next_point(_point(2, 104, (-1.0, 0.0, 0.0)))   # excitation 3
            op.on_next_point(_point(3, 105, (0.0, 1.0, 0.0)))    # excitation 4
            assert (a.exc, b.exc) == (3, 4) and op.points == [2, 3] and not op.error
            op.on_finished(None)
            assert (a.exc, b.exc) == (None, None)
    with MockBench("engine-rigid") as one:
        with BenchControl("127.0.0.1", one.control_port) as control:
            with pytest.raises(BenchControlError, match=r"no shaker 2: the bench has one"):
                control.attach_shaker(3, shaker=2)
            assert len(control.status()["shakers"]) == 1
