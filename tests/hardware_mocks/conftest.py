"""Fixtures for the mock devices: a shared bench, and a check that no thread is left behind."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from hardware_mocks.benches import get_bench
from hardware_mocks.physics import BenchPhysics


@pytest.fixture(scope="session")
def engine_physics_factory():
    bench = get_bench("engine")
    return lambda: BenchPhysics(bench)


@pytest.fixture(autouse=True)
def no_thread_left() -> Iterator[None]:
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + 30.0  # threads end at once; this guards against a hang
    left: list[threading.Thread] = []
    while time.monotonic() < deadline:
        left = [t for t in threading.enumerate() if t not in before and t.is_alive()]
        if not left:
            return
        time.sleep(0.02)
    pytest.fail(f"threads left running: {[t.name for t in left]}")
