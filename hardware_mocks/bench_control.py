"""Client of a mock bench's control channel: the operator's hands on a simulated bench.

``insitu mock-bench`` (:class:`hardware_mocks.bench_process.MockBench`) listens on
127.0.0.1 for one JSON object per line and answers each with one line::

    -> {"cmd": "hit", "exc": 3, "peak": 250.0}
    <- {"ok": true, "hits": [{"t0": 5123.4567, "exc": 3, "peak": 250.0, "duration": 0.0025}]}
    -> {"cmd": "attach-shaker", "exc": 5}          <- {"ok": true, "shaker": 1, "exc": 5}
    -> {"cmd": "attach-shaker", "exc": 7, "shaker": 2}   (a bench with two shakers)
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
import threading
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol

__all__ = ["BenchControl", "BenchControlError", "control_address"]


class StationLike(Protocol):
    """What :func:`control_address` reads of a station (a ``drivers.station.StationConfig``
    has both): its ``[extra]`` table and where it comes from."""

    @property
    def extra(self) -> Mapping[str, Any]: ...
    @property
    def source(self) -> str: ...


@dataclass(frozen=True)
class _StationFile:
    """A station file's ``[extra]`` table, read here with :mod:`tomllib` (the mock does not
    use the drivers' station parser)."""

    source: str
    extra: Mapping[str, Any] = field(default_factory=dict)


class BenchControlError(RuntimeError):
    """The mock bench refused a request or could not be reached (one-line message)."""


def control_address(station: StationLike) -> tuple[str, int]:
    """Host and port of the control channel named in a station's ``[extra.mock_bench]`` table.

    Raises :class:`BenchControlError` (one line) when the station has none, as a real
    bench's station file does not.
    """
    table = station.extra.get("mock_bench")
    control = table.get("control") if isinstance(table, Mapping) else None
    host, _, port = control.rpartition(":") if isinstance(control, str) else ("", "", "")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        what = "no" if control is None else f"a bad ({control!r})"
        raise BenchControlError(f"{station.source}: {what} [extra.mock_bench] control address "
                                "(HOST:PORT); only a station written by insitu mock-bench has one")
    return host, int(port)


class BenchControl:
    """Connection to a mock bench's control channel (usable from several threads).

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
            raise BenchControlError(f"mock bench control {self.address}: cannot connect "
                                    f"(is insitu mock-bench running?): "
                                    f"{err.strerror or err}") from err
        self._buf = b""
        self._lock = threading.Lock()  # one request and its answer at a time
        self._dead = ""

    @classmethod
    def from_station(cls, path: str | Path, *, timeout: float = 3.0) -> BenchControl:
        """Connect to the bench whose station file (``insitu mock-bench``) is ``path``."""
        p = Path(path)
        try:
            extra = tomllib.loads(p.read_text(encoding="utf-8")).get("extra", {})
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
            raise BenchControlError(f"{p}: cannot read the station file: {err}") from err
        table = extra if isinstance(extra, Mapping) else {}
        host, port = control_address(_StationFile(str(p), table))
        return cls(host, port, timeout=timeout)

    def request(self, **fields: Any) -> dict[str, Any]:
        """Send one request and return the bench's answer; a refusal raises BenchControlError."""
        with self._lock:
            if self._dead:
                raise BenchControlError(self._dead)
            try:
                self._sock.sendall(json.dumps(fields).encode() + b"\n")
                while b"\n" not in self._buf:
                    chunk = self._sock.recv(65536)
                    if not chunk:
                        raise BenchControlError(f"mock bench control {self.address}: connection "
                                                f"closed (bench stopped?)")
                    self._buf += chunk
            except TimeoutError as err:
                # a late answer would be taken for the next request's: give up the connection
                self._dead = (f"mock bench control {self.address}: no answer within "
                              f"{self.timeout:g} s")
                self._sock.close()
                raise BenchControlError(self._dead) from err
            except OSError as err:
                raise BenchControlError(f"mock bench control {self.address}: "
                                        f"{err.strerror or err}") from err
            line, _, self._buf = self._buf.partition(b"\n")
        try:
            reply = json.loads(line)
        except ValueError as err:
            raise BenchControlError(f"mock bench control {self.address}: not a JSON answer: "
                                    f"{line[:80]!r}") from err
        if not isinstance(reply, dict):
            raise BenchControlError(f"mock bench control {self.address}: not a JSON object: "
                                    f"{line[:80]!r}")
        if not reply.get("ok"):
            raise BenchControlError(f"mock bench: {reply.get('error', 'request refused')}")
        return dict(reply)

    def hit(self, exc: int = 0, peak: float | None = None, *, duration: float | None = None,
            delay: float = 0.05, double: tuple[float, float] | None = None
            ) -> list[dict[str, float]]:
        """Hit excitation DOF ``exc`` with ``peak`` N for ``duration`` s, ``delay`` s from now
        (``peak`` and ``duration`` left out: the bench's own hammer tip,
        :data:`hardware_mocks.physics.TIP_PEAK` and :data:`~hardware_mocks.physics.TIP_DURATION`).

        Returns the pulses made (``t0`` on the host's monotonic clock, s).
        """
        req: dict[str, Any] = {"cmd": "hit", "exc": exc, "delay": delay}
        if peak is not None:
            req["peak"] = peak
        if duration is not None:
            req["duration"] = duration
        if double is not None:
            req["double"] = list(double)
        return list(self.request(**req)["hits"])

    def attach_shaker(self, exc: int | None, shaker: int = 1) -> None:
        """Attach shaker ``shaker`` (from 1) to excitation DOF ``exc`` (None detaches it)."""
        self.request(cmd="attach-shaker", exc=exc, shaker=shaker)

    def fault(self, device: str, name: str, value: int | bool | str) -> None:
        """Set fault ``name`` of ``device`` (hammer, shaker, shaker2, frontend) to ``value``."""
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
