"""A station whose vendor APIs are simulated: its ``[simulation]`` table made into a bench.

A station file with ``[simulation] bench = "engine-rigid"`` runs its real drivers on
simulated vendor APIs (:mod:`hardware_mocks`) driven by that built-in bench's physics.
:class:`SimulatedStation` builds the bench (:class:`~hardware_mocks.physics.BenchPhysics`),
one fake API per device, handed to the driver at its boundary as keyword overrides of
``from_config`` (the procedures' ``device_options``), and the simulated operator who hits
where the run asks (:class:`~hardware_mocks.operator.MockOperator` on the physics), or who
moves the simulated shaker (a ``generator-visa`` device: a simulated Keysight 33500 and its
amplifier; a ``shaker-nidaqmx`` device: an amplifier on a simulated NI 9263 output) to each
point a shaker plan names. Every NI-DAQmx device of a station is in one simulated NI-DAQmx
system, as the modules of one chassis are.

The ``[simulation]`` table (besides ``bench``; every key optional):

=====================  =================================================================
key                    meaning
=====================  =================================================================
accel_noise            accelerometer noise, m/s^2 RMS (default 0)
force_noise            force sensor noise, N RMS (default 0)
settle                 least time between two hits, s (the operator's; default 0)
nidaqmx_driver         false: the NI-DAQmx driver is missing (``Task()`` raises
                       ``DaqNotFoundError``)
nidaqmx_modules        the module names NI-DAQmx sees (default: the station's)
nidaqmx_rates          ``"NI 9234"``: the modules run 51.2 kHz / n only (default: any rate)
remove_module          ``{ module = "cDAQ1Mod2", hit = 2, seconds = 1.0 }``: that module is
                       pulled out ``seconds`` after the ``hit``-th hit; ``point = 2`` in
                       place of ``hit``: after the shaker is attached at its 2nd point
=====================  =================================================================

Example
-------
>>> with SimulatedStation(load_station("docs/ni_station.toml")) as sim:  # doctest: +SKIP
...     proc = HammerProcedure(plan, sim.station, "run.h5", listeners=[sim.operator],
...                            device_options=sim.device_options)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any

import numpy as np

from drivers.station import DeviceConfig, NiDaqTransportConfig, StationConfig
from hardware_mocks.benches import BENCHES, get_bench
from hardware_mocks.generator_33500 import Generator33500
from hardware_mocks.input_signals import FORCE
from hardware_mocks.nidaqmx_ao import AmplifiedShaker
from hardware_mocks.nidaqmx_sim import NI9234_RATES, SimModule, SimulatedNiDaqmx
from hardware_mocks.operator import MockOperator, MockShakerOperator
from hardware_mocks.physics import REPLY_TIMEOUT, STALL_TIMEOUT, TIMING_SCATTER, BenchPhysics

__all__ = ["SIMULATED_BACKENDS", "SimulatedStation", "SimulationError"]

#: m/s^2 per g (a simulated accelerometer's data sheet gives mV/g)
G0 = 9.80665
#: a station channel measures a bench response DOF when their directions are this close (cos)
SAME_DIRECTION = 0.999
#: the simulated shaker's force per volt of its generator's output, N/V (the built-in benches')
SHAKER_FORCE_PER_VOLT = 50.0
_KEYS = {"bench", "accel_noise", "force_noise", "settle", "nidaqmx_driver", "nidaqmx_modules",
         "nidaqmx_rates", "remove_module"}


class SimulationError(ValueError):
    """The station's ``[simulation]`` cannot be built; one line naming the key."""


def _wiring_code(sim: SimulatedStation, dev: DeviceConfig, i: int) -> int | None:
    """The bench input a station channel is wired to: a response DOF by node and direction,
    the force for a force channel, None (open) for a channel the bench has no DOF for."""
    ch = dev.channels[i]
    if ch.quantity == "force":
        return FORCE
    b = sim.physics.bench
    if ch.node is None or ch.direction is None:
        return None
    cand = np.flatnonzero(b.resp_nodes == ch.node)
    if cand.size == 0:
        return None
    j = int(cand[np.argmax(b.resp_dirs[cand] @ np.asarray(ch.direction))])
    return j if float(b.resp_dirs[j] @ np.asarray(ch.direction)) >= SAME_DIRECTION else None


def simulated_nidaqmx(sim: SimulatedStation, dev: DeviceConfig) -> dict[str, Any]:
    """The fake nidaqmx of a ``frontend-nidaqmx`` device: its modules wired to the bench."""
    assert isinstance(dev.transport, NiDaqTransportConfig)
    table = sim.table
    per = int(dev.options.get("channels_per_module", 4))
    names = table.get("nidaqmx_modules", list(dev.transport.devices))
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise sim.fail("nidaqmx_modules", f"must be a list of module names, got {names!r}")
    rates = table.get("nidaqmx_rates")
    if rates not in (None, "NI 9234"):
        raise sim.fail("nidaqmx_rates", f"must be \"NI 9234\", got {rates!r}")
    teds = dev.options.get("teds", False)
    teds_names = {c.name for c in dev.channels} if teds is True else set(teds or ())
    wiring: dict[str, int] = {}
    sensors: dict[str, float] = {}
    teds_by_module: dict[str, dict[int, float]] = {n: {} for n in names}
    for i, ch in enumerate(dev.channels):
        module, ai = divmod(ch.input, per)
        if module >= len(dev.transport.devices):
            continue  # the driver refuses the station in one line
        phys = f"{dev.transport.devices[module]}/ai{ai}"
        code = _wiring_code(sim, dev, i)
        # the sensor's own data sheet: mV/g for an accelerometer, mV/N for a force sensor
        native = ch.sensitivity * G0 if ch.quantity == "acceleration" else ch.sensitivity
        if code is not None:
            wiring[phys], sensors[phys] = code, native
        if ch.name in teds_names and dev.transport.devices[module] in teds_by_module:
            teds_by_module[dev.transport.devices[module]][ai] = native
    modules = [SimModule(n, n_inputs=per, rates=NI9234_RATES if rates else None,
                         teds=teds_by_module[n]) for n in names]
    api = nidaqmx_system(sim)
    api.add(modules, wiring=wiring, sensors=sensors)
    return {"api": api, "stall_timeout": STALL_TIMEOUT, "timing_scatter": TIMING_SCATTER}


def nidaqmx_system(sim: SimulatedStation) -> SimulatedNiDaqmx:
    """The station's simulated NI-DAQmx (one for all its NI-DAQmx devices, as one chassis),
    made by the first device that needs it; each device adds its modules."""
    if sim.nidaqmx is None:
        driver = sim.table.get("nidaqmx_driver", True)
        if not isinstance(driver, bool):
            raise sim.fail("nidaqmx_driver", f"must be true or false, got {driver!r}")
        sim.nidaqmx = SimulatedNiDaqmx(sim.physics, [], wiring={}, sensors={},
                                       accel_noise=sim.accel_noise,
                                       force_noise=sim.force_noise, tail=4.0,
                                       driver_installed=driver)
        sim.apis.append(sim.nidaqmx)
    return sim.nidaqmx


def simulated_ao_shaker(sim: SimulatedStation, dev: DeviceConfig) -> dict[str, Any]:
    """The simulated output module of a ``shaker-nidaqmx`` device (an NI 9263 in the
    station's simulated NI-DAQmx) and the shaker its output drives through an amplifier
    (its force on the front end's force input)."""
    if sim.shaker_operator is not None:
        raise sim.fail("bench", f"devices.{dev.name}: one simulated shaker per station")
    if not (isinstance(dev.transport, NiDaqTransportConfig)
            and len(dev.transport.devices) == 1):
        return {}  # the driver refuses the station in one line
    api = nidaqmx_system(sim)
    module = dev.transport.devices[0]
    api.add([SimModule(module, "NI 9263", n_inputs=0, n_outputs=4, output_range=10.0)],
            wiring={}, sensors={})
    channel = dev.options.get("channel", "ao0")
    try:
        line = api.output_line(f"{module}/{channel}")
    except api.errors.DaqError:
        return {"api": api}  # a channel the module lacks: the driver says so in one line
    shaker = AmplifiedShaker(sim.physics, line, force_per_volt=SHAKER_FORCE_PER_VOLT)
    sim.closers.append(_Closing(shaker))
    sim.shaker_operator = MockShakerOperator(shaker)
    return {"api": api}


def _schedule_removal(sim: SimulatedStation) -> None:
    """``remove_module``: a module of the simulated NI-DAQmx pulled out after a hit or once
    the shaker is at a point."""
    remove = sim.table.get("remove_module")
    if remove is None:
        return
    bad = sim.fail("remove_module", "must be { module = NAME, hit = N >= 1 (or point = N "
                                     f">= 1), seconds = S }}, got {remove!r}")
    if not isinstance(remove, Mapping):
        raise bad
    given = [k for k in ("hit", "point") if k in remove]
    n = remove[given[0]] if len(given) == 1 else None
    seconds = remove.get("seconds", 0.0)
    if (not isinstance(remove.get("module"), str) or isinstance(n, bool)
            or not isinstance(n, int) or n < 1
            or set(remove) - {"module", "hit", "point", "seconds"}
            or isinstance(seconds, bool) or not isinstance(seconds, int | float)):
        raise bad
    api = sim.nidaqmx
    if api is None or remove["module"] not in api.modules:
        have = ", ".join(api.modules) if api is not None else "no NI-DAQmx device"
        raise sim.fail("remove_module", f"no module {remove['module']!r} in {have}")
    if given[0] == "hit":
        def when() -> float | None:
            made = sim.physics.hits()
            return made[n - 1].t0 + float(seconds) if len(made) >= n else None
    else:
        if sim.shaker_operator is None:
            raise sim.fail("remove_module", "point = N needs a simulated shaker in the station")
        shaker = sim.shaker_operator.shaker

        def when() -> float | None:
            at = shaker.attached_at
            return at[n - 1] + float(seconds) if len(at) >= n else None
    api.remove_when = (remove["module"], when)


def simulated_generator(sim: SimulatedStation, dev: DeviceConfig) -> dict[str, Any]:
    """The simulated Keysight 33500 of a ``generator-visa`` device: a function generator on a
    TCP socket of this host driving a shaker on the bench (its force on the front end's
    force input), reached through PyVISA's pyvisa-py as the real one on the LAN; the
    station's resource string is replaced by the socket's."""
    if sim.shaker_operator is not None:
        raise sim.fail("bench", f"devices.{dev.name}: one simulated shaker per station")
    gen = Generator33500(sim.physics, force_per_volt=SHAKER_FORCE_PER_VOLT)
    sim.closers.append(_Closing(gen))
    sim.shaker_operator = MockShakerOperator(gen)
    return {"resource": gen.resource, "backend": "@py", "reply_timeout": REPLY_TIMEOUT}


class _Closing:
    """``close()`` of a mock whose own word for it is ``shutdown()``."""

    def __init__(self, mock: Generator33500 | AmplifiedShaker) -> None:
        self.mock = mock

    def close(self) -> None:
        self.mock.shutdown()


#: The simulated vendor API of each backend, for stations with a ``[simulation]`` table.
#:
#: ``backend name -> factory(sim, device) -> keyword overrides``: ``sim`` is the
#: :class:`SimulatedStation` being built (its ``physics`` is the bench every fake samples
#: or drives, its ``table`` the ``[simulation]`` table, :meth:`SimulatedStation.fail` makes
#: a one-line error naming a key of it), ``device`` the station's
#: :class:`~drivers.station.DeviceConfig`. The factory builds the fake (from
#: :mod:`hardware_mocks`) for that device and returns the keywords the driver's
#: ``from_config`` takes to use it instead of the vendor's package (e.g. ``{"api": fake}``;
#: the procedures pass them as ``device_options``). A fake with something to close appends
#: a ``close()``-able object to ``sim.closers``; a simulated excitation device sets
#: ``sim.shaker_operator`` (a listener that attaches it where the shaker procedure asks,
#: as :class:`~hardware_mocks.operator.MockShakerOperator`). Adding a backend is one entry.
SIMULATED_BACKENDS: dict[str, Callable[[SimulatedStation, DeviceConfig], dict[str, Any]]] = {
    "frontend-nidaqmx": simulated_nidaqmx,
    "generator-visa": simulated_generator,
    "shaker-nidaqmx": simulated_ao_shaker,
}


class SimulatedStation:
    """A station's ``[simulation]``: the bench, a fake API per device, the simulated operator.

    Parameters
    ----------
    station : StationConfig
        With a ``[simulation]`` table.
    operator : mapping, optional
        Keyword arguments of :class:`~hardware_mocks.operator.MockOperator`.

    Attributes
    ----------
    device_options : dict
        Per device name, the keywords that inject its fake API (``device_options`` of the
        procedures).
    operator : MockOperator
        Hits the bench where the hammer procedure asks.
    shaker_operator : object or None
        Moves a simulated shaker where the shaker procedure asks (None: no simulated
        excitation device).
    """

    def __init__(self, station: StationConfig, *,
                 operator: Mapping[str, Any] | None = None) -> None:
        self.station = station
        self.table = dict(station.simulation)
        if extra := sorted(set(self.table) - _KEYS):
            raise self.fail(extra[0], f"unknown key; allowed: {', '.join(sorted(_KEYS))}")
        name = self.table.get("bench")
        if name not in BENCHES:
            raise self.fail("bench", f"{name!r} is not a built-in bench; choose one of "
                                     f"{', '.join(sorted(BENCHES))}")
        self.accel_noise = self._number("accel_noise")
        self.force_noise = self._number("force_noise")
        self.physics = BenchPhysics(get_bench(str(name)))
        self.apis: list[SimulatedNiDaqmx] = []
        #: the station's simulated NI-DAQmx, once a device needs it
        self.nidaqmx: SimulatedNiDaqmx | None = None
        self.closers: list[Any] = []
        self.shaker_operator: Any = None
        self.device_options: dict[str, dict[str, Any]] = {}
        for dev in station.devices.values():
            factory = SIMULATED_BACKENDS.get(dev.backend)
            if factory is None:
                raise SimulationError(
                    f"{station.source}: devices.{dev.name}: backend {dev.backend} has no "
                    f"simulated API (simulated: {', '.join(sorted(SIMULATED_BACKENDS))}): "
                    "remove [simulation] to use the real device")
            self.device_options[dev.name] = factory(self, dev)
        _schedule_removal(self)
        self.operator = MockOperator(self.physics, bench=self.physics.bench,
                                     **{"settle": self._number("settle"), **(operator or {})})

    def fail(self, key: str, message: str) -> SimulationError:
        """A one-line error naming ``simulation.key`` of the station file."""
        return SimulationError(f"{self.station.source}: simulation.{key}: {message}")

    def _number(self, key: str) -> float:
        v = self.table.get(key, 0.0)
        if isinstance(v, bool) or not isinstance(v, int | float) or v < 0:
            raise self.fail(key, f"must be a number >= 0, got {v!r}")
        return float(v)

    def shutdown(self) -> None:
        """Stop hitting and close every fake (idempotent)."""
        self.operator.shutdown()
        for api in self.apis:
            for task in list(api.tasks):
                task.close()
        for closer in self.closers:
            closer.close()
        self.closers.clear()

    def __enter__(self) -> SimulatedStation:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.shutdown()
