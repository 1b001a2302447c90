"""Device base classes: acquisition front ends and excitation devices.

Each base class has public template methods that check the state and the
arguments, log, and call one private hook that a backend implements, as
python-can's ``BusABC.recv()`` calls ``_recv_internal()``:

=====================  ============================
public                 backend hook
=====================  ============================
``open()``             ``_open_internal()``
``start()``            ``_start_internal()``
``stop()``             ``_stop_internal()``
``read_block()``       ``_read_block_internal()``
``shutdown()``         ``_shutdown_internal()``
=====================  ============================

``shutdown()`` is idempotent and every device is a context manager. An
excitation device's ``shutdown()`` always turns its output off first.

Example
-------
>>> ch = ChannelConfig("a1x", 0, "acceleration", sensitivity=10.2, node=1, direction=(1, 0, 0))
>>> ch.unit
'm/s^2'
"""

from __future__ import annotations

import enum
import logging
import threading
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from drivers.errors import DeviceError
from drivers.stream import SampleBuffer

if TYPE_CHECKING:
    from drivers.station import DeviceConfig

__all__ = [
    "QUANTITY_UNITS",
    "TIMING_SCATTER",
    "AcquisitionFrontEnd",
    "ChannelConfig",
    "Device",
    "DeviceState",
    "ExcitationDevice",
    "StreamHealth",
    "StreamingFrontEnd",
    "TimeBlock",
    "Waveform",
]

logger = logging.getLogger(__name__)

Quantity = Literal["force", "acceleration"]
#: SI unit of each measured quantity; sensitivities are in mV per this unit
QUANTITY_UNITS: dict[str, str] = {"force": "N", "acceleration": "m/s^2"}
#: largest scatter of a streaming device's frame arrival times, s, with which its clock is
#: taken for measured (station option ``timing_scatter``)
TIMING_SCATTER = 0.005


@dataclass(frozen=True)
class ChannelConfig:
    """One analogue input: what is measured, where, and how it is conditioned.

    Vocabulary as nidaqmx ``add_ai_accel_chan`` and UFF 58.

    Parameters
    ----------
    name : str
        Unique channel name, e.g. ``"a1x"``.
    input : int
        Physical input index on the device (0-based).
    quantity : {"force", "acceleration"}
    sensitivity : float
        Transducer sensitivity, mV/N or mV/(m/s^2); > 0.
    iepe : bool
        Whether the input powers an IEPE transducer (constant-current supply on).
    range_v : float
        Input range, +/- V; > 0.
    node : int, optional
        Node id of the measurement point in the geometry.
    direction : (3,) float, optional
        Measuring direction in the global frame; stored as a unit vector.
    """

    name: str
    input: int
    quantity: Quantity
    sensitivity: float
    iepe: bool = True
    range_v: float = 5.0
    node: int | None = None
    direction: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("channel name must not be empty")
        if self.quantity not in QUANTITY_UNITS:
            raise ValueError(
                f"channel {self.name!r}: quantity {self.quantity!r} is not one of "
                f"{', '.join(QUANTITY_UNITS)}"
            )
        if int(self.input) != self.input or self.input < 0:
            raise ValueError(f"channel {self.name!r}: input must be an integer >= 0")
        if not np.isfinite(self.sensitivity) or self.sensitivity <= 0:
            raise ValueError(f"channel {self.name!r}: sensitivity must be > 0 (mV per unit)")
        if not np.isfinite(self.range_v) or self.range_v <= 0:
            raise ValueError(f"channel {self.name!r}: range must be > 0 V")
        if self.direction is not None:
            d = np.asarray(self.direction, dtype=float).reshape(-1)
            norm = float(np.linalg.norm(d)) if d.size == 3 else 0.0
            if d.size != 3 or not np.isfinite(norm) or norm == 0:
                raise ValueError(f"channel {self.name!r}: direction must be a non-zero 3-vector")
            object.__setattr__(self, "direction", tuple(float(x) for x in d / norm))

    @property
    def unit(self) -> str:
        """SI unit of the physical values: ``"N"`` or ``"m/s^2"``."""
        return QUANTITY_UNITS[self.quantity]

    @property
    def full_scale(self) -> float:
        """Full-scale range in the physical unit: range (V) x 1000 / sensitivity (mV/unit)."""
        return self.range_v * 1000.0 / self.sensitivity

    def volts_to_physical(self, volts: NDArray[np.float64]) -> NDArray[np.float64]:
        """Convert input voltages (V) to physical units using the sensitivity (mV/unit)."""
        return np.asarray(volts, dtype=float) * (1000.0 / self.sensitivity)


@dataclass(frozen=True)
class TimeBlock:
    """A block of simultaneous samples from one device, in physical units.

    Attributes
    ----------
    data : (n_channels, n_samples) float64
        Samples in each channel's unit (N, m/s^2). Samples the device lost
        (sequence gaps, dropped or corrupt frames) are NaN.
    fs : float
        Nominal sampling rate of the device, Hz.
    channels : tuple of ChannelConfig
        One per row of ``data``.
    first_sample : int
        Device sample counter of ``data[:, 0]`` since the last start.
    host_time : float or None
        Host ``time.monotonic()`` by which the first sample had been taken, s: the tightest
        bound the device's latest frames give (their arrival less the samples after it at
        the nominal rate); None when unknown. Within a frame's latency of the sample's
        time; far behind the time of the read when the block comes from a backlog.
    missing : int
        Number of sample instants where at least one channel is NaN.
    overloaded : tuple of str
        Names of the channels the device reported overloaded during the block.
    """

    data: NDArray[np.float64]
    fs: float
    channels: tuple[ChannelConfig, ...]
    first_sample: int = 0
    host_time: float | None = None
    missing: int = 0
    overloaded: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        data = np.asarray(self.data, dtype=np.float64)
        if data.ndim != 2:
            raise ValueError(f"TimeBlock data must be (n_channels, n_samples), got {data.shape}")
        if data.shape[0] != len(self.channels):
            raise ValueError(
                f"TimeBlock has {data.shape[0]} rows but {len(self.channels)} channels"
            )
        if not np.isfinite(self.fs) or self.fs <= 0:
            raise ValueError(f"TimeBlock fs must be > 0 Hz, got {self.fs}")
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "overloaded", tuple(self.overloaded))

    @property
    def n_samples(self) -> int:
        return int(self.data.shape[1])

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)

    @property
    def complete(self) -> bool:
        """True when no sample is missing and no channel overloaded."""
        return self.missing == 0 and not self.overloaded

    def channel(self, name: str) -> NDArray[np.float64]:
        """The samples of channel ``name``."""
        try:
            return self.data[self.channel_names.index(name)]
        except ValueError:
            raise KeyError(
                f"no channel {name!r} in block: have {', '.join(self.channel_names)}"
            ) from None


@dataclass
class StreamHealth:
    """Counters a streaming driver keeps about what it received since ``start()``."""

    frames: int = 0
    bad_frames: int = 0
    gaps: int = 0
    lost_samples: int = 0
    resync_bytes: int = 0
    buffer_overflows: int = 0
    overloaded: set[str] = field(default_factory=set)

    def ok(self) -> bool:
        return not (self.bad_frames or self.gaps or self.lost_samples or self.buffer_overflows
                    or self.overloaded)


class DeviceState(enum.Enum):
    CLOSED = "closed"
    OPEN = "open"
    RUNNING = "running"
    SHUT_DOWN = "shut down"


class Device(ABC):
    """Common life cycle of every device: open, start, stop, shutdown.

    Parameters
    ----------
    name : str
        The device's name in the station file, used in messages and logs.
    """

    #: what ``drivers.station`` expects in the device's table ("acquisition" or "excitation")
    kind: ClassVar[str] = "device"

    def __init__(self, name: str) -> None:
        self.name = name
        self._state = DeviceState.CLOSED
        self._state_lock = threading.RLock()
        self.identity: str = ""

    # -- construction from a station file ----------------------------------------------------
    @classmethod
    @abstractmethod
    def from_config(cls, config: DeviceConfig, **overrides: Any) -> Device:
        """Build the device from its station-file entry; ``overrides`` replace options."""

    # -- life cycle ------------------------------------------------------------------------------
    @property
    def state(self) -> DeviceState:
        return self._state

    def open(self) -> None:
        """Open the transport, check the identity and configure the device."""
        with self._state_lock:
            if self._state in (DeviceState.OPEN, DeviceState.RUNNING):
                return
            if self._state is DeviceState.SHUT_DOWN:
                raise DeviceError(f"{self.name}: device was shut down; create a new one",
                                  self.name)
            self._open_internal()
            self._state = DeviceState.OPEN
            logger.info("%s: opened %s", self.name, self.identity or type(self).__name__)

    def start(self) -> None:
        """Start streaming (acquisition) or output (excitation)."""
        with self._state_lock:
            if self._state is DeviceState.RUNNING:
                return
            self._require(DeviceState.OPEN, "start")
            self._start_internal()
            self._state = DeviceState.RUNNING
            logger.info("%s: started", self.name)

    def stop(self) -> None:
        """Stop streaming or output; the device stays open and configured."""
        with self._state_lock:
            if self._state is not DeviceState.RUNNING:
                return
            self._state = DeviceState.OPEN
            self._stop_internal()
            logger.info("%s: stopped", self.name)

    def shutdown(self) -> None:
        """Stop and release the device; safe to call any number of times."""
        with self._state_lock:
            if self._state is DeviceState.SHUT_DOWN:
                return
            was = self._state
            self._state = DeviceState.SHUT_DOWN
        try:
            if was is DeviceState.RUNNING:
                try:
                    self._stop_internal()
                except DeviceError as err:
                    logger.warning("%s: stop during shutdown failed: %s", self.name, err)
        finally:
            self._shutdown_internal()
            logger.info("%s: shut down", self.name)

    def __enter__(self) -> Device:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.shutdown()

    def _require(self, state: DeviceState, action: str) -> None:
        if self._state is not state:
            raise DeviceError(
                f"{self.name}: cannot {action} while {self._state.value} "
                f"(needs {state.value})", self.name
            )

    # -- backend hooks ---------------------------------------------------------------------------
    @abstractmethod
    def _open_internal(self) -> None: ...

    @abstractmethod
    def _start_internal(self) -> None: ...

    @abstractmethod
    def _stop_internal(self) -> None: ...

    @abstractmethod
    def _shutdown_internal(self) -> None:
        """Release the transport. Called once, whatever state the device is in."""


class AcquisitionFrontEnd(Device):
    """A device that digitises channels and streams them to the host.

    Parameters
    ----------
    name : str
    channels : sequence of ChannelConfig
        The inputs to read, in the order of the rows of every :class:`TimeBlock`.
    fs : float
        Requested sampling rate, Hz.
    """

    kind: ClassVar[str] = "acquisition"
    #: sampling rates the device supports, Hz (empty: any)
    supported_rates: ClassVar[tuple[float, ...]] = ()
    #: number of physical inputs of the device
    n_inputs: ClassVar[int] = 1

    def __init__(self, name: str, channels: Sequence[ChannelConfig], fs: float) -> None:
        super().__init__(name)
        chans = tuple(channels)
        if not chans:
            raise ValueError(f"{name}: give at least one channel")
        names = [c.name for c in chans]
        if len(set(names)) != len(names):
            raise ValueError(f"{name}: duplicate channel names {sorted(names)}")
        inputs = [c.input for c in chans]
        if len(set(inputs)) != len(inputs):
            raise ValueError(f"{name}: two channels use the same input")
        if max(inputs) >= self.n_inputs:
            raise ValueError(
                f"{name}: input {max(inputs)} does not exist (device has {self.n_inputs})"
            )
        if self.supported_rates and fs not in self.supported_rates:
            raise ValueError(
                f"{name}: fs={fs} Hz not supported; choose one of "
                f"{', '.join(f'{r:g}' for r in self.supported_rates)}"
            )
        if fs <= 0:
            raise ValueError(f"{name}: fs must be > 0 Hz")
        self.channels = chans
        self.fs = float(fs)
        self.health = StreamHealth()

    def read_block(self, n_samples: int, timeout: float = 2.0) -> TimeBlock:
        """Read the next ``n_samples`` samples of every channel.

        Blocks until they are in or ``timeout`` (s) has passed since the call,
        then raises :class:`~drivers.errors.DeviceTimeoutError`. Consecutive
        blocks are contiguous: ``first_sample`` of one is the previous one's plus
        its length.
        """
        if n_samples <= 0:
            raise ValueError(f"n_samples must be > 0, got {n_samples}")
        if timeout <= 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout}")
        self._require(DeviceState.RUNNING, "read")
        block = self._read_block_internal(int(n_samples), float(timeout))
        if block.data.shape != (len(self.channels), n_samples):
            raise AssertionError(f"{self.name}: backend returned {block.data.shape}")
        logger.debug("%s: block of %d samples from #%d (%d missing%s)", self.name, n_samples,
                     block.first_sample, block.missing,
                     f", overloaded {','.join(block.overloaded)}" if block.overloaded else "")
        return block

    @abstractmethod
    def _read_block_internal(self, n_samples: int, timeout: float) -> TimeBlock: ...


class StreamingFrontEnd(AcquisitionFrontEnd):
    """A front end whose reader thread streams samples into a :class:`~drivers.stream.SampleBuffer`.

    The base owns the buffer (``self._buffer``: the backend's reader thread appends to it,
    resets it at start and stores its failure in it), reads blocks out of it, and gives the
    timing pairs from which :mod:`drivers.sync` fits the device clock.

    Parameters
    ----------
    name, channels, fs : as :class:`AcquisitionFrontEnd`
    stall_timeout : float
        Seconds without any sample after which a read raises DeviceTimeoutError.
    timing_scatter : float
        Largest scatter of the frames' host arrival times (s) with which the device's clock
        is still taken for measured (:func:`drivers.sync.check_alignment`, ``max_residual``):
        a hit whose streams are aligned by host timing needs it.
    """

    def __init__(self, name: str, channels: Sequence[ChannelConfig], fs: float, *,
                 stall_timeout: float = 0.5, timing_scatter: float = TIMING_SCATTER) -> None:
        super().__init__(name, channels, fs)
        self.stall_timeout = stall_timeout
        self.timing_scatter = timing_scatter
        self._buffer = SampleBuffer(len(self.channels), name)

    def clock_pairs(self) -> list[tuple[float, int]]:
        """(host arrival time, s; samples received) per frame or block, for :mod:`drivers.sync`."""
        return self._buffer.pairs()

    def _read_block_internal(self, n_samples: int, timeout: float) -> TimeBlock:
        data, first, missing, ovl = self._buffer.take(n_samples, timeout, self.stall_timeout)
        return TimeBlock(data, self.fs, self.channels, first,
                         self._buffer.taken_by(first, self.fs), missing,
                         tuple(self.channels[i].name for i in sorted(ovl)))


class Waveform(enum.Enum):
    """Drive signals an excitation device can produce."""

    RANDOM = "random"
    BURST_RANDOM = "burst-random"
    CHIRP = "chirp"
    SINE = "sine"


class ExcitationDevice(Device):
    """A device that drives the structure (shaker with its generator and amplifier).

    ``start()`` turns the output on (ramped), ``stop()`` turns it off (ramped);
    ``shutdown()`` always turns it off, whatever happened before.
    """

    kind: ClassVar[str] = "excitation"

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.waveform: Waveform | None = None
        self.level: float = 0.0

    @classmethod
    def setting_limits(cls, config: DeviceConfig) -> dict[str, tuple[float, float]]:
        """The range each setting may take on the device ``config`` describes, without
        opening it: ``{"level": (0.0, 2.0), ...}`` (V, Hz and s, by the names of
        :meth:`set_waveform`, ``level`` and ``ramp``); a setting not listed has no known
        limit. A run checks its plan against them before it starts."""
        return {}

    def set_waveform(self, waveform: Waveform | str, **params: float) -> None:
        """Choose the drive signal; ``params`` are waveform settings (``frequency``,
        ``f_start``, ``f_stop``, ``duration``, ``burst``), in Hz, s and fraction."""
        wf = Waveform(waveform)
        for key, value in params.items():
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{self.name}: {key} must be a finite value >= 0, got {value}")
        self._require(DeviceState.OPEN, "change the waveform")
        self._set_waveform_internal(wf, dict(params))
        self.waveform = wf
        logger.info("%s: waveform %s %s", self.name, wf.value, params or "")

    def set_level(self, level: float) -> None:
        """Set the output level (V RMS for random, V peak for sine and chirp)."""
        if not np.isfinite(level) or level < 0:
            raise ValueError(f"{self.name}: level must be >= 0, got {level}")
        if self._state not in (DeviceState.OPEN, DeviceState.RUNNING):
            self._require(DeviceState.OPEN, "set the level")
        self._set_level_internal(float(level))
        self.level = float(level)
        logger.info("%s: level %g", self.name, level)

    def output_problem(self) -> str:
        """``""`` while the output is on, else why it is not; a backend that can ask its
        device whether it still drives (its error queue, its task) does so, turning the
        output off when it finds an error."""
        return "" if self._state is DeviceState.RUNNING else f"{self.name}: output is off"

    def shutdown(self) -> None:
        """Turn the output off (always, even if not started) and release the device."""
        with self._state_lock:
            if self._state is DeviceState.SHUT_DOWN:
                return
            if self._state is not DeviceState.CLOSED:
                try:
                    self._output_off_internal()
                except DeviceError as err:
                    logger.warning("%s: output off during shutdown failed: %s", self.name, err)
                if self._state is DeviceState.RUNNING:
                    self._state = DeviceState.OPEN
        super().shutdown()

    def _start_internal(self) -> None:
        self._output_on_internal()

    def _stop_internal(self) -> None:
        self._output_off_internal()

    @abstractmethod
    def _set_waveform_internal(self, waveform: Waveform, params: dict[str, float]) -> None: ...

    @abstractmethod
    def _set_level_internal(self, level: float) -> None: ...

    @abstractmethod
    def _output_on_internal(self) -> None: ...

    @abstractmethod
    def _output_off_internal(self) -> None:
        """Turn the output off; must work in any open state and be safe to repeat."""
