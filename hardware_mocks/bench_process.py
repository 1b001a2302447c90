"""A whole simulated bench, meant to run as its own process (``insitu mock-bench``).

:class:`MockBench` starts every mock of one bench on one
:class:`~hardware_mocks.physics.BenchPhysics`: the hammer digitiser on a
pseudo-terminal, each shaker generator on another (one, or two driven at once, each
with its force sensor on its own front-end input), and the accelerometer front end
on a python-can ``virtual`` bus served to other processes by a
:class:`~hardware_mocks.socketcand.SocketcandServer` (classic CAN frames: python-can's
socketcand client has no CAN FD). :meth:`MockBench.station_toml` is the station
file that connects the drivers to it.

An operator acts on the bench through a control channel on 127.0.0.1: one JSON
object per line each way (:mod:`hardware_mocks.bench_control`), its address in the
station file's ``[extra.mock_bench]`` table.

Example
-------
>>> with MockBench("engine") as bench:  # doctest: +SKIP
...     print(bench.station_toml())
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import socket
import threading
from dataclasses import fields
from types import TracebackType
from typing import Any

from hardware_mocks.benches import Bench, get_bench
from hardware_mocks.frontend_device import FrontEndDevice, shaker_force_inputs
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.physics import (
    HEARTBEAT,
    REPLY_TIMEOUT,
    STALL_TIMEOUT,
    TIMING_SCATTER,
    TIP_DURATION,
    TIP_PEAK,
    BenchPhysics,
)
from hardware_mocks.shaker_device import ShakerDevice, bench_shakers, shaker_name
from hardware_mocks.socketcand import SocketcandServer

__all__ = ["MockBench", "response_channel_names"]

logger = logging.getLogger(__name__)

_counter = itertools.count()
#: sensitivities of the simulated transducers: accelerometers mV/(m/s^2), force mV/N
ACCEL_SENSITIVITY = 10.2
FORCE_SENSITIVITY = 2.25


def response_channel_names(bench: Bench) -> list[str]:
    """Station channel names of the bench's response DOFs: ``a{node}{x|y|z}``.

    The triaxial accelerometer at node 1 gives ``a1x``, ``a1y``, ``a1z`` (its own axes, in
    the order of :attr:`Bench.resp_dirs`), as in the built-in plans of
    ``insitu acquire --mock``, so those plans fit this bench's station.
    """
    names: list[str] = []
    seen: dict[int, int] = {}
    for node in bench.resp_nodes.tolist():
        k = seen.get(node, 0)
        seen[node] = k + 1
        names.append(f"a{node}{'xyz'[k] if k < 3 else k}")
    return names


class MockBench:
    """Every mock device of one bench, sharing its physics, plus the operator's control channel.

    Parameters
    ----------
    bench : str
        Name for :func:`hardware_mocks.benches.get_bench`.
    fe_rate, hammer_rate : float
        Sampling rates written into the station file, Hz.
    accel_noise, force_noise : float
        Sensor noise of the front end, m/s^2 and N RMS.
    can_channel : str
        Bus name clients open on the socketcand server.
    shakers : int
        Shakers on the bench (``shaker``, ``shaker2``..., :func:`bench_shakers`). With
        one, front-end input ``n_resp`` (``F``) carries every force (hammer and shaker);
        with more, inputs ``n_resp + k`` (``F1``, ``F2``...) carry shaker ``k``'s force
        sensor alone, for plans that drive them all at once.
    """

    def __init__(self, bench: str = "engine", *, fe_rate: float = 1024.0,
                 hammer_rate: float = 4096.0, accel_noise: float = 0.0,
                 force_noise: float = 0.0, can_channel: str = "can0", shakers: int = 1) -> None:
        self.bench_name = bench
        self.physics = BenchPhysics(get_bench(bench))
        self.fe_rate = fe_rate
        self.hammer_rate = hammer_rate
        self.can_channel = can_channel
        self._virtual = f"mock-bench-{os.getpid()}-{next(_counter)}"
        n_resp = len(self.physics.bench.resp_nodes)
        self.forces = shaker_force_inputs(shakers)  # (channel name, wiring code)
        self.wiring = [*range(n_resp), *(w for _, w in self.forces)]
        if len(self.wiring) > FrontEndDevice.N_INPUTS:
            raise ValueError(f"bench {bench!r} has {n_resp} response DOFs; the front end has "
                             f"{FrontEndDevice.N_INPUTS - len(self.forces)} inputs besides "
                             f"the {len(self.forces)} force inputs")
        self._started: list[Any] = []
        try:
            self.hammer = HammerDevice(self.physics, sensitivity=FORCE_SENSITIVITY)
            self._started.append(self.hammer)
            self.shakers: list[ShakerDevice] = bench_shakers(self.physics, shakers)
            self._started.extend(self.shakers)
            self.shaker = self.shakers[0]
            self.frontend = FrontEndDevice(
                self.physics, channel=self._virtual, wiring=self.wiring,
                sensitivity=[FORCE_SENSITIVITY if w < 0 else ACCEL_SENSITIVITY
                             for w in self.wiring],
                accel_noise=accel_noise, force_noise=force_noise)
            self._started.append(self.frontend)
            self.socketcand = SocketcandServer({can_channel: self._virtual})
            self._started.append(self.socketcand)
            self._control = socket.create_server(("127.0.0.1", 0))
        except BaseException:
            self._stop_devices()
            raise
        self._control.settimeout(0.1)
        self.control_port: int = self._control.getsockname()[1]
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._accept_thread = threading.Thread(target=self._accept, name="mock-bench-control",
                                               daemon=True)
        self._accept_thread.start()

    # -- the station file ----------------------------------------------------------------------
    def station_toml(self) -> str:
        """The station file (TOML) that connects the drivers to this bench."""
        b = self.physics.bench
        lines = [
            f"# mock bench {self.bench_name!r}, process {os.getpid()}: "
            f"operator control at tcp://127.0.0.1:{self.control_port}",
            "# (one JSON object per line: hit, attach-shaker, status, fault)",
            "",
            "[station]",
            f'name = "mock bench {self.bench_name}"',
            "",
            "[extra.mock_bench]",
            f'control = "127.0.0.1:{self.control_port}"',
            f'bench = "{self.bench_name}"',
            f"pid = {os.getpid()}",
            f"shakers = {len(self.shakers)}",
            "",
            "[devices.hammer]",
            'backend = "hammer-serial"',
            f"fs = {self.hammer_rate:g}",
            f'transport = {{ url = "{self.hammer.path}", baudrate = 921600 }}',
            f"options = {{ stall_timeout = {STALL_TIMEOUT:g}, reply_timeout = {REPLY_TIMEOUT:g}, "
            f"timing_scatter = {TIMING_SCATTER:g} }}",
            "",
            "[[devices.hammer.channels]]",
            'name = "hammer"',
            "input = 0",
            'quantity = "force"',
            f"sensitivity = {FORCE_SENSITIVITY}",
            "range = 5.0",
            "",
        ]
        for k, dev in enumerate(self.shakers):
            lines += [f"[devices.{shaker_name(k)}]",
                      'backend = "shaker-scpi"',
                      f'transport = {{ url = "{dev.path}", baudrate = 115200 }}',
                      f"options = {{ heartbeat = {HEARTBEAT:g}, ramp = 1.0, "
                      f"reply_timeout = {REPLY_TIMEOUT:g} }}",
                      ""]
        lines += [
            "[devices.frontend]",
            'backend = "frontend-can"',
            f"fs = {self.fe_rate:g}",
            f'transport = {{ interface = "socketcand", host = "127.0.0.1", '
            f'port = {self.socketcand.port}, channel = "{self.can_channel}", fd = false }}',
            f'options = {{ frame = "classic", stall_timeout = {STALL_TIMEOUT:g}, '
            f"reply_timeout = {REPLY_TIMEOUT:g}, timing_scatter = {TIMING_SCATTER:g} }}"
            "  # python-can's socketcand client has no CAN FD",
        ]
        names = response_channel_names(b)
        force_names = {w: name for name, w in self.forces}
        for i, w in enumerate(self.wiring):
            lines += ["", "[[devices.frontend.channels]]"]
            if w < 0:
                lines += [f'name = "{force_names[w]}"', f"input = {i}", 'quantity = "force"',
                          f"sensitivity = {FORCE_SENSITIVITY}", "range = 5.0"]
            else:
                d = ", ".join(repr(float(x)) for x in b.resp_dirs[w])
                lines += [f'name = "{names[w]}"', f"input = {i}", 'quantity = "acceleration"',
                          f"sensitivity = {ACCEL_SENSITIVITY}", "range = 5.0",
                          f"node = {int(b.resp_nodes[w])}", f"direction = [{d}]"]
        return "\n".join(lines) + "\n"

    # -- operator commands ---------------------------------------------------------------------
    def handle(self, request: dict[str, Any]) -> dict[str, Any]:
        """Carry out one control request; the reply has ``ok`` and, on failure, ``error``."""
        cmd = request.get("cmd")
        try:
            if cmd == "hit":
                double = request.get("double")
                hits = self.physics.hit(
                    int(request.get("exc", 0)), float(request.get("peak", TIP_PEAK)),
                    float(request.get("duration", TIP_DURATION)), float(request.get("delay", 0.05)),
                    None if double is None else (float(double[0]), float(double[1])))
                return {"ok": True, "hits": [{"t0": h.t0, "exc": h.exc, "peak": h.peak,
                                              "duration": h.duration} for h in hits]}
            if cmd == "attach-shaker":
                k = int(request.get("shaker", 1))
                if not 1 <= k <= len(self.shakers):
                    raise ValueError(f"no shaker {k}: the bench has "
                                     + ("one (shaker 1)" if len(self.shakers) == 1 else
                                        f"shakers 1..{len(self.shakers)}"))
                exc = request.get("exc")
                shaker = self.shakers[k - 1]
                shaker.attach(None if exc is None else int(exc))
                return {"ok": True, "shaker": k, "exc": shaker.exc}
            if cmd == "status":
                shakers = [{"exc": s.exc, "output": s.output, "level": s.level_now}
                           for s in self.shakers]
                return {"ok": True, "bench": self.bench_name, "hits": len(self.physics.hits()),
                        "shaker": shakers[0], "shakers": shakers,
                        "frontend": {"running": self.frontend.running,
                                     "frames_sent": self.frontend.frames_sent},
                        "hammer": {"streaming": self.hammer.streaming,
                                   "frames_sent": self.hammer.frames_sent}}
            if cmd == "fault":
                return self._fault(request)
        except (TypeError, ValueError, KeyError, IndexError) as err:
            return {"ok": False, "error": f"{cmd}: {err}"}
        return {"ok": False, "error": f"unknown command {cmd!r}; use hit, attach-shaker, "
                                      f"status or fault"}

    def _fault(self, request: dict[str, Any]) -> dict[str, Any]:
        devices: dict[str, Any] = {"hammer": self.hammer.faults,
                                   **{shaker_name(k): s.faults
                                      for k, s in enumerate(self.shakers)},
                                   "frontend": self.frontend.faults}
        name = request.get("device")
        if not isinstance(name, str) or name not in devices:
            return {"ok": False, "error": f"fault: device must be one of {', '.join(devices)}"}
        faults = devices[name]
        allowed = {f.name: f.type for f in fields(faults)}
        key = request.get("name")
        if key not in allowed:
            return {"ok": False, "error": f"fault: {name} faults are {', '.join(allowed)}"}
        value: Any = request.get("value")
        current = getattr(faults, key)
        if isinstance(current, bool):
            value = bool(value)
        elif isinstance(current, int):
            value = int(value)
        elif isinstance(current, bytes):
            value = str(value).encode("latin-1")
        setattr(faults, key, value)
        return {"ok": True}

    # -- control channel -----------------------------------------------------------------------
    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._control.accept()
            except TimeoutError:
                continue
            except OSError:
                break
            t = threading.Thread(target=self._serve, args=(conn,), name="mock-bench-client",
                                 daemon=True)
            self._threads = [x for x in self._threads if x.is_alive()] + [t]
            t.start()

    def _serve(self, conn: socket.socket) -> None:
        conn.settimeout(0.1)
        buf = b""
        with conn:
            while not self._stop.is_set():
                try:
                    chunk = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not chunk:
                    return
                buf += chunk
                while b"\n" in buf:
                    line, _, buf = buf.partition(b"\n")
                    if not line.strip():
                        continue
                    try:
                        request = json.loads(line)
                        if not isinstance(request, dict):
                            raise ValueError("a request is a JSON object")
                    except ValueError as err:
                        reply: dict[str, Any] = {"ok": False, "error": f"bad request: {err}"}
                    else:
                        reply = self.handle(request)
                    try:
                        conn.sendall(json.dumps(reply).encode() + b"\n")
                    except OSError:
                        return

    # -- life cycle ----------------------------------------------------------------------------
    def _stop_devices(self) -> None:
        for dev in reversed(self._started):
            try:
                dev.shutdown()
            except OSError as err:
                logger.warning("mock bench: %s did not shut down cleanly: %s",
                               type(dev).__name__, err)
        self._started.clear()

    def shutdown(self) -> None:
        """Stop the control channel and every device; idempotent."""
        if not hasattr(self, "_stop") or self._stop.is_set():
            self._stop_devices()
            return
        self._stop.set()
        self._accept_thread.join(1.0)
        self._control.close()
        for t in self._threads:
            t.join(1.0)
        self._stop_devices()

    def __enter__(self) -> MockBench:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.shutdown()
