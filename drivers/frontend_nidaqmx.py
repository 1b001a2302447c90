"""NI-DAQmx front end: IEPE modules (NI 9234 class) in a CompactDAQ chassis, through nidaqmx.

The hammer's force sensor and the triaxial accelerometers sit on the modules' inputs. One
NI-DAQmx task holds every channel of the device: a force channel
(``add_ai_force_iepe_chan``, N) per ``quantity = "force"`` and an accelerometer channel
(``add_ai_accel_chan``, m/s^2) per ``quantity = "acceleration"``; NI-DAQmx scales the
samples itself from the sensitivities the station file gives. A continuous sample clock
fills NI-DAQmx's buffer, and an every-N-samples event (ten a second) reads each N samples
with ``AnalogMultiChannelReader.read_many_sample`` into the
:class:`~drivers.stream.SampleBuffer` of :class:`~drivers.base.StreamingFrontEnd`: the
streaming contract of the CAN front end, so the procedures run unchanged (the hammer's
hits are found on the stream by the procedure's software pre-trigger,
:mod:`app.acquire.streams`).

Station file::

    [devices.frontend]
    backend = "frontend-nidaqmx"
    fs = 2048
    transport = { nidaqmx = ["cDAQ1Mod1", "cDAQ1Mod2", "cDAQ1Mod3", "cDAQ1Mod4"] }
    options = { coupling = "AC", excitation_current = 0.002, teds = false }

Input ``k`` is ``ai{k % channels_per_module}`` of module ``k // channels_per_module`` in
the transport's list (4 inputs a module, as the NI 9234). Options (all optional):

====================  ==========================================================  =======
option                meaning                                                     default
====================  ==========================================================  =======
channels_per_module   inputs of each module                                       4
coupling              ``"AC"`` or ``"DC"``, every channel                          ``"AC"``
excitation_current    IEPE current, A, on the channels with ``iepe = true``       0.002
teds                  true (every channel) or a list of channel names whose       false
                      sensors carry TEDS: their sensitivity is read from the
                      sensor and must match the station file's within 1 %
samples_per_event     samples read at each every-N-samples event                  fs / 10
buffer_seconds        NI-DAQmx's input buffer, s                                  10
stall_timeout         s without samples before a read fails                       0.5
timing_scatter        s of scatter in the reads' arrival times with which the     0.005
                      clock counts as measured (a separate force device's hits)
====================  ==========================================================  =======

Sensitivities stay in the station file's units, mV/N and mV/(m/s^2); NI-DAQmx takes an
accelerometer's in mV/g, :func:`accel_sensitivity_mv_per_g` converts (standard gravity
9.80665 m/s^2). Each channel's range is the station's ``range`` (V) as a physical
full scale, ``+/- range x 1000 / sensitivity``; a sample at or beyond it (within the last
8 codes of a 24-bit converter) marks the block's channel overloaded, as the CAN front end's
overload flags do. The rate NI-DAQmx reports after configuring the clock must be the
station's ``fs``: the modules' rates are steps (NI 9234: 51.2 kHz / n), and a coerced rate
is refused in one line.

The nidaqmx API is injected (``api=``: an object with nidaqmx's ``Task``, ``constants``,
``errors``, ``stream_readers`` and ``system``), by default the ``nidaqmx`` package, imported
when the device opens: without it, one line names ``pip install 'insitu[ni]'``.

Example
-------
>>> fe = NiDaqFrontEnd("fe", channels, fs=2048, devices=["cDAQ1Mod1"])  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Sequence
from typing import Any, ClassVar

import numpy as np

from drivers import nidaqmx_common
from drivers.base import TIMING_SCATTER, ChannelConfig, StreamHealth, StreamingFrontEnd, TimeBlock
from drivers.errors import (
    DeviceError,
    DeviceInitializationError,
    DeviceTimeoutError,
)
from drivers.nidaqmx_common import INSTALL, close_task, daq_error, device_options, new_task
from drivers.station import DeviceConfig, NiDaqTransportConfig

__all__ = ["INSTALL", "OVERLOAD_FRACTION", "STANDARD_GRAVITY", "NiDaqFrontEnd",
           "accel_sensitivity_mv_per_g", "import_nidaqmx"]

logger = logging.getLogger(__name__)

#: m/s^2 in one g (NI-DAQmx's g, the standard gravity)
STANDARD_GRAVITY = 9.80665
#: a sample at or beyond this fraction of the range is an overload (the last 8 codes of 24 bits)
OVERLOAD_FRACTION = 1.0 - 8.0 / 2**23
#: NI-DAQmx's error for samples overwritten before they were read
SAMPLES_OVERWRITTEN = -200279

OPTIONS = ("api", "channels_per_module", "coupling", "excitation_current", "teds",
           "samples_per_event", "buffer_seconds", "stall_timeout", "timing_scatter")


def accel_sensitivity_mv_per_g(mv_per_si: float) -> float:
    """An accelerometer's sensitivity in mV/g from mV/(m/s^2).

    >>> round(accel_sensitivity_mv_per_g(10.2), 5)
    100.02783
    """
    return float(mv_per_si) * STANDARD_GRAVITY


def import_nidaqmx(device: str) -> Any:
    """The ``nidaqmx`` package with the modules the driver uses; one line naming the
    install when it is missing."""
    return nidaqmx_common.import_nidaqmx(device, "frontend-nidaqmx",
                   ("constants", "errors", "stream_readers", "system"))


def _member(enum: Any, *names: str) -> Any:
    """The first of ``names`` that ``enum`` has (members renamed between nidaqmx releases)."""
    for name in names:
        if hasattr(enum, name):
            return getattr(enum, name)
    raise AttributeError(f"{enum.__name__} has none of {', '.join(names)}")


class NiDaqFrontEnd(StreamingFrontEnd):
    """IEPE channels of NI-DAQmx modules, streamed on a continuous sample clock.

    Parameters
    ----------
    name : str
    channels : sequence of ChannelConfig
        ``input`` numbers the modules' inputs in the order of ``devices``.
    fs : float
        Sampling rate, Hz; NI-DAQmx must run it exactly.
    devices : sequence of str
        Module names as NI MAX shows them (``"cDAQ1Mod1"``).
    api : object, optional
        The nidaqmx API (default: the ``nidaqmx`` package, imported at ``open()``).
    channels_per_module : int
    coupling : {"AC", "DC"}
    excitation_current : float
        IEPE excitation, A (channels with ``iepe``; the others get none).
    teds : bool or sequence of str
        Channels whose sensors carry TEDS (True: all).
    samples_per_event : int, optional
        Samples per every-N-samples event (default ``fs / 10``).
    buffer_seconds : float
        NI-DAQmx input buffer, s.
    stall_timeout : float
        Seconds without samples after which a read raises.
    timing_scatter : float
        Largest scatter of the reads' arrival times, s, with which the clock counts as
        measured (:class:`~drivers.base.StreamingFrontEnd`).
    """

    #: the module inputs are checked against ``devices`` and ``channels_per_module``
    n_inputs: ClassVar[int] = 1 << 16

    def __init__(self, name: str, channels: Sequence[ChannelConfig], fs: float, *,
                 devices: Sequence[str], api: Any = None, channels_per_module: int = 4,
                 coupling: str = "AC", excitation_current: float = 0.002,
                 teds: bool | Iterable[str] = False, samples_per_event: int | None = None,
                 buffer_seconds: float = 10.0, stall_timeout: float = 0.5,
                 timing_scatter: float = TIMING_SCATTER) -> None:
        super().__init__(name, channels, fs, stall_timeout=stall_timeout,
                         timing_scatter=timing_scatter)
        self.devices = tuple(devices)
        if not self.devices:
            raise ValueError(f"{name}: give the NI-DAQmx module names (transport nidaqmx)")
        if isinstance(channels_per_module, bool) or not (
                isinstance(channels_per_module, int) and channels_per_module > 0):
            raise ValueError(f"{name}: channels_per_module must be an integer > 0, got "
                             f"{channels_per_module!r}")
        self.channels_per_module = channels_per_module
        top = len(self.devices) * channels_per_module
        for ch in self.channels:
            if ch.input >= top:
                raise ValueError(f"{name}: channel {ch.name!r} is on input {ch.input}, but "
                                 f"{len(self.devices)} module(s) of {channels_per_module} "
                                 f"inputs have {top} (0..{top - 1}): add its module to "
                                 "transport nidaqmx")
        if coupling not in ("AC", "DC"):
            raise ValueError(f"{name}: coupling must be \"AC\" or \"DC\", got {coupling!r}")
        self.coupling = coupling
        if not (isinstance(excitation_current, int | float)
                and not isinstance(excitation_current, bool) and excitation_current > 0):
            raise ValueError(f"{name}: excitation_current must be > 0 A, got "
                             f"{excitation_current!r}")
        self.excitation_current = float(excitation_current)
        names = [c.name for c in self.channels]
        if isinstance(teds, bool):
            self.teds = frozenset(names if teds else ())
        elif isinstance(teds, str) or not all(isinstance(t, str) for t in teds):
            raise ValueError(f"{name}: teds must be true, false or a list of channel names")
        else:
            self.teds = frozenset(teds)
            if unknown := sorted(self.teds - set(names)):
                raise ValueError(f"{name}: teds names {', '.join(unknown)}, not channels of "
                                 f"this device ({', '.join(names)})")
        n_event = max(1, round(self.fs / 10)) if samples_per_event is None else samples_per_event
        if isinstance(n_event, bool) or not isinstance(n_event, int) or n_event < 1:
            raise ValueError(f"{name}: samples_per_event must be an integer >= 1, got "
                             f"{samples_per_event!r}")
        self.samples_per_event = n_event
        if not buffer_seconds > 0:
            raise ValueError(f"{name}: buffer_seconds must be > 0, got {buffer_seconds!r}")
        self.buffer_seconds = float(buffer_seconds)
        self._api = api
        self._ni: Any = None
        self._task: Any = None
        self._reader: Any = None
        self._streaming = False
        self._limits = np.array([c.full_scale * OVERLOAD_FRACTION for c in self.channels])
        #: the sample rate NI-DAQmx reported, Hz (after open)
        self.actual_rate = 0.0

    @classmethod
    def from_config(cls, config: DeviceConfig, **overrides: Any) -> NiDaqFrontEnd:
        if not isinstance(config.transport, NiDaqTransportConfig):
            raise ValueError(f"device {config.name!r}: frontend-nidaqmx needs transport = "
                             "{ nidaqmx = [module names] }")
        if config.fs is None:
            raise ValueError(f"device {config.name!r}: give fs (Hz), a rate the modules run "
                             "exactly (NI 9234: 51200 / n)")
        opts = device_options(config, overrides, OPTIONS)
        return cls(config.name, config.channels, config.fs, devices=config.transport.devices,
                   **opts)

    def physical_channel(self, ch: ChannelConfig) -> str:
        """The NI-DAQmx physical channel of ``ch``: ``"cDAQ1Mod2/ai1"``."""
        module, ai = divmod(ch.input, self.channels_per_module)
        return f"{self.devices[module]}/ai{ai}"

    # -- errors -----------------------------------------------------------------------------------
    def _daq_error(self, err: BaseException, doing: str) -> DeviceError:
        """One line for an NI-DAQmx error raised while ``doing``."""
        code = int(getattr(err, "error_code", 0))
        if code == SAMPLES_OVERWRITTEN:
            return DeviceError(
                f"{self.name}: {doing}: samples lost, NI-DAQmx overwrote its buffer before "
                f"they were read (error {code}): the host read too slowly; raise "
                "buffer_seconds", self.name)
        return daq_error(self.name, self.devices, err, doing)

    # -- life cycle -------------------------------------------------------------------------------
    def _open_internal(self) -> None:
        ni = self._api if self._api is not None else import_nidaqmx(self.name)
        self._ni = ni
        task = new_task(ni, self.name, self.devices)
        self._task = task
        try:
            self._configure(ni, task)
        except BaseException:
            self._close_task()
            raise
        self.identity = f"NI-DAQmx {', '.join(self.devices)} at {self.actual_rate:g} Hz"

    def _configure(self, ni: Any, task: Any) -> None:
        c = ni.constants
        coupling = c.Coupling.AC if self.coupling == "AC" else c.Coupling.DC
        for ch in self.channels:
            phys = self.physical_channel(ch)
            try:
                chan = self._add_channel(ni, task, ch, phys)
                chan.ai_coupling = coupling
            except ni.errors.DaqError as err:
                raise self._daq_error(err, f"channel {ch.name} ({phys})") from err
            if ch.name in self.teds:
                self._check_teds(ch, chan)
        try:
            task.timing.cfg_samp_clk_timing(
                self.fs, sample_mode=c.AcquisitionType.CONTINUOUS,
                samps_per_chan=max(round(self.buffer_seconds * self.fs),
                                   4 * self.samples_per_event))
            self.actual_rate = float(task.timing.samp_clk_rate)
        except ni.errors.DaqError as err:
            raise self._daq_error(err, f"sample clock at {self.fs:g} Hz") from err
        if abs(self.actual_rate - self.fs) > 1e-6 * self.fs:
            raise DeviceInitializationError(
                f"{self.name}: NI-DAQmx runs {', '.join(self.devices)} at "
                f"{self.actual_rate:.6g} Hz, not the {self.fs:g} Hz asked (the modules' rates "
                "are steps, NI 9234: 51200 / n Hz): set fs and the plan's record.fs to a rate "
                "they run exactly, e.g. 2048", self.name)
        try:
            self._reader = ni.stream_readers.AnalogMultiChannelReader(task.in_stream)
            task.register_every_n_samples_acquired_into_buffer_event(
                self.samples_per_event, self._on_samples)
        except ni.errors.DaqError as err:
            raise self._daq_error(err, "every-N-samples event") from err

    def _add_channel(self, ni: Any, task: Any, ch: ChannelConfig, phys: str) -> Any:
        """Create ``ch``'s NI-DAQmx channel: IEPE force (N) or accelerometer (m/s^2)."""
        c = ni.constants
        fsc = ch.full_scale
        excite = {"current_excit_source": c.ExcitationSource.INTERNAL if ch.iepe
                  else c.ExcitationSource.NONE,
                  "current_excit_val": self.excitation_current if ch.iepe else 0.0}
        ai = task.ai_channels
        if ch.name in self.teds:
            ni.system.PhysicalChannel(phys).configure_teds()
            if ch.quantity == "force":
                return ai.add_teds_ai_force_iepe_chan(
                    phys, name_to_assign_to_channel=ch.name, min_val=-fsc, max_val=fsc,
                    units=c.ForceUnits.NEWTONS, **excite)
            return ai.add_teds_ai_accel_chan(
                phys, name_to_assign_to_channel=ch.name, min_val=-fsc, max_val=fsc,
                units=c.AccelUnits.METERS_PER_SECOND_SQUARED, **excite)
        if ch.quantity == "force":
            return ai.add_ai_force_iepe_chan(
                phys, name_to_assign_to_channel=ch.name, min_val=-fsc, max_val=fsc,
                units=c.ForceUnits.NEWTONS, sensitivity=ch.sensitivity,
                sensitivity_units=_member(c.ForceIEPESensorSensitivityUnits,
                                          "MILLIVOLTS_PER_NEWTON", "M_VOLTS_PER_NEWTON"),
                **excite)
        return ai.add_ai_accel_chan(
            phys, name_to_assign_to_channel=ch.name, min_val=-fsc, max_val=fsc,
            units=c.AccelUnits.METERS_PER_SECOND_SQUARED,
            sensitivity=accel_sensitivity_mv_per_g(ch.sensitivity),
            sensitivity_units=_member(c.AccelSensitivityUnits, "MILLIVOLTS_PER_G",
                                      "M_VOLTS_PER_G"),
            **excite)

    def _check_teds(self, ch: ChannelConfig, chan: Any) -> None:
        """A TEDS sensor's sensitivity must be the station file's (the run file keeps that)."""
        if ch.quantity == "force":
            teds = float(chan.ai_force_iepe_sensor_sensitivity)
            unit = "mV/N"
        else:
            teds = float(chan.ai_accel_sensitivity) / STANDARD_GRAVITY
            unit = "mV/(m/s^2)"
        if not abs(teds - ch.sensitivity) <= 0.01 * ch.sensitivity:
            raise DeviceInitializationError(
                f"{self.name}: channel {ch.name}: the sensor's TEDS gives {teds:.5g} {unit}, "
                f"the station file {ch.sensitivity:g}: put the TEDS value in the station file",
                self.name)

    def _start_internal(self) -> None:
        self.health = StreamHealth()
        self._buffer.reset()
        self._streaming = True
        try:
            self._task.start()
        except self._ni.errors.DaqError as err:
            self._streaming = False
            raise self._daq_error(err, "starting") from err

    def _stop_internal(self) -> None:
        self._streaming = False
        try:
            self._task.stop()
        except self._ni.errors.DaqError as err:
            raise self._daq_error(err, "stopping") from err

    def _shutdown_internal(self) -> None:
        self._streaming = False
        self._close_task()

    def _close_task(self) -> None:
        task, self._task = self._task, None
        close_task(task, self._ni, self.name)

    # -- streaming --------------------------------------------------------------------------------
    def _on_samples(self, task_handle: Any, event_type: int, n_samples: int,
                    callback_data: Any) -> int:
        """NI-DAQmx's every-N-samples callback: read the N samples into the buffer."""
        if not self._streaming:
            return 0
        try:
            data = np.empty((len(self.channels), n_samples))
            got = int(self._reader.read_many_sample(
                data, number_of_samples_per_channel=n_samples, timeout=self.stall_timeout))
            t_rx = time.monotonic()
            data = data[:, :got]
            with np.errstate(invalid="ignore"):
                over = np.flatnonzero((np.abs(data) >= self._limits[:, None]).any(axis=1))
            for i in over:
                self.health.overloaded.add(self.channels[i].name)
            self.health.frames += 1
            self._buffer.append(data, t_rx, frozenset(int(i) for i in over))
        except self._ni.errors.DaqError as err:
            self._streaming = False
            self._buffer.fail(self._daq_error(err, "reading"))
        except Exception as err:  # never lost: the next read raises it
            logger.exception("%s: every-N-samples callback failed", self.name)
            self._buffer.fail(err)
        return 0

    def _read_block_internal(self, n_samples: int, timeout: float) -> TimeBlock:
        try:
            return super()._read_block_internal(n_samples, timeout)
        except DeviceTimeoutError as stall:
            # no event came: NI-DAQmx keeps why the task stopped (a module removed)
            try:
                self._task.is_task_done()
            except self._ni.errors.DaqError as err:
                raise self._daq_error(err, "streaming") from stall
            raise
