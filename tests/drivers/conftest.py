"""Test helpers for the drivers: a scripted serial device on a pseudo-terminal.

``ScriptedDevice`` plays a list of ``(expected request bytes, reply bytes)``
exchanges, like PyMeasure's ``expected_protocol``: the literal bytes on both
sides are in the test. It does not use any driver code.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from collections.abc import Iterator

import pytest


class ScriptedDevice:
    def __init__(self, script: list[tuple[bytes, bytes]]) -> None:
        self.script = script
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        self._slave = slave
        self.received: list[bytes] = []
        self.error: str | None = None
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _read_exact(self, n: int) -> bytes:
        buf = b""
        deadline = time.monotonic() + 30.0  # only guards against a hang
        while len(buf) < n and not self._stop.is_set() and time.monotonic() < deadline:
            r, _, _ = select.select([self.master], [], [], 0.02)
            if r:
                try:
                    buf += os.read(self.master, n - len(buf))
                except OSError:
                    break
        return buf

    def _run(self) -> None:
        for expected, reply in self.script:
            got = self._read_exact(len(expected))
            self.received.append(got)
            if got != expected:
                self.error = f"expected {expected!r}, got {got!r}"
                return
            if reply:
                os.write(self.master, reply)
        self.done.set()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(3.0)
        os.close(self._slave)
        os.close(self.master)

    def check(self) -> None:
        assert self.error is None, self.error
        assert self.done.wait(30.0), f"script not finished; received {self.received}"


@pytest.fixture
def scripted() -> Iterator[type[ScriptedDevice]]:
    made: list[ScriptedDevice] = []

    class _Factory(ScriptedDevice):
        def __init__(self, script: list[tuple[bytes, bytes]]) -> None:
            super().__init__(script)
            made.append(self)

    yield _Factory
    for dev in made:
        dev.close()


@pytest.fixture(autouse=True)
def no_thread_left() -> Iterator[None]:
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + 30.0  # threads end at once; this guards against a hang
    while time.monotonic() < deadline:
        left = [t for t in threading.enumerate() if t not in before and t.is_alive()]
        if not left:
            return
        time.sleep(0.02)
    pytest.fail(f"threads left running: {[t.name for t in left]}")
