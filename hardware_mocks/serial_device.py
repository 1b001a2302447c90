"""What the simulated serial instruments share: firmware in a thread on a pty.

:class:`SerialMockDevice` owns the device end of a pseudo-terminal (:class:`PtyPort`),
the thread that runs the instrument's firmware loop (:meth:`_run`, written by each
device), pulling the cable (:meth:`unplug`) and an idempotent :meth:`shutdown`; devices
are context managers. The framing of each protocol stays in the device's own module.
"""

from __future__ import annotations

import threading
import time
from types import TracebackType

from hardware_mocks.pty_port import PtyPort

__all__ = ["SerialMockDevice"]


class SerialMockDevice:
    """Base of the serial mocks; subclasses call :meth:`_start_firmware` last in
    ``__init__`` and implement :meth:`_run`."""

    _port: PtyPort

    def _start_firmware(self, thread_name: str) -> None:
        self._stop = threading.Event()
        self._unplug = threading.Event()
        self._thread = threading.Thread(target=self._run, name=thread_name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        raise NotImplementedError

    @property
    def path(self) -> str:
        """The serial port to give the driver."""
        return self._port.path

    def unplug(self) -> None:
        """Pull the cable: the driver's port goes away mid-run (returns once it has)."""
        self._unplug.set()
        deadline = time.monotonic() + 1.0
        while not self._port.closed and time.monotonic() < deadline:
            time.sleep(0.005)

    def shutdown(self) -> None:
        """Stop the firmware and close the port (idempotent)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        self._port.close()

    def __enter__(self) -> SerialMockDevice:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.shutdown()
