"""Client of a mock bench's control channel: the operator's hands on a simulated bench.

``insitu mock-bench`` (:class:`hardware_mocks.bench_process.MockBench`) listens on
127.0.0.1 for one JSON object per line and answers each with one line::

    -> {"cmd": "hit", "exc": 3, "peak": 250.0}
    <- {"ok": true, "hits": [{"t0": 5123.4567, "exc": 3, "peak": 250.0, "duration": 0.004}]}
    -> {"cmd": "attach-shaker", "exc": 5}          <- {"ok": true, "exc": 5}
    -> {"cmd": "fault", "device": "hammer", "name": "drop_every", "value": 7}
    -> {"cmd": "status"}
    <- {"ok": false, "error": "hit: excitation index 99 out of range 0..17"}

``t0`` is on the host's ``time.monotonic()`` clock, shared by the processes of one
machine. The address is in the station file's ``[extra.mock_bench]`` table.

Example
-------
>>> with BenchControl.from_station("station.toml") as bench:  # doctest: +SKIP
...     bench.hit(exc=0, peak=200.0)
"""

from __future__ import annotations

import json
import socket
from pathlib import Path
from types import TracebackType
from typing import Any

from drivers.station import load_station

__all__ = ["BenchControl", "BenchControlError"]


class BenchControlError(RuntimeError):
    """The mock bench refused a request or could not be reached (one-line message)."""


class BenchControl:
    """Connection to a mock bench's control channel.

    Parameters
    ----------
    host, port : str, int
        Address of the control channel.
    timeout : float
        Seconds to wait for the connection and for each answer.
    """

    def __init__(self, host: str, port: int, *, timeout: float = 3.0) -> None:
        self.address = f"{host}:{port}"
        self.timeout = timeout
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as err:
            raise BenchControlError(f"mock bench control {self.address}: cannot connect: "
                                    f"{err}") from err
        self._buf = b""

    @classmethod
    def from_station(cls, path: str | Path, *, timeout: float = 3.0) -> BenchControl:
        """Connect to the bench whose station file (``insitu mock-bench``) is ``path``."""
        station = load_station(path)
        control = station.extra.get("mock_bench", {}).get("control")
        if not isinstance(control, str) or ":" not in control:
            raise BenchControlError(f"{path}: no [extra.mock_bench] control address; was it "
                                    f"written by insitu mock-bench?")
        host, _, port = control.rpartition(":")
        return cls(host, int(port), timeout=timeout)

    def request(self, **fields: Any) -> dict[str, Any]:
        """Send one request and return the bench's answer; a refusal raises BenchControlError."""
        try:
            self._sock.sendall(json.dumps(fields).encode() + b"\n")
            while b"\n" not in self._buf:
                chunk = self._sock.recv(65536)
                if not chunk:
                    raise BenchControlError(f"mock bench control {self.address}: connection "
                                            f"closed (bench stopped?)")
                self._buf += chunk
        except TimeoutError as err:
            raise BenchControlError(f"mock bench control {self.address}: no answer within "
                                    f"{self.timeout:g} s") from err
        except OSError as err:
            raise BenchControlError(f"mock bench control {self.address}: {err}") from err
        line, _, self._buf = self._buf.partition(b"\n")
        reply = json.loads(line)
        if not reply.get("ok"):
            raise BenchControlError(f"mock bench: {reply.get('error', 'request refused')}")
        return dict(reply)

    def hit(self, exc: int = 0, peak: float = 200.0, *, duration: float = 0.004,
            delay: float = 0.05, double: tuple[float, float] | None = None
            ) -> list[dict[str, float]]:
        """Hit excitation DOF ``exc`` with ``peak`` N for ``duration`` s, ``delay`` s from now.

        Returns the pulses made (``t0`` on the host's monotonic clock, s).
        """
        req: dict[str, Any] = {"cmd": "hit", "exc": exc, "peak": peak, "duration": duration,
                               "delay": delay}
        if double is not None:
            req["double"] = list(double)
        return list(self.request(**req)["hits"])

    def attach_shaker(self, exc: int | None) -> None:
        """Attach the shaker to excitation DOF ``exc`` (None detaches it)."""
        self.request(cmd="attach-shaker", exc=exc)

    def fault(self, device: str, name: str, value: int | bool | str) -> None:
        """Set fault ``name`` of ``device`` (hammer, shaker, frontend) to ``value``."""
        self.request(cmd="fault", device=device, name=name, value=value)

    def status(self) -> dict[str, Any]:
        return self.request(cmd="status")

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> BenchControl:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
