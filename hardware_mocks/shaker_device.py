"""Simulated SG-1 shaker signal generator and amplifier: SCPI on a pseudo-terminal.

Commands (LF-terminated; queries answer one LF-terminated line)::

    *IDN?  *RST  *CLS
    SOUR:FUNC RAND|BRAN|CHIRP|SIN     SOUR:FUNC?
    SOUR:FREQ <Hz>                    (sine)
    SOUR:FREQ:STAR <Hz>  SOUR:FREQ:STOP <Hz>   (random band, chirp sweep)
    SOUR:PER <s>  SOUR:BURS:DCYC <0..1>        (chirp and burst period, burst duty)
    SOUR:VOLT <V>                     SOUR:VOLT?   (V RMS random, V peak sine/chirp)
    OUTP ON|OFF                       OUTP?        (1 while on or ramping up)
    OUTP:RAMP <s>                     OUTP:LEV?    (ramp time; present output level)
    SYST:ERR?                         -> <code>,"<text>"   (0,"No error" when empty)
    SYST:HEART:TIM <s>                (watchdog; 0 disables)
    SYST:HEART                        (heartbeat, no reply)

The output ramps linearly to the level over the ramp time and back to 0 when
turned off. It goes off by itself on any command error, when heartbeats stop
for longer than the watchdog time, when the host closes the port, and on an
amplifier fault; each of these leaves an error in the queue.

Given a :class:`~hardware_mocks.physics.BenchPhysics`, the shaker is a force
source on the bench: attached to an excitation DOF (:meth:`ShakerDevice.attach`),
it pushes with ``force_per_volt`` times its output voltage, which the front end
mock turns into accelerations and shows on its force input. The output is
``level_now`` (the ramped level) times a unit waveform of the time since the
device was made: random and burst random are a random-phase multisine with a flat
spectrum over ``[f_start, f_stop]`` (at most 4096 lines, period at least 16 s,
unit RMS; the burst gates it on for ``duty * period`` of every ``period``), chirp a
linear sweep from ``f_start`` to ``f_stop`` every ``period`` (unit peak), sine unit
peak at ``frequency``.

Example
-------
>>> with ShakerDevice() as dev:  # doctest: +SKIP
...     print(dev.path)  # open with drivers.shaker_scpi.ScpiShaker
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.bench_drive import BenchDrive
from hardware_mocks.physics import BenchPhysics
from hardware_mocks.pty_port import PtyPort
from hardware_mocks.serial_device import SerialMockDevice

__all__ = ["ShakerDevice", "ShakerFaults", "bench_shakers", "shaker_name"]

ERRORS = {
    -100: "Command error",
    -113: "Undefined header",
    -222: "Data out of range",
    -224: "Illegal parameter value",
    -350: "Queue overflow",
    101: "Heartbeat lost; output off",
    102: "Host disconnected; output off",
    103: "Amplifier fault; output off",
}
FUNCTIONS = ("RAND", "BRAN", "CHIRP", "SIN")


@dataclass
class ShakerFaults:
    """Faults the mock can inject. ``silent``: stop answering (output keeps its state)."""

    silent: bool = False


class ShakerDevice(BenchDrive, SerialMockDevice):
    """The generator/amplifier as seen from its serial port.

    Parameters
    ----------
    physics : BenchPhysics, optional
        The bench to drive; without it the shaker drives nothing.
    max_level : float
        Highest level the amplifier accepts, V.
    serial_number : str
    exc : int, optional
        Excitation DOF index it is attached to at first (None: detached).
    force_per_volt : float
        Force on the structure per volt of output, N/V (amplifier and shaker).
    seed : int
        Seed of the random waveform's phases (two shakers driven at once: two seeds).
    sensor : int
        Its force sensor: the front-end input wired to
        :func:`~hardware_mocks.frontend_device.shaker_force` of it shows this shaker's
        force alone.
    t_origin : float, optional
        Time origin of its waveforms on ``time.monotonic()``, s (default: now). Shakers
        given one origin start their periods and bursts together.
    """

    def __init__(self, physics: BenchPhysics | None = None, *, max_level: float = 2.0,
                 serial_number: str = "0007", exc: int | None = None,
                 force_per_volt: float = 50.0, seed: int = 0, sensor: int = 0,
                 t_origin: float | None = None) -> None:
        BenchDrive.__init__(self, physics, force_per_volt, seed, sensor)
        self.max_level = max_level
        self.serial_number = serial_number
        self._t_origin = time.monotonic() if t_origin is None else t_origin
        self.faults = ShakerFaults()
        self.commands: list[str] = []
        self.heartbeats = 0
        self._port = PtyPort()
        self._errors: deque[int] = deque()
        self._rx = bytearray()
        self._lock = threading.Lock()
        self._reset()
        self._last_update = time.monotonic()
        self._start_firmware("mock-shaker")
        if exc is not None:
            self.attach(exc)

    def _reset(self) -> None:
        self.function = "SIN"
        self.frequency = 100.0
        self.f_start = 5.0
        self.f_stop = 200.0
        self.period = 1.0
        self.duty = 0.5
        self.level = 0.0
        self.ramp = 1.0
        self.output = False
        self.level_now = 0.0
        self._rest_until = time.monotonic()  # the last instant seen with the output at 0
        self.watchdog = 0.0
        self._last_heartbeat = time.monotonic()

    @property
    def errors(self) -> list[int]:
        """Codes waiting in the error queue."""
        with self._lock:
            return list(self._errors)

    # -- the shaker on the bench ----------------------------------------------------------------
    def force(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Force on the structure (N) at host instants ``t`` (s, ``time.monotonic()``).

        The ramp is extrapolated from the device's present state, so a change of
        output (on, off, level) shows in forces asked for after it. Before the last
        instant the device saw its output at rest the force is 0: a front end started
        just before the output came on asks for its past (one impulse response long).
        """
        t = np.asarray(t, dtype=float)
        with self._lock:
            target = self.level if self.output else 0.0
            now_level, t_upd, rest = self.level_now, self._last_update, self._rest_until
            rate = max(self.level, self.level_now) / self.ramp if self.ramp > 0 else np.inf
            func, f_sine = self.function, self.frequency
            f0, f1, period, duty = self.f_start, self.f_stop, self.period, self.duty
        if np.isfinite(rate):
            step = np.minimum(rate * np.maximum(t - t_upd, 0.0), abs(target - now_level))
            env = now_level + np.sign(target - now_level) * step
        else:  # no ramp: the level changes at once
            env = np.full_like(t, target)
        # the wave only where the output is on: a multisine costs its 4096 lines a sample
        on = np.flatnonzero((env != 0) & (t >= rest))
        out = np.zeros_like(t)
        if on.size == 0:
            return out
        tau = t[on] - self._t_origin
        if func == "SIN":
            wave = np.sin(2 * np.pi * f_sine * tau)
        elif func == "CHIRP":
            u = np.mod(tau, period)
            wave = np.sin(2 * np.pi * (f0 * u + (f1 - f0) * u**2 / (2 * period)))
        else:
            wave = self.multisine(tau, f0, f1)
            if func == "BRAN":
                wave = wave * (np.mod(tau, period) < duty * period)
        out[on] = self.force_per_volt * env[on] * wave
        return out

    def amplifier_fault(self) -> None:
        """Trip the amplifier: output off, error 103 queued."""
        with self._lock:
            self._fail(103)

    def shutdown(self) -> None:
        self.detach_from_bench()
        SerialMockDevice.shutdown(self)

    def __enter__(self) -> ShakerDevice:
        return self

    # -- firmware ---------------------------------------------------------------------------------
    def _fail(self, code: int) -> None:
        if len(self._errors) >= 10:
            self._errors[-1] = -350
        else:
            self._errors.append(code)
        self.output = False  # any error turns the output off (it ramps down)

    def _update_ramp(self) -> None:
        now = time.monotonic()
        dt, self._last_update = now - self._last_update, now
        target = self.level if self.output else 0.0
        step = (self.level / self.ramp * dt) if self.ramp > 0 else float("inf")
        if self.level_now < target:
            self.level_now = min(target, self.level_now + max(step, 1e-9))
        elif self.level_now > target:
            down = (self.level_now / self.ramp * dt) if self.ramp > 0 else float("inf")
            self.level_now = max(target, self.level_now - max(step, down, 1e-9))
        if self.level_now == 0.0:
            self._rest_until = now

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._unplug.is_set() and not self._port.closed:
                self._port.close()
            data = self._port.read(0.005) if not self._port.closed else b""
            with self._lock:
                if self._port.closed or self._port.hung_up:
                    if self.output:
                        self._fail(102)
                    if self._port.hung_up:
                        time.sleep(0.005)
                elif not self.faults.silent:
                    self._rx += data
                    while b"\n" in self._rx:
                        line, _, rest = self._rx.partition(b"\n")
                        self._rx = bytearray(rest)
                        self._command(line.decode("ascii", "replace").strip())
                if (self.watchdog > 0 and self.output
                        and time.monotonic() - self._last_heartbeat > self.watchdog):
                    self._fail(101)
                self._update_ramp()
            if self._port.closed:
                time.sleep(0.005)

    def _reply(self, text: str) -> None:
        self._port.write(text.encode("ascii") + b"\n")

    def _command(self, cmd: str) -> None:
        if not cmd:
            return
        self.commands.append(cmd)
        head, _, arg = cmd.partition(" ")
        head = head.upper()
        arg = arg.strip()
        if head == "SYST:HEART":
            self.heartbeats += 1
            self._last_heartbeat = time.monotonic()
        elif head == "*IDN?":
            self._reply(f"INSITU,SG-1,{self.serial_number},2.1")
        elif head == "*RST":
            self._reset()
        elif head == "*CLS":
            self._errors.clear()
        elif head == "SYST:ERR?":
            code = self._errors.popleft() if self._errors else 0
            self._reply(f'{code},"{ERRORS.get(code, "No error")}"')
        elif head == "SOUR:FUNC":
            if arg.upper() in FUNCTIONS:
                self.function = arg.upper()
            else:
                self._fail(-224)
        elif head == "SOUR:FUNC?":
            self._reply(self.function)
        elif head == "SOUR:VOLT?":
            self._reply(f"{self.level:.6g}")
        elif head == "OUTP?":
            self._reply("1" if self.output else "0")
        elif head == "OUTP:LEV?":
            self._reply(f"{self.level_now:.6g}")
        elif head == "OUTP":
            if arg.upper() in ("ON", "1"):
                self.output = True
                self._last_heartbeat = time.monotonic()
            elif arg.upper() in ("OFF", "0"):
                self.output = False
            else:
                self._fail(-224)
        else:
            self._setting(head, arg)

    def _setting(self, head: str, arg: str) -> None:
        limits = {
            "SOUR:FREQ": ("frequency", 0.1, 20000.0),
            "SOUR:FREQ:STAR": ("f_start", 0.0, 20000.0),
            "SOUR:FREQ:STOP": ("f_stop", 0.1, 20000.0),
            "SOUR:PER": ("period", 0.01, 100.0),
            "SOUR:BURS:DCYC": ("duty", 0.0, 1.0),
            "SOUR:VOLT": ("level", 0.0, self.max_level),
            "OUTP:RAMP": ("ramp", 0.0, 60.0),
            "SYST:HEART:TIM": ("watchdog", 0.0, 60.0),
        }
        if head not in limits:
            self._fail(-113)
            return
        attr, low, high = limits[head]
        value = self._number(arg, low, high)
        if value is not None:
            setattr(self, attr, value)
            if attr == "watchdog":
                self._last_heartbeat = time.monotonic()


def shaker_name(k: int) -> str:
    """Station device name of a mock bench's shaker ``k`` (from 0): ``shaker``, ``shaker2``..."""
    return "shaker" if k == 0 else f"shaker{k + 1}"


def bench_shakers(physics: BenchPhysics, n: int, *, force_per_volt: float = 50.0
                  ) -> list[ShakerDevice]:
    """The ``n`` SG-1 mocks of one bench, as one generator with ``n`` channels.

    Shaker ``k`` (from 0) has seed ``k`` (its own random signal), force sensor ``k``
    (:func:`~hardware_mocks.frontend_device.shaker_force`) and serial number
    ``0007 + k``; all share one time origin (their bursts start together). A shaker
    that fails to start shuts down those already started.

    Parameters
    ----------
    physics : BenchPhysics
        The bench they push on.
    n : int
        Number of shakers, at least 1.
    force_per_volt : float
        Force of each per volt of output, N/V.
    """
    if n < 1:
        raise ValueError(f"a bench has at least one shaker, not {n}")
    origin = time.monotonic()
    out: list[ShakerDevice] = []
    try:
        for k in range(n):
            out.append(ShakerDevice(physics, force_per_volt=force_per_volt, seed=k, sensor=k,
                                    serial_number=f"{7 + k:04d}", t_origin=origin))
    except BaseException:
        for dev in out:
            dev.shutdown()
        raise
    return out
