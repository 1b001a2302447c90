"""Built-in plans derived from the simulated benches, and an in-process mock bench.

:func:`plan_for_bench` gives the test plan of a built-in bench (the article's
engine: 4 triaxial points, 18 forces; the block: 4 points, 9 forces).
:class:`InProcessBench` starts the simulated front end (python-can ``virtual``
bus), hammer digitiser and shaker (pseudo-terminals; or a function generator on a TCP
socket) on one shared physics, and
gives the station that connects the real drivers to them, with a simulated
operator for each procedure (``operator`` hits, ``shaker_operator`` moves the shaker).

Example
-------
>>> with InProcessBench("engine-rigid") as bench:  # doctest: +SKIP
...     proc = HammerProcedure(plan_for_bench("engine-rigid"), bench.station, "run.h5",
...                            listeners=[bench.operator])
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import Any

import numpy as np

from app.acquire.plan import TestPlan, parse_plan
from drivers.station import StationConfig, parse_station
from hardware_mocks.bench_drive import BenchDrive
from hardware_mocks.benches import Bench, get_bench
from hardware_mocks.frontend_device import FrontEndDevice, shaker_force_inputs
from hardware_mocks.generator_33500 import Generator33500
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.operator import MockOperator, MockShakerOperator
from hardware_mocks.physics import (
    HEARTBEAT,
    REPLY_TIMEOUT,
    STALL_TIMEOUT,
    TIMING_SCATTER,
    BenchPhysics,
)
from hardware_mocks.shaker_device import ShakerDevice, bench_shakers, shaker_name

__all__ = ["InProcessBench", "plan_for_bench"]

_AXES = "xyz"
_counter = itertools.count()


def _channel_names(bench: Bench) -> list[str]:
    names: list[str] = []
    seen: dict[int, int] = {}
    for node in bench.resp_nodes.tolist():
        k = seen.get(node, 0)
        seen[node] = k + 1
        names.append(f"a{node}{_AXES[k] if k < 3 else k}")
    return names


def plan_for_bench(name: str, *, points: Sequence[int] | None = None, hits: int = 1,
                   fs: float = 1024.0, length: float = 2.0, pretrigger: float = 0.05,
                   trigger_level: float = 20.0, exp_tau: float = 0.0, method: str = "hammer",
                   shaker: Mapping[str, Any] | None = None) -> TestPlan:
    """The hammer (or shaker) plan of built-in bench ``name`` (engine, engine-rigid, block, ...).

    ``points`` selects excitation indices (default all); record settings as in
    :class:`~app.acquire.plan.RecordSettings` (Hz, s, N). ``method="shaker"`` makes a
    shaker plan with the ``[shaker]`` keys given in ``shaker``
    (:class:`~app.acquire.plan.ShakerSettings`; its blocks set the record length).
    """
    bench = get_bench(name)
    g = bench.geometry
    sel = range(len(bench.exc_nodes)) if points is None else points
    exc_xyz = g.coordinates(bench.exc_nodes)
    names = _channel_names(bench)
    responses = []
    for node in dict.fromkeys(bench.resp_nodes.tolist()):
        chans = [n for n, r in zip(names, bench.resp_nodes.tolist(), strict=True) if r == node]
        responses.append({"node": node, "xyz": g.coordinates(np.array([node]))[0].tolist(),
                          "channels": chans})
    record: dict[str, Any] = {"fs": fs, "pretrigger": pretrigger,
                              "trigger_level": trigger_level, "exp_tau": exp_tau}
    if method != "shaker":
        record["length"] = length
    return parse_plan({
        "plan": {"name": f"{name} (built in)", "method": method, "hits": hits},
        "record": record,
        "shaker": dict(shaker or {}),
        "excitation": [{"node": int(bench.exc_nodes[j]), "xyz": exc_xyz[j].tolist(),
                        "direction": bench.exc_dirs[j].tolist()} for j in sel],
        "response": responses,
    }, f"built-in plan {name}")


#: the shaker generators an in-process bench can have (:class:`InProcessBench` ``generator``)
GENERATORS = ("sg-1", "33500")


def _shaker_entry(dev: BenchDrive) -> dict[str, Any]:
    """The station entry of a mock shaker generator (its drivers get the mocks' patience)."""
    if isinstance(dev, Generator33500):
        return {"backend": "generator-visa",
                "transport": {"visa": dev.resource, "backend": "@py"},
                "options": {"reply_timeout": REPLY_TIMEOUT}}
    assert isinstance(dev, ShakerDevice)
    return {"backend": "shaker-scpi", "transport": {"url": dev.path, "baudrate": 115200},
            "options": {"reply_timeout": REPLY_TIMEOUT, "heartbeat": HEARTBEAT}}


class InProcessBench:
    """Simulated front end + hammer on one bench, in this process, and their station.

    Parameters
    ----------
    name : str
        Built-in bench.
    fs_frontend, fs_hammer : float
        Sample rates, Hz.
    accel_noise, force_noise : float
        Sensor noise, m/s^2 and N RMS.
    hammer_ppm, hammer_offset : float
        The hammer digitiser's clock error (ppm) and start delay (s).
    operator : dict
        Keyword arguments of :class:`~hardware_mocks.operator.MockOperator`.
    fe_force : bool
        Wire the force to front-end input ``n_resp`` (channel ``F_fe``): the hammer's
        and the shaker's force sensor. False leaves the hammer's digitiser as the only
        force channel.
    force_per_volt : float
        The shaker's force per volt of output, N/V.
    shakers : int
        Shakers on the bench (``shaker``, ``shaker2``...), each with its own random
        signal (seed) and its force sensor on its own front-end input (``F1_fe``,
        ``F2_fe``...; with more than one, these replace ``F_fe``); their generators
        share one time origin (bursts start together, as one generator's channels).
    generator : {"sg-1", "33500"}
        What drives the shaker's amplifier: the SG-1 generator/amplifier on a
        pseudo-terminal (backend ``shaker-scpi``), or a simulated Keysight 33500 function
        generator on a TCP socket, reached through PyVISA's pyvisa-py backend (backend
        ``generator-visa``, resource ``TCPIP0::127.0.0.1::PORT::SOCKET``; one shaker).
    """

    def __init__(self, name: str = "engine", *, fs_frontend: float = 1024.0,
                 fs_hammer: float = 4096.0, accel_noise: float = 0.0, force_noise: float = 0.0,
                 hammer_ppm: float = 0.0, hammer_offset: float = 0.0,
                 operator: dict[str, Any] | None = None, fe_force: bool = True,
                 force_per_volt: float = 50.0, shakers: int = 1,
                 generator: str = "sg-1") -> None:
        if generator not in GENERATORS or (generator == "33500" and shakers != 1):
            raise ValueError(f"generator {generator!r} with {shakers} shakers: choose "
                             "sg-1 (1 or more shakers) or 33500 (one shaker)")
        self.bench = get_bench(name)
        self.physics = BenchPhysics(self.bench)
        n_resp = len(self.bench.resp_nodes)
        channel = f"insitu-inproc-{next(_counter)}"
        forces = shaker_force_inputs(shakers, "_fe") if fe_force else []
        self.frontend = FrontEndDevice(self.physics, channel=channel,
                                       wiring=[*range(n_resp), *(w for _, w in forces)],
                                       accel_noise=accel_noise, force_noise=force_noise,
                                       tail=4.0)
        self.hammer = HammerDevice(self.physics, ppm=hammer_ppm, offset=hammer_offset,
                                   noise=force_noise)
        self.shakers: list[BenchDrive] = (
            [Generator33500(self.physics, force_per_volt=force_per_volt)]
            if generator == "33500"
            else list(bench_shakers(self.physics, shakers, force_per_volt=force_per_volt)))
        self.shaker = self.shakers[0]
        dirs = self.bench.resp_dirs
        chans = [{"name": n, "input": i, "quantity": "acceleration", "sensitivity": 10.2,
                  "range": 10.0, "node": int(node), "direction": dirs[i].tolist()}
                 for i, (n, node) in enumerate(zip(_channel_names(self.bench),
                                                   self.bench.resp_nodes.tolist(), strict=True))]
        for k, (force, _) in enumerate(forces):
            chans.append({"name": force, "input": n_resp + k, "quantity": "force",
                          "sensitivity": 2.25, "range": 5.0})
        patient = {"stall_timeout": STALL_TIMEOUT, "reply_timeout": REPLY_TIMEOUT,
                   "timing_scatter": TIMING_SCATTER}
        shaker_devices = {shaker_name(k): _shaker_entry(dev)
                          for k, dev in enumerate(self.shakers)}
        self.station: StationConfig = parse_station({
            "station": {"name": f"in-process mock bench ({name})"},
            "devices": {
                "frontend": {"backend": "frontend-can", "fs": fs_frontend,
                             "transport": {"interface": "virtual", "channel": channel,
                                           "fd": True},
                             "options": patient, "channels": chans},
                "hammer": {"backend": "hammer-serial", "fs": fs_hammer,
                           "transport": {"url": self.hammer.path, "baudrate": 921600},
                           "options": patient,
                           "channels": [{"name": "F", "input": 0, "quantity": "force",
                                         "sensitivity": 2.25, "range": 5.0}]},
                **shaker_devices,
            },
            # a run file keeps it: --resume finds the bench its records came from
            "extra": {"in_process_bench": name}}, "in-process mock station")
        self.operator = MockOperator(self.hammer, **(operator or {}))
        self.shaker_operator = MockShakerOperator(*self.shakers)

    def shutdown(self) -> None:
        self.operator.shutdown()
        for dev in self.shakers:
            dev.shutdown()
        self.hammer.shutdown()
        self.frontend.shutdown()

    def __enter__(self) -> InProcessBench:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.shutdown()
