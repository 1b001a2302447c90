"""The shaker's amplifier driven from an analogue output of the cDAQ, through NI-DAQmx.

Backend ``shaker-nidaqmx``: one voltage output of an NI 9263 / 9260 class C Series module
in the chassis that holds the front end's modules, wired to the shaker amplifier's input.
The output runs on the chassis' timebase, as the inputs do: drive and measurement share one
clock and never drift apart. Station file::

    [devices.shaker]
    backend = "shaker-nidaqmx"
    transport = { nidaqmx = "cDAQ1Mod5" }
    options = { channel = "ao0", rate = 10240, max_level = 1.0 }

Options (all optional):

=============  ===============================================================  =========
option         meaning                                                          default
=============  ===============================================================  =========
channel        the module's output, ``"ao0"`` .. ``"ao3"``                         ``"ao0"``
rate           output sample rate, Sa/s: a chirp's or burst's period must be a   10240
               whole number of samples (a multiple of the plan's ``record.fs``)
max_level      highest level this station allows, V (RMS for random, peak for    2.0
               sine and chirp)
output_range   the module's output range, +/- V (NI 9263: 10; NI 9260: 4.24)     10.0
ramp           ramp up and down, s (the shaker plan gives its ``ramp``)          1.0
random_period  length of the random drive's buffer, s                           4.0
bursts         burst random: different bursts in the buffer, played in turn     4
seed           seed of the random and burst-random noise                        0
timeout        s NI-DAQmx may take for a call before the driver gives up         2.0
=============  ===============================================================  =========

One NI-DAQmx task holds the output (``ao_channels.add_ao_voltage_chan`` over
``+/- output_range`` V). Turning it on configures a continuous sample clock
(``timing.cfg_samp_clk_timing``) with one buffer of the waveform's period, allows
regeneration (``out_stream.regen_mode``), writes the first buffer with
``AnalogSingleChannelWriter.write_many_sample`` and starts: NI-DAQmx then plays the buffer
over and over with no help from the host. Every waveform is periodic in its buffer, so the
regenerated output repeats sample for sample (:mod:`processing.excitation`):

============== ======================================================================
random         :func:`~processing.excitation.periodic_random`, flat over
               ``f_start``..``f_stop``, one ``random_period`` long; level in V RMS.
burst random   :func:`~processing.excitation.burst_random`: ``bursts`` different bursts,
               each on for ``burst`` of its ``period``; level in V RMS within the bursts.
chirp          :func:`~processing.excitation.periodic_chirp`, one sweep a ``period``
               (band edges rounded so the phase closes on itself); level in V peak.
sine           a whole number of cycles in the shortest buffer that holds one; level in
               V peak.
============== ======================================================================

The ramp. NI-DAQmx lets a program write to a regenerating task while it runs: each write
goes where the last one ended and waits until the generation has moved past that part of
the buffer. The driver always writes whole buffers, so each write lands on a period
boundary: the first buffer written before the start is the waveform under the rising part
of the ramp, the next ones (written after the start, each accepted one period later) the
rest of the ramp, then the waveform at its level, which plays on. A level changed while the
output is on ramps from the old to the new one the same way. ``stop()`` writes the falling
ramp and then a buffer of zeros (regenerated from then on: the output stays at 0 V even if
the host stops here), waits until NI-DAQmx has generated the ramp, stops the task and
writes 0 V on demand. A change takes effect at the next buffer boundary: up to one period
(and the chassis' output FIFO) late.

Output off at once (``shutdown()``, any NI-DAQmx error, :meth:`NiDaqShaker.output_problem`
finding the task failed, interpreter exit through ``atexit``): stop the task, switch it
to on-demand timing and write 0 V, from a helper thread waited for ``2 timeout`` s at most.
A module removed or a chassis gone leaves nothing to switch off; a host that dies without
running any of these (``kill -9``, a power cut) leaves the module regenerating its buffer:
see ``docs/hardware.md``.

Without the nidaqmx package, without NI's driver, with an unknown module or a module
removed, the driver raises one line each, as the front end does
(:mod:`drivers.nidaqmx_common`).

Example
-------
>>> with NiDaqShaker("shaker", "cDAQ1Mod5", rate=10240) as shaker:  # doctest: +SKIP
...     shaker.set_waveform("chirp", f_start=2.0, f_stop=200.0, period=1.0)
...     shaker.set_level(0.5)  # V peak
...     shaker.start()  # ramps up
"""

from __future__ import annotations

import atexit
import logging
import math
import re
import threading
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers import nidaqmx_common
from drivers.base import DeviceState, ExcitationDevice, Waveform
from drivers.errors import DeviceError, DeviceInitializationError, DeviceTimeoutError
from drivers.nidaqmx_common import (
    DEVICE_GONE,
    close_task,
    daq_error,
    device_options,
    first_line,
    new_task,
)
from drivers.station import DeviceConfig, NiDaqTransportConfig

__all__ = ["MAX_LEVEL", "OUTPUT_RANGE", "RATE", "NiDaqShaker"]

logger = logging.getLogger(__name__)

#: the highest level a station allows by default, V (option ``max_level``)
MAX_LEVEL = 2.0
#: the NI 9263's output range, +/- V (option ``output_range``)
OUTPUT_RANGE = 10.0
#: default output rate, Sa/s (ten samples a cycle at the top of a 1024 Hz plan's band)
RATE = 10240.0
#: a sine's buffer is at most this long, s
SINE_SECONDS = 10.0
OPTIONS = ("api", "channel", "rate", "max_level", "output_range", "ramp", "random_period",
           "bursts", "seed", "timeout")
_CHANNEL = re.compile(r"^ao\d+$")
_PARAMS = {
    Waveform.RANDOM: {"f_start", "f_stop"},
    Waveform.BURST_RANDOM: {"f_start", "f_stop", "period", "burst"},
    Waveform.CHIRP: {"f_start", "f_stop", "period"},
    Waveform.SINE: {"frequency"},
}


class NiDaqShaker(ExcitationDevice):
    """An analogue output of an NI-DAQmx module feeding a shaker amplifier.

    Parameters
    ----------
    name : str
    device : str
        The output module's name as NI MAX shows it (``"cDAQ1Mod5"``).
    api : object, optional
        The nidaqmx API (default: the ``nidaqmx`` package, imported at ``open()``).
    channel, rate, max_level, output_range, ramp, random_period, bursts, seed, timeout
        See the module's table (V, Sa/s and s).
    """

    def __init__(self, name: str, device: str, *, api: Any = None, channel: str = "ao0",
                 rate: float = RATE, max_level: float = MAX_LEVEL,
                 output_range: float = OUTPUT_RANGE, ramp: float = 1.0,
                 random_period: float = 4.0, bursts: int = 4, seed: int = 0,
                 timeout: float = 2.0) -> None:
        super().__init__(name)
        if not isinstance(channel, str) or not _CHANNEL.match(channel):
            raise ValueError(f"{name}: channel must be an output of the module, \"ao0\" .. "
                             f"\"ao7\", got {channel!r}")
        numbers = {"rate": rate, "max_level": max_level, "output_range": output_range,
                   "random_period": random_period, "timeout": timeout}
        for key, value in numbers.items():
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: {key} must be a number > 0, got {value!r}")
        if isinstance(ramp, bool) or not isinstance(ramp, int | float) or not 0 <= ramp < 1e4:
            raise ValueError(f"{name}: ramp must be a number of seconds >= 0, got {ramp!r}")
        if isinstance(bursts, bool) or not isinstance(bursts, int) or bursts < 1:
            raise ValueError(f"{name}: bursts must be an integer >= 1, got {bursts!r}")
        self.device = device
        self.channel = channel
        self.rate = float(rate)
        self.max_level = float(max_level)
        self.output_range = float(output_range)
        self.ramp = float(ramp)
        self.random_period = float(random_period)
        self.bursts = bursts
        self.seed = int(seed)
        self.timeout = float(timeout)
        self._api = api
        self._ni: Any = None
        self._task: Any = None
        self._writer: Any = None
        #: one period of the waveform at unit level (unit RMS for random, unit peak else)
        self._wave: NDArray[np.float64] | None = None
        self._written = 0  # samples written since the start
        self._ramp_writer: threading.Thread | None = None
        self._write_error = ""  # why the ramp up failed (the output is off)
        self._halted = threading.Event()  # the output is being turned off: writes may fail

    @property
    def physical_channel(self) -> str:
        """``"cDAQ1Mod5/ao0"``."""
        return f"{self.device}/{self.channel}"

    @classmethod
    def from_config(cls, config: DeviceConfig, **overrides: Any) -> NiDaqShaker:
        if not (isinstance(config.transport, NiDaqTransportConfig)
                and len(config.transport.devices) == 1):
            raise ValueError(f"device {config.name!r}: shaker-nidaqmx needs its output module, "
                             "transport = { nidaqmx = \"cDAQ1Mod5\" }")
        opts = device_options(config, overrides, OPTIONS)
        return cls(config.name, config.transport.devices[0], **opts)

    @classmethod
    def setting_limits(cls, config: DeviceConfig) -> dict[str, tuple[float, float]]:
        """Frequencies up to half the output rate, the ramp, and the level up to the station's
        ``max_level`` and the module's range."""
        opts = config.options
        nyquist = float(opts.get("rate", RATE)) / 2
        level = min(float(opts.get("max_level", MAX_LEVEL)),
                    float(opts.get("output_range", OUTPUT_RANGE)))
        return {"f_start": (0.0, nyquist), "f_stop": (0.0, nyquist),
                "frequency": (0.0, nyquist), "ramp": (0.0, 1e4), "level": (0.0, level)}

    # -- errors -----------------------------------------------------------------------------------
    def _fail(self, err: BaseException, doing: str) -> DeviceError:
        return daq_error(self.name, (self.device,), err, doing)

    # -- life cycle -------------------------------------------------------------------------------
    def _open_internal(self) -> None:
        ni = self._api if self._api is not None else nidaqmx_common.import_nidaqmx(
            self.name, "shaker-nidaqmx", ("constants", "errors", "stream_writers"))
        self._ni = ni
        self._task = new_task(ni, self.name, (self.device,))
        try:
            self._configure(ni, self._task)
        except BaseException:
            self._close_task()
            raise
        self.identity = f"NI-DAQmx {self.physical_channel} at {self.rate:g} Sa/s"
        atexit.register(self.shutdown)

    def _configure(self, ni: Any, task: Any) -> None:
        c = ni.constants
        phys = self.physical_channel
        try:
            task.ao_channels.add_ao_voltage_chan(
                phys, name_to_assign_to_channel=self.name, min_val=-self.output_range,
                max_val=self.output_range, units=c.VoltageUnits.VOLTS)
        except ni.errors.DaqError as err:
            raise self._fail(err, f"output {phys}") from err
        try:
            task.timing.cfg_samp_clk_timing(self.rate, sample_mode=c.AcquisitionType.CONTINUOUS,
                                            samps_per_chan=round(self.rate))
            actual = float(task.timing.samp_clk_rate)
        except ni.errors.DaqError as err:
            raise self._fail(err, f"sample clock at {self.rate:g} Sa/s") from err
        if abs(actual - self.rate) > 1e-6 * self.rate:
            raise DeviceInitializationError(
                f"{self.name}: NI-DAQmx runs {phys} at {actual:.6g} Sa/s, not the "
                f"{self.rate:g} asked: set option rate to one the module runs exactly "
                "(a multiple of the plan's record.fs)", self.name)
        self._writer = ni.stream_writers.AnalogSingleChannelWriter(task.out_stream)
        self._zero(task)

    def _zero(self, task: Any) -> None:
        """0 V on demand (the task stopped): on-demand timing, one sample written."""
        task.timing.samp_timing_type = self._ni.constants.SampleTimingType.ON_DEMAND
        self._writer.write_one_sample(0.0, timeout=self.timeout)

    def _shutdown_internal(self) -> None:
        atexit.unregister(self.shutdown)
        self._close_task()

    def _close_task(self) -> None:
        task, self._task = self._task, None
        close_task(task, self._ni, self.name)

    # -- waveform and level -----------------------------------------------------------------------
    def _set_waveform_internal(self, waveform: Waveform, params: dict[str, float]) -> None:
        allowed = _PARAMS[waveform]
        if extra := set(params) - allowed:
            raise ValueError(f"{self.name}: {waveform.value} takes {sorted(allowed)}, "
                             f"not {sorted(extra)}")
        for key in ("f_start", "f_stop", "frequency"):
            if params.get(key, 0.0) > self.rate / 2:
                raise ValueError(f"{self.name}: {key} {params[key]:g} Hz above half the output "
                                 f"rate ({self.rate / 2:g} Hz): raise option rate")
        wave = self._synthesise(waveform, params)
        if self.level > 0:
            self._check_level(self.level, wave)
        self._wave = wave

    def _synthesise(self, waveform: Waveform, params: dict[str, float]) -> NDArray[np.float64]:
        """One buffer of ``waveform`` at unit level."""
        from processing.excitation import burst_random, periodic_chirp, periodic_random

        band = (params.get("f_start", 0.0), params.get("f_stop", 200.0))
        if waveform is Waveform.SINE:
            return self._sine(params.get("frequency", 100.0))
        if waveform is Waveform.RANDOM:
            n = max(round(self.random_period * self.rate), 2)
            return periodic_random(n, self.rate, band=band, seed=self.seed)
        period = params.get("period", 1.0)
        n = round(period * self.rate)
        if n < 2 or abs(n - period * self.rate) > 1e-6 * n:
            raise ValueError(f"{self.name}: a {waveform.value} period of {period:g} s is not a "
                             f"whole number of samples at {self.rate:g} Sa/s: set option rate "
                             "to a multiple of the plan's record.fs")
        if waveform is Waveform.CHIRP:
            return periodic_chirp(1, n, self.rate, band=band)
        return burst_random(self.bursts, n, self.rate, burst_fraction=params.get("burst", 0.5),
                            band=band, seed=self.seed)[0]

    def _sine(self, frequency: float) -> NDArray[np.float64]:
        """Whole cycles of a unit sine in the shortest buffer that holds them exactly."""
        cycles = np.arange(1, math.floor(SINE_SECONDS * frequency) + 1)
        samples = cycles * self.rate / frequency if frequency > 0 else cycles * 0.0
        exact = np.flatnonzero((np.abs(samples - np.round(samples)) < 1e-6) & (samples >= 2))
        if exact.size == 0:
            raise ValueError(f"{self.name}: a sine of {frequency:g} Hz has no whole number of "
                             f"cycles in {SINE_SECONDS:g} s at {self.rate:g} Sa/s (the "
                             "regenerated buffer must hold whole cycles): choose a frequency "
                             "with a whole number of cycles in some whole number of samples, "
                             "e.g. a whole number of Hz")
        n = round(float(samples[exact[0]]))
        return np.sin(2 * np.pi * frequency * np.arange(n) / self.rate)

    def _check_level(self, level: float, wave: NDArray[np.float64] | None) -> None:
        if level > self.max_level:
            raise ValueError(f"{self.name}: level {level:g} V above the station's limit "
                             f"{self.max_level:g} V (option max_level)")
        peak = level * (float(np.max(np.abs(wave))) if wave is not None else 1.0)
        if peak > self.output_range:
            raise ValueError(f"{self.name}: level {level:g} V peaks at {peak:.4g} V with this "
                             f"waveform, beyond the module's +/-{self.output_range:g} V: "
                             "lower the level")

    def _set_level_internal(self, level: float) -> None:
        self._check_level(level, self._wave)
        if self._state is DeviceState.RUNNING:
            self._join_ramp()
            self._write_all(self._ramp_buffers(self.level, level), "changing the level")

    # -- output -----------------------------------------------------------------------------------
    def _ramp_buffers(self, start: float, end: float) -> list[NDArray[np.float64]]:
        """Whole buffers from level ``start`` to ``end`` (V): the waveform under a linear
        ramp of ``ramp`` s (none without a ramp), then one buffer at ``end``. Written as the
        first buffers of a generation or after the buffers written so far, each begins at a
        period boundary."""
        assert self._wave is not None
        n = self._wave.size
        steady = self._wave * end
        k = math.ceil(self.ramp * self.rate / n) if self.ramp > 0 else 0
        if k == 0:
            return [steady]
        t = np.arange(k * n) / self.rate
        envelope = start + (end - start) * np.clip(t / self.ramp, 0.0, 1.0)
        ramp = (np.tile(self._wave, k) * envelope).reshape(k, n)
        return [*ramp, steady]

    def _write_all(self, buffers: list[NDArray[np.float64]], doing: str) -> None:
        """Write ``buffers`` to the running task, each once the generation has room for it
        (one period after the last); on an error, output off and one line."""
        n = buffers[0].size if buffers else 0
        try:
            for buf in buffers:
                self._writer.write_many_sample(buf, timeout=n / self.rate + self.timeout)
                self._written += n
        except self._ni.errors.DaqError as err:
            failure = self._fail(err, doing)
            if not self._halted.is_set():  # else cut short by an output off: it is off
                self._emergency_off()
                self._write_error = f"{failure}; output turned off"
            raise failure from err

    def _output_on_internal(self) -> None:
        if self._wave is None:
            raise DeviceError(f"{self.name}: choose a waveform before turning the output on",
                              self.name)
        self._join_ramp()
        c, task = self._ni.constants, self._task
        buffers = self._ramp_buffers(0.0, self.level)
        self._halted.clear()
        self._write_error = ""
        try:
            task.timing.cfg_samp_clk_timing(self.rate, sample_mode=c.AcquisitionType.CONTINUOUS,
                                            samps_per_chan=self._wave.size)
            task.out_stream.regen_mode = c.RegenerationMode.ALLOW_REGENERATION
            self._writer.write_many_sample(buffers[0], timeout=self.timeout)
            self._written = self._wave.size
            task.start()
        except self._ni.errors.DaqError as err:
            failure = self._fail(err, "starting the output")
            self._emergency_off()
            raise failure from err
        if len(buffers) > 1:  # the rest of the ramp, each buffer a period ahead of the output
            self._ramp_writer = threading.Thread(
                target=self._ramp_up, args=(buffers[1:],), name=f"{self.name}-ramp",
                daemon=True)
            self._ramp_writer.start()

    def _ramp_up(self, buffers: list[NDArray[np.float64]]) -> None:
        """The ramp's later buffers and the steady one, written while the output runs; a
        failure turns the output off and is told by :meth:`output_problem`."""
        try:
            self._write_all(buffers, "ramping up")
        except DeviceError as err:  # told by output_problem() unless cut short by an off
            logger.debug("%s: ramp up ended: %s", self.name, err)

    def _join_ramp(self) -> None:
        """Wait for the ramp up's writes (each done within a period)."""
        thread, self._ramp_writer = self._ramp_writer, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(self._period() + 2 * self.timeout)

    def _period(self) -> float:
        return self._wave.size / self.rate if self._wave is not None else 0.0

    def _stop_internal(self) -> None:
        """Ramp down from the next buffer boundary; once the ramp is out, stop and 0 V."""
        if self._task is None or self._wave is None:
            return
        self._join_ramp()
        if self.ramp > 0 and not self._write_error:
            start = self._written
            self._write_all(self._ramp_buffers(self.level, 0.0)[:-1], "ramping down")
            ramp_end = start + round(self.ramp * self.rate)
            deadline = time.monotonic() + self._period() + self.ramp + self.timeout
            try:
                while (int(self._task.out_stream.total_samp_per_chan_generated) < ramp_end
                       and time.monotonic() < deadline):
                    time.sleep(0.01)
            except self._ni.errors.DaqError as err:
                failure = self._fail(err, "ramping down")
                self._emergency_off()
                raise failure from err
        self._output_off_internal()

    def _output_off_internal(self) -> None:
        """Stop the task and write 0 V, from a helper thread waited for ``2 timeout`` s."""
        task = self._task
        if task is None:
            return
        self._halted.set()
        failed: list[BaseException] = []
        done = threading.Event()

        def off() -> None:
            try:
                try:
                    task.stop()
                finally:
                    self._zero(task)
            except Exception as err:  # any failure is reported below
                failed.append(err)
            finally:
                done.set()

        threading.Thread(target=off, name=f"{self.name}-off", daemon=True).start()
        if not done.wait(2 * self.timeout):
            raise DeviceTimeoutError(f"{self.name}: NI-DAQmx did not stop the output within "
                                     f"{2 * self.timeout:g} s: turn the amplifier off by hand",
                                     self.name)
        if failed:
            err = failed[0]
            if int(getattr(err, "error_code", 0)) in DEVICE_GONE:  # nothing left to turn off
                logger.info("%s: output off: %s", self.name, first_line(err))
            elif isinstance(err, self._ni.errors.DaqError):
                raise self._fail(err, "turning the output off") from err
            else:
                raise err

    def _emergency_off(self) -> None:
        """Output off now (errors logged, never raised)."""
        if self._state is DeviceState.RUNNING:
            self._state = DeviceState.OPEN
        try:
            self._output_off_internal()
        except DeviceError as err:
            logger.error("%s: could not turn the output off: %s", self.name, err)

    def output_problem(self) -> str:
        """``""`` while NI-DAQmx generates, else why not (the output turned off)."""
        if self._write_error:
            return self._write_error
        if self._state is not DeviceState.RUNNING or self._task is None:
            return f"{self.name}: output is off"
        try:
            self._task.is_task_done()
        except self._ni.errors.DaqError as err:
            failure = self._fail(err, "generating")
            self._emergency_off()
            return f"{failure}; output turned off"
        return ""
