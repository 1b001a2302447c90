"""Shaker signal generator and amplifier over serial with SCPI (model "SG-1").

The driver keeps the output safe: it ramps up and down (``OUTP:RAMP``), turns
the output off on ``stop()``, on any error it sees, on ``shutdown()`` and at
interpreter exit, and arms the device's watchdog (``SYST:HEART:TIM``) with a
heartbeat thread, so the device turns itself off when the application dies
or the cable is pulled. Command set: see ``docs/protocols.md``.

Example
-------
>>> with ScpiShaker("shaker", "/dev/ttyUSB1") as shaker:  # doctest: +SKIP
...     shaker.set_waveform("random", f_start=5.0, f_stop=200.0)
...     shaker.set_level(0.5)
...     shaker.start()  # ramps up
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
from typing import Any, ClassVar

from drivers.base import DeviceState, ExcitationDevice, Waveform
from drivers.errors import (
    DeviceError,
    DeviceInitializationError,
    DeviceTimeoutError,
    ProtocolError,
)
from drivers.scpi import read_error_queue
from drivers.station import DeviceConfig, SerialTransportConfig
from drivers.transports import SerialLink

__all__ = ["ScpiShaker", "ShakerError"]

logger = logging.getLogger(__name__)

IDENTITY_PREFIX = "INSITU,SG-1,"
#: the highest level a station allows by default, V (option ``max_level``)
MAX_LEVEL = 2.0
#: what the SG-1 accepts: frequencies (Hz), the chirp and burst period and the ramp (s)
SG1_LIMITS = {"f_start": (0.0, 20000.0), "f_stop": (0.1, 20000.0), "period": (0.01, 100.0),
              "ramp": (0.0, 60.0)}
FUNCTION_CODES = {
    Waveform.RANDOM: "RAND",
    Waveform.BURST_RANDOM: "BRAN",
    Waveform.CHIRP: "CHIRP",
    Waveform.SINE: "SIN",
}


class ShakerError(DeviceError):
    """The device reported an error in its SCPI error queue (``code``, ``text``)."""

    def __init__(self, message: str, device: str | None, code: int, text: str) -> None:
        super().__init__(message, device)
        self.code = code
        self.text = text


class ScpiShaker(ExcitationDevice):
    """Driver of the SG-1 generator/amplifier.

    Parameters
    ----------
    name : str
    url : str
        Serial port or pyserial URL.
    baudrate : int
    heartbeat : float
        Watchdog time armed on the device, s; the driver sends a heartbeat four
        times per period. 0 disables the watchdog (not recommended).
    ramp : float
        Output ramp time up and down, s.
    max_level : float
        Highest level this station allows, V (checked before sending).
    reply_timeout : float
        Seconds to wait for a query's reply.
    """

    max_error_reads: ClassVar[int] = 12

    def __init__(self, name: str, url: str, *, baudrate: int = 115200, heartbeat: float = 0.5,
                 ramp: float = 1.0, max_level: float = MAX_LEVEL,
                 reply_timeout: float = 0.5) -> None:
        super().__init__(name)
        if heartbeat < 0 or ramp < 0 or max_level <= 0:
            raise ValueError(f"{name}: heartbeat and ramp must be >= 0 s, max_level > 0 V")
        self.heartbeat = heartbeat
        self.ramp = ramp
        self.max_level = max_level
        self.reply_timeout = reply_timeout
        self._link = SerialLink(url, baudrate, name)
        self._io_lock = threading.RLock()
        self._beat_stop = threading.Event()
        self._beat_thread: threading.Thread | None = None
        self.heartbeat_error: DeviceError | None = None

    @classmethod
    def from_config(cls, config: DeviceConfig, **overrides: Any) -> ScpiShaker:
        if not isinstance(config.transport, SerialTransportConfig):
            raise ValueError(f"device {config.name!r}: shaker-scpi needs a serial url")
        opts: dict[str, Any] = {"baudrate": config.transport.baudrate, **config.options,
                                **overrides}
        return cls(config.name, config.transport.url, **opts)

    @classmethod
    def setting_limits(cls, config: DeviceConfig) -> dict[str, tuple[float, float]]:
        """The SG-1's ranges, and the level up to the station's ``max_level`` option."""
        level = config.options.get("max_level", MAX_LEVEL)
        return {**SG1_LIMITS, "level": (0.0, float(level))}

    # -- SCPI -------------------------------------------------------------------------------------
    def write(self, command: str) -> None:
        """Send one SCPI command (no reply expected)."""
        with self._io_lock:
            self._link.write(command.encode("ascii") + b"\n")

    def query(self, command: str) -> str:
        """Send a query and return its reply line, stripped."""
        with self._io_lock:
            self._link.write(command.encode("ascii") + b"\n")
            return self._link.readline(self.reply_timeout).decode("ascii", "replace").strip()

    def errors(self) -> list[tuple[int, str]]:
        """Empty the device's error queue: ``[(code, text), ...]``, oldest first."""
        return read_error_queue(self.query, self.name, self.max_error_reads)

    def command(self, command: str) -> None:
        """Send a setting and check the error queue; on an error, output off and raise."""
        self._check_heartbeat()
        with self._io_lock:
            self.write(command)
            errs = self.errors()
        if errs:
            self._emergency_off()
            code, text = errs[0]
            raise ShakerError(f"{self.name}: {command!r} failed: {code} {text}", self.name,
                              code, text)

    def output_level(self) -> float:
        """The output level now (V), which lags the set level while ramping."""
        reply = self.query("OUTP:LEV?")
        try:
            return float(reply)
        except ValueError:
            raise ProtocolError(f"{self.name}: OUTP:LEV? answered {reply!r}", self.name) from None

    def output_is_on(self) -> bool:
        return self.query("OUTP?") == "1"

    def wait_ramp(self, timeout: float | None = None) -> None:
        """Block until the output level reaches the set level (after ``start()``)."""
        deadline = time.monotonic() + (timeout if timeout is not None else self.ramp + 1.0)
        while True:
            if abs(self.output_level() - self.level) <= 1e-6 * max(1.0, self.level):
                return
            if not self.output_is_on():
                errs = self.errors()
                raise ShakerError(f"{self.name}: output went off while ramping: {errs}",
                                  self.name, errs[0][0] if errs else 0,
                                  errs[0][1] if errs else "")
            if time.monotonic() > deadline:
                raise DeviceTimeoutError(f"{self.name}: ramp not done in time", self.name)
            time.sleep(0.02)

    # -- life cycle -------------------------------------------------------------------------------
    def _open_internal(self) -> None:
        self._link.open()
        try:
            self._link.reset_input()
            ident = self.query("*IDN?")
            if not ident.startswith(IDENTITY_PREFIX):
                raise DeviceInitializationError(
                    f"{self.name}: not an SG-1 shaker generator (identity {ident!r})", self.name)
            self.identity = ident
            self.write("OUTP OFF")
            self.write("*RST")
            self.write("*CLS")
            self.command(f"OUTP:RAMP {self.ramp:g}")
            self.command(f"SYST:HEART:TIM {self.heartbeat:g}")
        except BaseException:
            self._link.close()
            raise
        if self.heartbeat > 0:
            self._beat_stop.clear()
            self._beat_thread = threading.Thread(target=self._beat, name=f"{self.name}-heartbeat",
                                                 daemon=True)
            self._beat_thread.start()
        atexit.register(self.shutdown)

    def _beat(self) -> None:
        period = self.heartbeat / 4
        while not self._beat_stop.wait(period):
            try:
                self.write("SYST:HEART")
            except DeviceError as err:
                logger.error("%s: heartbeat failed, device will turn off: %s", self.name, err)
                self.heartbeat_error = err
                return

    def _check_heartbeat(self) -> None:
        if self.heartbeat_error is not None:
            raise self.heartbeat_error

    def _emergency_off(self) -> None:
        try:
            self.write("OUTP OFF")
        except DeviceError as err:
            logger.error("%s: could not turn the output off: %s", self.name, err)
        if self._state is DeviceState.RUNNING:
            self._state = DeviceState.OPEN

    def _set_waveform_internal(self, waveform: Waveform, params: dict[str, float]) -> None:
        allowed = {
            Waveform.RANDOM: {"f_start", "f_stop"},
            Waveform.BURST_RANDOM: {"f_start", "f_stop", "period", "burst"},
            Waveform.CHIRP: {"f_start", "f_stop", "period"},
            Waveform.SINE: {"frequency"},
        }[waveform]
        extra = set(params) - allowed
        if extra:
            raise ValueError(f"{self.name}: {waveform.value} takes {sorted(allowed)}, "
                             f"not {sorted(extra)}")
        self.command(f"SOUR:FUNC {FUNCTION_CODES[waveform]}")
        scpi = {"frequency": "SOUR:FREQ", "f_start": "SOUR:FREQ:STAR", "f_stop": "SOUR:FREQ:STOP",
                "period": "SOUR:PER", "burst": "SOUR:BURS:DCYC"}
        for key in sorted(params):
            self.command(f"{scpi[key]} {params[key]:g}")

    def _set_level_internal(self, level: float) -> None:
        if level > self.max_level:
            raise ValueError(f"{self.name}: level {level:g} V above the station's limit "
                             f"{self.max_level:g} V")
        self.command(f"SOUR:VOLT {level:g}")

    def _output_on_internal(self) -> None:
        if self.waveform is None:
            raise DeviceError(f"{self.name}: choose a waveform before turning the output on",
                              self.name)
        self.command("OUTP ON")

    def _output_off_internal(self) -> None:
        self.write("OUTP OFF")

    def _shutdown_internal(self) -> None:
        atexit.unregister(self.shutdown)
        self._beat_stop.set()
        beat, self._beat_thread = self._beat_thread, None
        if beat is not None:
            beat.join(1.0)
        try:
            if self._link.is_open:
                self.write("SYST:HEART:TIM 0")
        except DeviceError as err:
            logger.debug("%s: could not disarm the watchdog: %s", self.name, err)
        self._link.close()
