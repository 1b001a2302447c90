"""``insitu mock-bench`` as its own process: the real drivers connect with its station file."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from drivers.base import AcquisitionFrontEnd
from drivers.registry import create_device
from drivers.station import load_station
from hardware_mocks.bench_control import BenchControl, BenchControlError
from hardware_mocks.benches import get_bench
from hardware_mocks.physics import BenchPhysics

FS = 256


@pytest.fixture
def mock_bench(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Path]]:
    station = tmp_path / "station.toml"
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli.main", "mock-bench", "--station", str(station),
         "--fe-rate", str(FS)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120.0  # only guards against a hang
        while not station.exists():
            if proc.poll() is not None or time.monotonic() > deadline:
                _, err = proc.communicate(timeout=5)
                pytest.fail(f"mock-bench did not start (status {proc.returncode}): {err}")
            time.sleep(0.05)
        yield proc, station
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


def test_hits_through_the_printed_station(mock_bench: tuple[subprocess.Popen[str], Path]
                                          ) -> None:
    proc, station_path = mock_bench
    station = load_station(station_path)
    assert set(station.devices) == {"hammer", "shaker", "frontend"}
    assert station.devices["frontend"].transport.bus_kwargs()["interface"] == "socketcand"
    fe = create_device(station.devices["frontend"])
    hammer = create_device(station.devices["hammer"])
    assert isinstance(fe, AcquisitionFrontEnd) and isinstance(hammer, AcquisitionFrontEnd)
    try:
        fe.open()
        hammer.open()
        fe.start()
        hammer.start()
        with BenchControl.from_station(station_path) as control:
            hits = control.hit(exc=4, peak=150.0, duration=0.005)
            assert hits[0]["exc"] == 4
            block = fe.read_block(FS, timeout=30.0)  # (a hang guard)
            force_hammer = hammer.read_block(4096, timeout=30.0).channel("hammer")
            with pytest.raises(BenchControlError, match=r"out of range 0\.\.17"):
                control.hit(exc=99)
            assert control.status()["hits"] == 1
    finally:
        fe.shutdown()
        hammer.shutdown()
    assert block.complete and fe.health.ok() and hammer.health.ok()
    assert force_hammer.max() == pytest.approx(150.0, rel=0.01)
    force = block.channel("F")
    assert force.sum() / FS == pytest.approx(2 * 150.0 * 0.005 / np.pi, rel=1e-3)
    # the model's accelerations for the force the front end measured
    physics = BenchPhysics(get_bench("engine"))
    expected = physics.response(force, 4, FS)
    acc = np.vstack([block.channel(f"a{node}{axis}") for node in (1, 2, 3, 4) for axis in "xyz"])
    assert np.abs(acc - expected).max() / np.abs(expected).max() < 2e-3

    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert out == station_path.read_text() and "stopped" in err
