"""Analogue outputs of the simulated NI-DAQmx: an NI 9263 class module driving a shaker.

The output side of :class:`~hardware_mocks.nidaqmx_sim.SimulatedNiDaqmx`, with nidaqmx
1.7's names: ``task.ao_channels.add_ao_voltage_chan``, ``task.out_stream``
(:class:`SimOutStream`: ``regen_mode``, ``total_samp_per_chan_generated``) and
``stream_writers.AnalogSingleChannelWriter`` (``write_many_sample``,
``write_one_sample``). A buffered task regenerates what was written before its start on
its own :class:`~hardware_mocks.physics.DeviceClock`; a write while it runs goes where the
last one ended, sample by sample as soon as the generation has played what was in that
place of the buffer (NI-DAQmx's space available), and returns once all of it is in. A
stopped task leaves the output at the last value generated; with on-demand timing a write
sets the output at once. Each output
is an :class:`OutputLine` whose voltage at any host instant is known (zero-order hold, as a
DAC without a reconstruction filter); :class:`AmplifiedShaker` pushes on the bench with
``force_per_volt`` times it (a :class:`~hardware_mocks.bench_drive.BenchDrive`).

Faults: the module removed (the output drops to 0 V; writes, ``is_task_done`` and ``stop``
raise -201003), a write that finds no room in time (-200292), a write cut short by the
task stopping (-200010), a range beyond the module (-200077). The simulated modules
regenerate only: ``regen_mode = DONT_ALLOW_REGENERATION`` is refused at the start.

Example
-------
>>> ni = SimulatedNiDaqmx(physics, [SimModule("cDAQ1Mod5", "NI 9263", n_inputs=0,
...                       n_outputs=4)], wiring={}, sensors={})  # doctest: +SKIP
>>> shaker = AmplifiedShaker(physics, ni.output_line("cDAQ1Mod5/ao0"))  # doctest: +SKIP
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.bench_drive import BenchDrive
from hardware_mocks.nidaqmx_api import constants, errors
from hardware_mocks.physics import BenchPhysics, DeviceClock

__all__ = ["AmplifiedShaker", "AnalogSingleChannelWriter", "OutputLine",
           "SimAOChannelCollection", "SimOutStream"]

#: how often a blocked write looks again, s
POLL = 0.005


def daq_error(message: str, code: int, task: str = "") -> Exception:
    """nidaqmx's ``DaqError`` (or its stand-in) with NI-DAQmx's ``code``."""
    err: Exception = errors.DaqError(message, code, task_name=task)
    return err


class OutputLine:
    """One analogue output's voltage over host time: its task's generation, else held."""

    def __init__(self, name: str) -> None:
        self.name = name
        #: the voltage while nothing generates, V
        self.held = 0.0
        #: the module was pulled out: 0 V from then on
        self.removed = False
        self.generation: SimOutStream | None = None

    def voltage(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Volts at host instants ``t`` (s, ``time.monotonic()``)."""
        t = np.asarray(t, dtype=float)
        gen = self.generation
        if self.removed:
            return np.zeros_like(t)
        if gen is None:
            return np.full_like(t, self.held)
        return gen.voltage(t, self.held)


class SimAOChannel:
    """An analogue output channel of a task."""

    def __init__(self, name: str, physical_channel: str, line: OutputLine, min_val: float,
                 max_val: float, units: Any) -> None:
        self.name = name
        self.physical_channel = physical_channel
        self.line = line
        self.ao_min = min_val
        self.ao_max = max_val
        self.ao_voltage_units = units


class SimAOChannelCollection:
    """``task.ao_channels``: ``add_ao_voltage_chan`` of nidaqmx 1.7."""

    def __init__(self, task: Any) -> None:
        self._task = task
        self._channels: list[SimAOChannel] = []

    def __len__(self) -> int:
        return len(self._channels)

    def __iter__(self) -> Iterator[SimAOChannel]:
        return iter(self._channels)

    def __getitem__(self, index: int) -> SimAOChannel:
        return self._channels[index]

    def add_ao_voltage_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                            min_val: float = -10.0, max_val: float = 10.0,
                            units: Any = constants.VoltageUnits.VOLTS,
                            custom_scale_name: str = "") -> SimAOChannel:
        task = self._task
        module, _ = task.system.resolve(physical_channel, task.name)
        if task.running:
            raise daq_error("Specified operation cannot be performed while the task is "
                            "running.", -200479, task.name)
        if len(task.ai_channels) or self._channels:
            raise daq_error("The simulated modules take one output channel a task and no "
                            "inputs beside it.", -200559, task.name)
        if max(abs(min_val), abs(max_val)) > module.output_range * (1 + 1e-9):
            raise daq_error(f"Requested value is not a supported value for this property. "
                            f"Property: DAQmx_AO_Max Requested Value: {max_val:g} Maximum "
                            f"Value: {module.output_range:g} Channel Name: "
                            f"{name_to_assign_to_channel or physical_channel}", -200077,
                            task.name)
        if units != constants.VoltageUnits.VOLTS:
            raise daq_error(f"Requested value is not a supported value for this property. "
                            f"Property: DAQmx_AO_Voltage_Units Requested Value: {units}",
                            -200077, task.name)
        chan = SimAOChannel(name_to_assign_to_channel or physical_channel, physical_channel,
                            task.system.output_line(physical_channel), min_val, max_val, units)
        self._channels.append(chan)
        return chan


class SimOutStream:
    """``task.out_stream`` and the generation it runs: the buffer, its clock, the writes.

    The buffer is what was written before the start (its length is the period of the
    regeneration); sample ``k`` of the generation plays place ``k % size`` of it. A write
    fills the places after the last one's, each once the generation has played it, so a
    sample not yet played is always the latest written for it.

    Attributes
    ----------
    writes : list of (int, ndarray)
        Every write since the start: the generation's sample its first value is for, and
        the values.
    """

    def __init__(self, task: Any) -> None:
        self._task = task
        self.regen_mode = constants.RegenerationMode.ALLOW_REGENERATION
        self._lock = threading.Lock()
        self._stopped = threading.Event()
        self._pending: list[NDArray[np.float64]] = []  # written before the start
        self.writes: list[tuple[int, NDArray[np.float64]]] = []
        self._buffer = np.zeros(0)
        self._size = 0
        self._written = 0
        self._clock: DeviceClock | None = None
        self._generated = 0  # frozen at the stop

    @property
    def output_buf_size(self) -> int:
        return self._size or sum(p.size for p in self._pending)

    @property
    def total_samp_per_chan_generated(self) -> int:
        self._task.check_modules()
        clock = self._clock
        return clock.due() if clock is not None else self._generated

    # -- the task's side --------------------------------------------------------------------
    def start(self) -> None:
        task = self._task
        if self.regen_mode != constants.RegenerationMode.ALLOW_REGENERATION:
            raise daq_error("The simulated modules generate with regeneration only "
                            "(out_stream.regen_mode ALLOW_REGENERATION).", -200077, task.name)
        if not self._pending:
            raise daq_error("Generation cannot be started, because the output buffer is "
                            "empty. Write data before starting a buffered generation.",
                            -200462, task.name)
        buf = np.concatenate(self._pending)
        self._pending = []
        clock = DeviceClock(task.timing.samp_clk_rate)
        with self._lock:
            self._size, self._written = buf.size, buf.size
            self._buffer = buf.copy()
            self.writes = [(0, buf)]
            self._stopped.clear()
            clock.start()
            self._clock = clock
        for chan in task.ao_channels:
            chan.line.generation = self

    def stop(self) -> None:
        """Stop generating: the output holds the last sample generated."""
        with self._lock:
            clock, self._clock = self._clock, None
            self._stopped.set()
            if clock is None:
                return
            self._generated = clock.due()
            last = self._buffer[(self._generated - 1) % self._size]
        for chan in self._task.ao_channels:
            chan.line.held = float(last)
            chan.line.generation = None

    def write(self, data: NDArray[np.float64], timeout: float) -> int:
        """A buffered write: before the start into the buffer, while running into its
        place once the generation has left it."""
        task = self._task
        task.check_modules()
        data = np.array(data, dtype=float).reshape(-1)
        chan = task.ao_channels[0]
        if np.any(np.abs(data) > max(abs(chan.ao_min), abs(chan.ao_max)) * (1 + 1e-12)):
            raise daq_error("Attempted writing analog data that is too large or too small. "
                            f"Channel Name: {chan.name}", -200561, task.name)
        if not task.running:
            self._pending.append(data)
            return int(data.size)
        if data.size > self._size:
            raise daq_error(f"The simulated modules take writes of at most the buffer's "
                            f"{self._size} samples while generating.", -200547, task.name)
        deadline = time.monotonic() + timeout
        with self._lock:
            self.writes.append((self._written, data))
        done = 0
        while True:
            with self._lock:
                clock = self._clock
                if clock is None:
                    raise daq_error("Finite acquisition or generation has been stopped before "
                                    "the requested number of samples were acquired or "
                                    "generated.", -200010, task.name)
                room = min(clock.due() + self._size - self._written, data.size - done)
                if room > 0:
                    places = (self._written + np.arange(room)) % self._size
                    self._buffer[places] = data[done:done + room]
                    self._written += room
                    done += room
                if done == data.size:
                    return int(data.size)
            task.check_modules()
            if time.monotonic() > deadline:
                raise daq_error("Some or all of the samples to write could not be written to "
                                "the buffer yet. More space will free up as samples currently "
                                "in the buffer are generated.", -200292, task.name)
            self._stopped.wait(POLL)

    def write_on_demand(self, value: float) -> None:
        task = self._task
        task.check_modules()
        for chan in task.ao_channels:
            chan.line.held = float(value)

    # -- the output -------------------------------------------------------------------------
    def voltage(self, t: NDArray[np.float64], held: float) -> NDArray[np.float64]:
        with self._lock:
            clock = self._clock
            if clock is None:
                return np.full_like(t, held)
            k = np.floor((t - clock.t_first) * clock.true_rate).astype(np.int64)
            out = self._buffer[np.maximum(k, 0) % self._size]
        return np.where(k < 0, held, out)


class AnalogSingleChannelWriter:
    """``nidaqmx.stream_writers.AnalogSingleChannelWriter`` on a simulated task."""

    def __init__(self, task_out_stream: SimOutStream, auto_start: Any = None) -> None:
        self._out_stream = task_out_stream
        self._task = task_out_stream._task
        self.auto_start = auto_start
        self.verify_array_shape = True

    def write_many_sample(self, data: NDArray[np.float64], timeout: float = 10.0) -> int:
        if self.verify_array_shape and np.ndim(data) != 1:
            raise daq_error("Write cannot be performed because the NumPy array passed into "
                            "this function is not shaped correctly.", -1, self._task.name)
        return self._out_stream.write(data, timeout)

    def write_one_sample(self, data: float, timeout: float = 10) -> None:
        task = self._task
        if task.timing.samp_timing_type == constants.SampleTimingType.ON_DEMAND:
            if self.auto_start is False and not task.running:
                raise daq_error("Task must be started before writing (auto_start false).",
                                -200474, task.name)
            self._out_stream.write_on_demand(float(data))
            return
        self._out_stream.write(np.array([float(data)]), timeout)


class AmplifiedShaker(BenchDrive):
    """A shaker whose amplifier's input is a simulated analogue output.

    Parameters
    ----------
    physics : BenchPhysics
        The bench it pushes on once attached (:meth:`attach`).
    line : OutputLine
        The module output wired to the amplifier's input.
    force_per_volt : float
        Force on the structure per volt at the amplifier's input, N/V.
    seed, sensor : int
        As :class:`~hardware_mocks.bench_drive.BenchDrive`.
    """

    def __init__(self, physics: BenchPhysics, line: OutputLine, *,
                 force_per_volt: float = 50.0, seed: int = 0, sensor: int = 0) -> None:
        super().__init__(physics, force_per_volt, seed, sensor)
        self.line = line

    def force(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Force (N) at host instants ``t``: the amplified output voltage."""
        return self.force_per_volt * self.line.voltage(t)

    def shutdown(self) -> None:
        """Leave the bench (idempotent)."""
        self.detach_from_bench()
