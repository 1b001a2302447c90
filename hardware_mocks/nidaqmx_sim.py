"""A simulated NI-DAQmx system: the nidaqmx surface insitu's NI front end calls, on a bench.

:class:`SimulatedNiDaqmx` stands where the ``nidaqmx`` package does: it has ``Task``,
``constants``, ``errors``, ``stream_readers`` (``AnalogMultiChannelReader``),
``stream_writers`` (``AnalogSingleChannelWriter``) and ``system``
(``PhysicalChannel``), with nidaqmx 1.7's names, argument order and defaults, and the real
package's constants and exceptions where it is installed (:mod:`hardware_mocks.nidaqmx_api`).
Its modules (:class:`SimModule`, NI 9234 class: 4 IEPE inputs, +/- 5 V) are wired to a
:class:`~hardware_mocks.physics.BenchPhysics`: each physical channel to a response DOF of
the bench, to the force on it, or to one shaker's force sensor, through a sensor of its own
sensitivity (mV/g or mV/N, as on its data sheet). A started task samples the bench on its
own :class:`~hardware_mocks.physics.DeviceClock` in a thread
(:class:`~hardware_mocks.input_signals.InputSignals`), turns the physical values into
volts by the sensors, clips them at the module's range, scales them back as NI-DAQmx does
from the channel's configured sensitivity and units, buffers them (``samps_per_chan``
samples, as NI-DAQmx's circular buffer) and calls the every-N-samples callback. Modules with
outputs (NI 9263 class, ``n_outputs``) generate voltages (:mod:`hardware_mocks.nidaqmx_ao`:
a task's regenerated buffer on its own clock, an amplified shaker on the bench).

Faults, as NI-DAQmx reports them: no driver (``Task()`` raises ``DaqNotFoundError``), an
unknown device (-200220 "Device identifier is invalid"), a channel the module lacks
(-200170), a range or excitation the module cannot do (-200077), no TEDS sensor (-200709),
a module removed (:meth:`SimulatedNiDaqmx.remove`, or scheduled after a hit with
:attr:`SimulatedNiDaqmx.remove_when`: reads, writes and ``is_task_done`` raise -201003, no
more events, its outputs drop to 0 V), unread samples overwritten (-200279).

Example
-------
>>> ni = SimulatedNiDaqmx(physics, [SimModule("cDAQ1Mod1")],
...                       wiring={"cDAQ1Mod1/ai0": 0}, sensors={"cDAQ1Mod1/ai0": 100.0})
>>> fe = NiDaqFrontEnd("fe", chans, 1024, devices=["cDAQ1Mod1"], api=ni)  # doctest: +SKIP
"""

from __future__ import annotations

import itertools
import re
import threading
import time
import types
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.input_signals import InputSignals
from hardware_mocks.nidaqmx_ao import (
    AnalogSingleChannelWriter,
    OutputLine,
    SimAOChannelCollection,
    SimOutStream,
)
from hardware_mocks.nidaqmx_api import constants, errors
from hardware_mocks.physics import BenchPhysics, DeviceClock

__all__ = ["NI9234_RATES", "SimModule", "SimulatedNiDaqmx"]

G0 = 9.80665  # m/s^2 per g (NI-DAQmx's)
#: NI 9234 sample rates: 51.2 kHz / n, n = 1..31, Hz
NI9234_RATES = tuple(51200.0 / n for n in range(31, 0, -1))
_PHYS = re.compile(r"^(?P<dev>[^/]+)/(?P<kind>ai|ao)(?P<ai>\d+)$")
_task_ids = itertools.count(1)


def _error(message: str, code: int, task: str = "") -> Exception:
    err: Exception = errors.DaqError(message, code, task_name=task)
    return err


@dataclass
class SimModule:
    """One simulated C Series module.

    Attributes
    ----------
    name : str
        Device name as NI MAX shows it (``"cDAQ1Mod1"``).
    product_type : str
    n_inputs : int
    range_v : float
        Input range, +/- V (the converter clips there).
    n_outputs : int
        Analogue outputs (NI 9263: 4; an input module: 0).
    output_range : float
        Output range, +/- V.
    rates : tuple of float, optional
        The rates the module runs, Hz (a request is coerced to the next one up); None: any
        rate (the simulated bench's modules).
    excitation_currents : tuple of float
        IEPE currents the module supplies, A.
    teds : mapping of int to float
        Inputs whose sensor carries TEDS, and the sensitivity it holds (mV/g or mV/N).
    """

    name: str
    product_type: str = "NI 9234"
    n_inputs: int = 4
    range_v: float = 5.0
    n_outputs: int = 0
    output_range: float = 10.0
    rates: tuple[float, ...] | None = None
    excitation_currents: tuple[float, ...] = (0.002,)
    teds: Mapping[int, float] = field(default_factory=dict)
    removed: bool = False


class SimAIChannel:
    """An analogue input channel of a task (the properties the driver reads or sets)."""

    def __init__(self, name: str, physical_channel: str, volts_per_unit: float,
                 min_val: float, max_val: float) -> None:
        self.name = name
        self.physical_channel = physical_channel
        #: V per unit of the channel, from its configured sensitivity (how it scales)
        self.volts_per_unit = volts_per_unit
        self.ai_min = min_val
        self.ai_max = max_val
        self.ai_coupling = constants.Coupling.AC
        self.ai_teds_is_teds = False
        self.ai_accel_units: Any = None
        self.ai_accel_sensitivity = 0.0
        self.ai_accel_sensitivity_units: Any = None
        self.ai_force_units: Any = None
        self.ai_force_iepe_sensor_sensitivity = 0.0
        self.ai_force_iepe_sensor_sensitivity_units: Any = None
        self.ai_excit_src: Any = None
        self.ai_excit_val = 0.0


class SimAIChannelCollection:
    """``task.ai_channels``: the add methods of nidaqmx 1.7 the driver uses."""

    def __init__(self, task: SimTask) -> None:
        self._task = task
        self._channels: list[SimAIChannel] = []

    def __len__(self) -> int:
        return len(self._channels)

    def __iter__(self) -> Iterator[SimAIChannel]:
        return iter(self._channels)

    def __getitem__(self, index: int) -> SimAIChannel:
        return self._channels[index]

    def add_ai_accel_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                          terminal_config: Any = constants.TerminalConfiguration.DEFAULT,
                          min_val: float = -5.0, max_val: float = 5.0,
                          units: Any = constants.AccelUnits.G, sensitivity: float = 1000.0,
                          sensitivity_units: Any = constants.AccelSensitivityUnits.
                          MILLIVOLTS_PER_G,
                          current_excit_source: Any = constants.ExcitationSource.INTERNAL,
                          current_excit_val: float = 0.004,
                          custom_scale_name: str = "") -> SimAIChannel:
        mv_per_g = sensitivity * (1000.0 if sensitivity_units
                                  == constants.AccelSensitivityUnits.VOLTS_PER_G else 1.0)
        chan = self._add(physical_channel, name_to_assign_to_channel, min_val, max_val,
                         _accel_volts_per_unit(mv_per_g, units), current_excit_source,
                         current_excit_val)
        chan.ai_accel_units, chan.ai_accel_sensitivity = units, sensitivity
        chan.ai_accel_sensitivity_units = sensitivity_units
        return chan

    def add_ai_force_iepe_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                               terminal_config: Any = constants.TerminalConfiguration.DEFAULT,
                               min_val: float = -2000.0, max_val: float = 2000.0,
                               units: Any = constants.ForceUnits.NEWTONS,
                               sensitivity: float = 2.25,
                               sensitivity_units: Any = constants.
                               ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON,
                               current_excit_source: Any = constants.ExcitationSource.INTERNAL,
                               current_excit_val: float = 0.004,
                               custom_scale_name: str = "") -> SimAIChannel:
        chan = self._add(physical_channel, name_to_assign_to_channel, min_val, max_val,
                         _force_volts_per_unit(sensitivity, units, sensitivity_units),
                         current_excit_source, current_excit_val)
        chan.ai_force_units, chan.ai_force_iepe_sensor_sensitivity = units, sensitivity
        chan.ai_force_iepe_sensor_sensitivity_units = sensitivity_units
        return chan

    def add_teds_ai_accel_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                               terminal_config: Any = constants.TerminalConfiguration.DEFAULT,
                               min_val: float = -5.0, max_val: float = 5.0,
                               units: Any = constants.AccelUnits.G,
                               current_excit_source: Any = constants.ExcitationSource.INTERNAL,
                               current_excit_val: float = 0.004,
                               custom_scale_name: str = "") -> SimAIChannel:
        mv_per_g = self._task.system.teds_of(physical_channel, self._task.name)
        chan = self.add_ai_accel_chan(
            physical_channel, name_to_assign_to_channel, terminal_config, min_val, max_val,
            units, mv_per_g, constants.AccelSensitivityUnits.MILLIVOLTS_PER_G,
            current_excit_source, current_excit_val)
        chan.ai_teds_is_teds = True
        return chan

    def add_teds_ai_force_iepe_chan(self, physical_channel: str,
                                    name_to_assign_to_channel: str = "",
                                    terminal_config: Any = constants.TerminalConfiguration.DEFAULT,
                                    min_val: float = -2000.0, max_val: float = 2000.0,
                                    units: Any = constants.ForceUnits.NEWTONS,
                                    current_excit_source: Any = constants.ExcitationSource.
                                    INTERNAL,
                                    current_excit_val: float = 0.001,
                                    custom_scale_name: str = "") -> SimAIChannel:
        mv_per_n = self._task.system.teds_of(physical_channel, self._task.name)
        chan = self.add_ai_force_iepe_chan(
            physical_channel, name_to_assign_to_channel, terminal_config, min_val, max_val,
            units, mv_per_n, constants.ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON,
            current_excit_source, current_excit_val)
        chan.ai_teds_is_teds = True
        return chan

    def _add(self, physical_channel: str, name: str, min_val: float, max_val: float,
             volts_per_unit: float, excit_source: Any, excit_val: float) -> SimAIChannel:
        task = self._task
        module, _ = task.system.resolve(physical_channel, task.name)
        if task.running:
            raise _error("Specified operation cannot be performed while the task is running.",
                         -200479, task.name)
        volts = max(abs(min_val), abs(max_val)) * volts_per_unit
        if volts > module.range_v * (1 + 1e-9):
            raise _error(f"Requested value is not a supported value for this property. "
                         f"Property: DAQmx_AI_Max Requested Value: {max_val:g} Channel Name: "
                         f"{name or physical_channel} (the sensor's signal at it would be "
                         f"{volts:.4g} V, the module's range is +/-{module.range_v:g} V)",
                         -200077, task.name)
        choices = ", ".join(f"{c:g}" for c in module.excitation_currents)
        if excit_source == constants.ExcitationSource.INTERNAL and not any(
                abs(excit_val - c) < 1e-9 for c in module.excitation_currents):
            raise _error(f"Requested value is not a supported value for this property. "
                         f"Property: DAQmx_AI_Excit_Val Requested Value: {excit_val:g} "
                         f"You Can Select: {choices}",
                         -200077, task.name)
        if any(c.physical_channel == physical_channel for c in self._channels):
            raise _error(f"Physical channel {physical_channel} is already in the task.",
                         -200489, task.name)
        chan = SimAIChannel(name or physical_channel, physical_channel, volts_per_unit,
                            min_val, max_val)
        chan.ai_excit_src, chan.ai_excit_val = excit_source, excit_val
        self._channels.append(chan)
        return chan


def _accel_volts_per_unit(mv_per_g: float, units: Any) -> float:
    if units == constants.AccelUnits.G:
        return mv_per_g / 1000.0
    if units == constants.AccelUnits.METERS_PER_SECOND_SQUARED:
        return mv_per_g / 1000.0 / G0
    raise _error(f"Requested value is not a supported value for this property. Property: "
                 f"DAQmx_AI_Accel_Units Requested Value: {units}", -200077)


def _force_volts_per_unit(sensitivity: float, units: Any, sensitivity_units: Any) -> float:
    if (units != constants.ForceUnits.NEWTONS or sensitivity_units
            != constants.ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON):
        raise _error("Requested value is not a supported value for this property (the "
                     "simulated modules take newtons and mV/N)", -200077)
    return sensitivity / 1000.0


class SimTiming:
    """``task.timing``: the sample clock."""

    def __init__(self, task: SimTask) -> None:
        self._task = task
        self.samp_clk_rate = 0.0
        self.samp_quant_samp_mode: Any = None
        self.samp_quant_samp_per_chan = 0
        self._timing_type: Any = constants.SampleTimingType.ON_DEMAND

    @property
    def samp_timing_type(self) -> Any:
        return self._timing_type

    @samp_timing_type.setter
    def samp_timing_type(self, value: Any) -> None:
        if self._task.running:
            raise _error("Specified operation cannot be performed while the task is running.",
                         -200479, self._task.name)
        self._timing_type = value

    def cfg_samp_clk_timing(self, rate: float, source: str = "",
                            active_edge: Any = constants.Edge.RISING,
                            sample_mode: Any = constants.AcquisitionType.FINITE,
                            samps_per_chan: int = 1000) -> None:
        task = self._task
        if not (len(task.ai_channels) or len(task.ao_channels)):
            raise _error("Task contains no channels.", -200478, task.name)
        if task.running:
            raise _error("Specified operation cannot be performed while the task is running.",
                         -200479, task.name)
        coerced = float(rate)
        for module in task.modules():
            if module.rates is not None:
                up = [r for r in module.rates if r >= rate * (1 - 1e-12)]
                if not up:
                    raise _error(f"Requested value is not a supported value for this "
                                 f"property. Property: DAQmx_SampClk_Rate Requested Value: "
                                 f"{rate:g} Maximum Value: {max(module.rates):g}", -200077,
                                 task.name)
                coerced = max(coerced, min(up))
        self.samp_clk_rate = coerced
        self.samp_quant_samp_mode = sample_mode
        self.samp_quant_samp_per_chan = int(samps_per_chan)
        self._timing_type = constants.SampleTimingType.SAMPLE_CLOCK


class SimInStream:
    """``task.in_stream``: the task's buffer, read by the stream readers."""

    def __init__(self, task: SimTask) -> None:
        self._task = task

    @property
    def num_chans(self) -> int:
        return len(self._task.ai_channels)

    @property
    def avail_samp_per_chan(self) -> int:
        return self._task.available()

    @property
    def total_samp_per_chan_acquired(self) -> int:
        return self._task.acquired


class AnalogMultiChannelReader:
    """``nidaqmx.stream_readers.AnalogMultiChannelReader`` on a simulated task."""

    def __init__(self, task_in_stream: SimInStream) -> None:
        self._in_stream = task_in_stream
        self._task = task_in_stream._task
        self.verify_array_shape = True

    def read_many_sample(self, data: NDArray[np.float64],
                         number_of_samples_per_channel: int = constants.READ_ALL_AVAILABLE,
                         timeout: float = 10.0) -> int:
        task = self._task
        n = number_of_samples_per_channel
        if n == constants.READ_ALL_AVAILABLE:
            n = task.available()
        shape = (self._in_stream.num_chans, n)
        if self.verify_array_shape and data.shape != shape:
            raise _error("Read cannot be performed because the NumPy array passed into this "
                         "function is not shaped correctly. Shape of NumPy Array provided: "
                         f"{data.shape} Shape of NumPy Array required: {shape}", -1, task.name)
        data[:, :n] = task.take(n, timeout)
        return n


class SimPhysicalChannel:
    """``nidaqmx.system.PhysicalChannel``: TEDS of a physical channel."""

    def __init__(self, system: SimulatedNiDaqmx, name: str) -> None:
        self._system = system
        self.name = name

    def configure_teds(self, file_path: str | None = None) -> None:
        self._system.teds_of(self.name, "")


class SimTask:
    """``nidaqmx.Task`` of the simulated system (construct it as ``system.Task()``)."""

    def __init__(self, system: SimulatedNiDaqmx, new_task_name: str = "", *,
                 grpc_options: Any = None) -> None:
        if not system.driver_installed:
            raise errors.DaqNotFoundError(
                "Could not find an installation of NI-DAQmx. Download the latest version of "
                "NI-DAQmx at: https://www.ni.com/en/support/downloads/drivers/download.ni-daq-"
                "mx.html")
        self.system = system
        self.name = new_task_name or f"_unnamedTask<{next(_task_ids)}>"
        self.ai_channels = SimAIChannelCollection(self)
        self.timing = SimTiming(self)
        self.in_stream = SimInStream(self)
        self.ao_channels = SimAOChannelCollection(self)
        self.out_stream = SimOutStream(self)
        self.running = False
        self.closed = False
        self.acquired = 0
        self._callback: Callable[[int, int, int, Any], int] | None = None
        self._n_event = 0
        self._cond = threading.Condition()
        self._buffer = np.zeros((0, 0))
        self._read = 0  # samples read since start
        self._error: Exception | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.signals: InputSignals | None = None
        self.clock: DeviceClock | None = None
        system.tasks.append(self)

    def __enter__(self) -> SimTask:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def modules(self) -> list[SimModule]:
        """The modules of the task's channels, in channel order, once each."""
        mods = [self.system.resolve(c.physical_channel, self.name)[0]
                for c in [*self.ai_channels, *self.ao_channels]]
        return list({id(m): m for m in mods}.values())

    def register_every_n_samples_acquired_into_buffer_event(
            self, sample_interval: int, callback_method: Callable[..., int] | None) -> None:
        if self.running:
            raise _error("Specified operation cannot be performed while the task is running.",
                         -200479, self.name)
        if callback_method is not None and self._callback is not None:
            raise _error("Every N Samples Acquired Into Buffer event is already registered.",
                         -200960, self.name)
        self._callback = callback_method
        self._n_event = int(sample_interval)

    def start(self) -> None:
        if self.closed:
            raise _error("Task specified is invalid or does not exist.", -200088, self.name)
        if self.running:
            return
        rate = self.timing.samp_clk_rate
        if not rate:
            raise _error("Sample clock not configured.", -200077, self.name)
        for module in self.modules():
            if module.removed:
                raise _error(f"Device cannot be accessed. Device: {module.name}", -201003,
                             self.name)
        if len(self.ao_channels):
            self.out_stream.start()
            self.running = True
            return
        chans = list(self.ai_channels)
        sys_ = self.system
        wiring = [sys_.wiring.get(c.physical_channel) for c in chans]
        self.signals = InputSignals(sys_.physics, wiring, len(chans),
                                    accel_noise=sys_.accel_noise, force_noise=sys_.force_noise,
                                    tail=sys_.tail, seed=sys_.seed)
        self._volts_in = np.array([sys_.sensor_volts_per_unit(c.physical_channel)
                                   for c in chans])
        self._volts_out = np.array([c.volts_per_unit for c in chans])
        self._range = np.array([sys_.resolve(c.physical_channel, self.name)[0].range_v
                                for c in chans])
        sys_.physics.impulse_response(rate, 0)  # computed before the clock starts
        self.clock = DeviceClock(rate)
        self.clock.start()
        self.signals.start(self.clock)
        with self._cond:
            size = max(self.timing.samp_quant_samp_per_chan, 1)
            self._buffer = np.zeros((len(chans), size))
            self.acquired = self._read = 0
            self._error = None
        self._stop.clear()
        self.running = True
        self._thread = threading.Thread(target=self._run, name=f"sim-nidaqmx-{self.name}",
                                        daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._halt()
        if len(self.ao_channels):  # stopping an output on a module that is gone fails
            self.check_modules()

    def _halt(self) -> None:
        self.running = False
        self._stop.set()
        self.out_stream.stop()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)

    def check_modules(self) -> None:
        """NI-DAQmx's -201003 when a module of the task has been removed."""
        self.system.check_removal()
        self.modules()

    def close(self) -> None:
        self._halt()
        self.closed = True
        if self in self.system.tasks:
            self.system.tasks.remove(self)

    def is_task_done(self) -> bool:
        if len(self.ao_channels):
            self.check_modules()
        with self._cond:
            if self._error is not None:
                raise self._error
        return not self.running

    # -- the device side ------------------------------------------------------------------
    def available(self) -> int:
        with self._cond:
            return self.acquired - self._read

    def take(self, n: int, timeout: float) -> NDArray[np.float64]:
        """The next ``n`` unread samples (n_chans, n); the task's error if it has one."""
        deadline = time.monotonic() + max(timeout, 0.0)
        with self._cond:
            while True:
                if self._error is not None:
                    raise self._error
                if self.acquired - self._read > self._buffer.shape[1]:
                    self._error = _error(
                        "The application is not able to keep up with the hardware acquisition. "
                        "Attempted to read samples that are no longer available.", -200279,
                        self.name)
                    raise self._error
                if self.acquired - self._read >= n:
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    raise _error("Some or all of the samples requested have not yet been "
                                 "acquired.", -200284, self.name)
                self._cond.wait(min(left, 0.05))
            size = self._buffer.shape[1]
            idx = (self._read + np.arange(n)) % size
            out = self._buffer[:, idx].copy()
            self._read += n
        return out

    def _run(self) -> None:
        assert self.signals is not None and self.clock is not None
        next_event = self._n_event
        period = min(0.01, max(self._n_event, 1) / self.clock.fs / 4)
        mine = self.modules()
        while not self._stop.wait(period):
            self.system.check_removal()
            gone = [m.name for m in mine if m.removed]
            if gone:
                with self._cond:
                    self._error = _error(f"Device cannot be accessed. Device: {gone[0]}",
                                         -201003, self.name)
                    self._cond.notify_all()
                self.running = False
                return
            due = self.clock.due()
            new = due - self.signals.produced
            if new <= 0:
                continue
            self.signals.advance(due)
            volts = np.clip(self.signals.take(new) * self._volts_in[:, None],
                            -self._range[:, None], self._range[:, None])
            scaled = volts / self._volts_out[:, None]
            with self._cond:
                size = self._buffer.shape[1]
                idx = (self.acquired + np.arange(new)) % size
                self._buffer[:, idx] = scaled
                self.acquired += new
                self._cond.notify_all()
            callback = self._callback
            while callback is not None and self._n_event and self.acquired >= next_event:
                if self._stop.is_set():
                    return
                callback(0, constants.EveryNSamplesEventType.ACQUIRED_INTO_BUFFER.value,
                         self._n_event, None)
                next_event += self._n_event


class SimulatedNiDaqmx:
    """A simulated NI-DAQmx system: chassis modules wired to a bench, and nidaqmx's surface.

    Parameters
    ----------
    physics : BenchPhysics
        The bench the modules' sensors sit on.
    modules : sequence of SimModule
        The modules NI-DAQmx sees.
    wiring : mapping of str to int
        Physical channel (``"cDAQ1Mod1/ai0"``) -> wiring code of
        :class:`~hardware_mocks.input_signals.InputSignals` (response DOF, ``FORCE``,
        ``shaker_force(k)``); other channels are open.
    sensors : mapping of str to float
        Physical channel -> its sensor's sensitivity, mV/g (response DOFs) or mV/N (forces).
    accel_noise, force_noise : float
        Sensor noise, m/s^2 and N RMS.
    tail : float, optional
        Length of each hit's computed response, s (see InputSignals).
    driver_installed : bool
        False: ``Task()`` raises ``DaqNotFoundError``, as nidaqmx without NI's driver.
    seed : int
        Noise seed.

    Attributes
    ----------
    remove_when : tuple (module name, when), optional
        Remove that module once ``when()`` gives a host time (``time.monotonic()``) that
        has passed; ``when()`` gives None until it knows the time.
    """

    def __init__(self, physics: BenchPhysics, modules: Sequence[SimModule], *,
                 wiring: Mapping[str, int], sensors: Mapping[str, float],
                 accel_noise: float = 0.0, force_noise: float = 0.0,
                 tail: float | None = None, driver_installed: bool = True,
                 seed: int = 0) -> None:
        self.physics = physics
        self.modules = {m.name: m for m in modules}
        self.wiring = dict(wiring)
        self.sensors = dict(sensors)
        for phys in self.wiring:
            if phys not in self.sensors:
                raise ValueError(f"{phys} is wired but has no sensor sensitivity")
        self.accel_noise, self.force_noise, self.tail = accel_noise, force_noise, tail
        self.driver_installed = driver_installed
        self.seed = seed
        self.remove_when: tuple[str, Callable[[], float | None]] | None = None
        self.lines: dict[str, OutputLine] = {}
        self.tasks: list[SimTask] = []
        self.constants = constants
        self.errors = errors
        self.stream_readers = types.SimpleNamespace(
            AnalogMultiChannelReader=AnalogMultiChannelReader)
        self.stream_writers = types.SimpleNamespace(
            AnalogSingleChannelWriter=AnalogSingleChannelWriter)
        self.system = types.SimpleNamespace(
            PhysicalChannel=lambda name, *, grpc_options=None: SimPhysicalChannel(self, name))

    def Task(self, new_task_name: str = "", *, grpc_options: Any = None) -> SimTask:
        """``nidaqmx.Task()`` on this system."""
        return SimTask(self, new_task_name, grpc_options=grpc_options)

    def resolve(self, physical_channel: str, task: str) -> tuple[SimModule, int]:
        """The module and input of ``"Dev/aiK"``, or NI-DAQmx's error for it."""
        m = _PHYS.match(physical_channel)
        dev = m.group("dev") if m else physical_channel.split("/")[0]
        module = self.modules.get(dev)
        if module is None:
            raise _error(f"Device identifier is invalid. Device Specified: {dev}", -200220,
                         task)
        if module.removed:
            raise _error(f"Device cannot be accessed. Device: {dev}", -201003, task)
        kind = m.group("kind") if m else "ai"
        count = module.n_outputs if kind == "ao" else module.n_inputs
        if m is None or int(m.group("ai")) >= count:
            valid = f"{dev}/{kind}0:{count - 1}" if count else "none"
            raise _error(f"Physical channel specified does not exist on this device. Physical "
                         f"Channel Name: {physical_channel} Valid Physical Channels: {valid}",
                         -200170, task)
        return module, int(m.group("ai"))

    def teds_of(self, physical_channel: str, task: str) -> float:
        """The sensitivity the TEDS of the sensor at ``physical_channel`` holds."""
        module, ai = self.resolve(physical_channel, task)
        if ai not in module.teds:
            raise _error(f"TEDS sensor not detected in the specified physical channel. "
                         f"Physical Channel: {physical_channel}", -200709, task)
        return float(module.teds[ai])

    def sensor_volts_per_unit(self, physical_channel: str) -> float:
        """V per m/s^2 (or per N) of the sensor at ``physical_channel`` (0: nothing there)."""
        code = self.wiring.get(physical_channel)
        if code is None:
            return 0.0
        mv = self.sensors[physical_channel]
        return mv / 1000.0 / G0 if code >= 0 else mv / 1000.0

    def add(self, modules: Sequence[SimModule], *, wiring: Mapping[str, int],
            sensors: Mapping[str, float]) -> None:
        """Plug in more modules (another device's) with their inputs' wiring and sensors."""
        for phys in wiring:
            if phys not in sensors:
                raise ValueError(f"{phys} is wired but has no sensor sensitivity")
        self.modules.update({m.name: m for m in modules})
        self.wiring.update(wiring)
        self.sensors.update(sensors)

    def output_line(self, physical_channel: str) -> OutputLine:
        """The output ``"Dev/aoK"`` (what an amplifier wired to it sees)."""
        module, _ = self.resolve(physical_channel, "")
        line = self.lines.setdefault(physical_channel, OutputLine(physical_channel))
        line.removed = module.removed
        return line

    def remove(self, module: str) -> None:
        """Pull ``module`` out of the chassis now (its outputs drop to 0 V)."""
        self.modules[module].removed = True
        for phys, line in self.lines.items():
            if phys.split("/")[0] == module:
                line.removed = True

    def check_removal(self) -> None:
        """Carry out :attr:`remove_when` once its time has come (on the host clock)."""
        if self.remove_when is None:
            return
        module, when = self.remove_when
        t = when()
        if t is not None and time.monotonic() >= t:
            self.remove(module)
            self.remove_when = None
