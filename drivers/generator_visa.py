"""A bench function generator driving the shaker's amplifier, through PyVISA (Keysight 33500).

Backend ``generator-visa``: an Agilent/Keysight 33500- or 33600-series generator
(``*IDN?`` ``Agilent Technologies,335..`` or ``Keysight Technologies,336..``) on LAN, USB
or GPIB, its output (channel 1) wired to the shaker amplifier's input. The resource string
and the PyVISA backend come from the station file::

    [devices.shaker]
    backend = "generator-visa"
    transport = { visa = "TCPIP0::192.168.1.20::5025::SOCKET", backend = "@py" }
    options = { max_level = 1.0, load = "INF" }

How each waveform is made (commands of the 33500 manual, one per line):

============== ====================================================================
random         ``FUNC NOIS``, ``FUNC:NOIS:BAND <f_stop>``; level ``VOLT:UNIT VRMS``.
               The 33500's noise is flat from DC to its bandwidth: ``f_start`` is not
               a lower band edge here.
burst random   an arbitrary waveform: ``bursts`` different bursts of band-limited noise
               (:func:`processing.excitation.burst_random`), each on for ``burst`` of its
               ``period`` and silent for the rest, uploaded with ``DATA:VOL:CLE``,
               ``DATA:ARB:DAC INSITU,<counts>``, ``FUNC:ARB INSITU``, ``FUNC ARB``,
               ``FUNC:ARB:SRAT <Sa/s>`` and played over and over. (The 33500 gates its
               noise only with an external gate signal, ``BURS:MODE GAT``; an arbitrary
               waveform needs no wiring.) Level ``VOLT:UNIT VPP``: twice the RMS within
               the bursts times their crest factor.
chirp          an arbitrary waveform too, one linear sweep a period
               (:func:`processing.excitation.periodic_chirp`, whose band edges are rounded
               so the phase closes on itself): it repeats sample for sample, so every
               block of one period is leakage-free (a ``SWE`` sweep is phase-continuous
               across its return and repeats only when a period holds whole cycles).
               Level ``VOLT:UNIT VPP``, twice the peak.
sine           ``FUNC SIN``, ``FREQ <Hz>``; level ``VOLT:UNIT VPP``, twice the peak.
============== ====================================================================

Every batch of settings is followed by ``SYST:ERR?`` until ``+0,"No error"``. The 33500
has no watchdog and no output ramp: the driver turns the output off (``OUTP OFF``) on
``stop()``, on any error it reads, on a reply that does not come in time, on
``shutdown()`` and at interpreter exit (``atexit``; the command line turns SIGTERM and
SIGHUP into a stop, which shuts the devices down). An ``OUTP OFF`` never waits more than
``reply_timeout`` s for a silent or unplugged generator. A host that dies without running
any of these (``kill -9``, a power cut) leaves the output on: see ``docs/hardware.md``.

Example
-------
>>> with VisaGenerator("shaker", "TCPIP0::192.168.1.20::5025::SOCKET") as gen:  # doctest: +SKIP
...     gen.set_waveform("random", f_start=5.0, f_stop=200.0)
...     gen.set_level(0.5)  # V RMS
...     gen.start()
"""

from __future__ import annotations

import atexit
import logging
import math
import re
import threading
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from drivers.base import DeviceState, ExcitationDevice, Waveform
from drivers.errors import (
    DeviceError,
    DeviceInitializationError,
    DeviceNotAvailableError,
    DeviceTimeoutError,
    one_line,
)
from drivers.scpi import read_error_queue
from drivers.station import DeviceConfig, VisaTransportConfig

__all__ = ["GeneratorError", "VisaGenerator"]

logger = logging.getLogger(__name__)

#: what ``*IDN?`` starts with: maker, then a 33500- or 33600-series model
IDENTITY = re.compile(r"^(Agilent|Keysight) Technologies,33[56]\d\d[A-Z]?,")
INSTALL = "pip install 'insitu[visa]'"
#: the highest level a station allows by default, V (option ``max_level``)
MAX_LEVEL = 2.0
#: the 33500's largest output, V peak to peak, by load (``OUTP:LOAD``)
MAX_VPP = {"INF": 20.0, "50": 10.0}
MIN_VPP = 0.001
#: noise bandwidth, sine frequency (the lowest top of the 33500 and 33600 families), Hz
MAX_FREQUENCY = 20e6
#: what the driver accepts (frequencies in Hz)
LIMITS = {"f_start": (0.0, MAX_FREQUENCY), "f_stop": (0.001, MAX_FREQUENCY),
          "frequency": (1e-6, MAX_FREQUENCY)}
#: arbitrary waveforms: samples per cycle at the top frequency, the 33500B's sample rates
ARB_SAMPLES_PER_CYCLE = 20
ARB_RATES = (1e-6, 160e6)
ARB_NAME = "INSITU"
DAC_FULL = 32767
_PARAMS = {
    Waveform.RANDOM: {"f_start", "f_stop"},
    Waveform.BURST_RANDOM: {"f_start", "f_stop", "period", "burst"},
    Waveform.CHIRP: {"f_start", "f_stop", "period"},
    Waveform.SINE: {"frequency"},
}


class GeneratorError(DeviceError):
    """The generator reported an error in its SCPI error queue (``code``, ``text``)."""

    def __init__(self, message: str, device: str | None, code: int, text: str) -> None:
        super().__init__(message, device)
        self.code = code
        self.text = text


def _import_pyvisa(name: str) -> Any:
    try:
        import pyvisa
    except ImportError as err:
        raise DeviceNotAvailableError(f"{name}: the generator-visa backend needs PyVISA, "
                                      f"which is not installed: {INSTALL}", name) from err
    return pyvisa


class VisaGenerator(ExcitationDevice):
    """Driver of a Keysight 33500-series function generator feeding a shaker amplifier.

    Parameters
    ----------
    name : str
    resource : str
        VISA resource string, e.g. ``"TCPIP0::192.168.1.20::5025::SOCKET"`` (LAN, raw
        SCPI port), ``"TCPIP0::192.168.1.20::inst0::INSTR"`` (VXI-11) or
        ``"USB0::0x0957::0x2C07::MY52400000::INSTR"``.
    backend : str, optional
        PyVISA backend: ``"@py"`` (pyvisa-py), ``"@ivi"`` (an installed VISA library),
        ``"file.yaml@sim"`` (pyvisa-sim); None: PyVISA's default.
    resource_manager : pyvisa.ResourceManager, optional
        Use this one instead of opening one (tests); not closed by the driver.
    max_level : float
        Highest level this station allows, V (RMS for random, peak for sine and chirp).
    load : {"INF", 50}
        ``OUTP:LOAD``: the amplifier's input impedance as the generator sees it (INF for
        a high-impedance input, so the set voltage is the voltage at the amplifier).
    reply_timeout : float
        Seconds to wait for a reply (and at most for an ``OUTP OFF`` to go out).
    bursts : int
        Burst random: different bursts in the uploaded waveform, played in turn.
    arb_points : int
        Most samples of an uploaded waveform (the 33500B holds 1 MSa a channel; 65536
        keeps an upload short on any link).
    seed : int
        Seed of the bursts' noise.
    """

    max_error_reads: ClassVar[int] = 20

    def __init__(self, name: str, resource: str, *, backend: str | None = None,
                 resource_manager: Any = None, max_level: float = MAX_LEVEL,
                 load: str | int = "INF", reply_timeout: float = 2.0, bursts: int = 4,
                 arb_points: int = 65536, seed: int = 0) -> None:
        super().__init__(name)
        self._pyvisa = _import_pyvisa(name)
        load_key = str(load).upper()
        if load_key not in MAX_VPP:
            raise ValueError(f"{name}: load must be \"INF\" or 50 (ohm), got {load!r}")
        if max_level <= 0 or reply_timeout <= 0 or bursts < 1 or arb_points < 8:
            raise ValueError(f"{name}: max_level and reply_timeout must be > 0, bursts >= 1, "
                             "arb_points >= 8")
        self.resource = resource
        self.backend = backend
        self.max_level = float(max_level)
        self.load = load_key
        self.reply_timeout = float(reply_timeout)
        self.bursts = int(bursts)
        self.arb_points = int(arb_points)
        self.seed = int(seed)
        self._rm = resource_manager
        self._own_rm = resource_manager is None
        self._inst: Any = None
        self._io_lock = threading.RLock()
        self._stale = False  # a reply timed out: what comes in next may be its late answer
        #: the amplitude unit of the waveform set and volts of it per volt of level
        self._unit, self._per_level = "VPP", 2.0

    @classmethod
    def from_config(cls, config: DeviceConfig, **overrides: Any) -> VisaGenerator:
        if not isinstance(config.transport, VisaTransportConfig):
            raise ValueError(f"device {config.name!r}: generator-visa needs a VISA resource "
                             "(transport = { visa = \"TCPIP0::HOST::5025::SOCKET\" })")
        opts: dict[str, Any] = {"resource": config.transport.resource,
                                "backend": config.transport.backend, **config.options,
                                **overrides}  # a simulated station's own socket, say
        return cls(config.name, **opts)

    @classmethod
    def setting_limits(cls, config: DeviceConfig) -> dict[str, tuple[float, float]]:
        """The 33500's frequency ranges, and the level up to the station's ``max_level``."""
        level = config.options.get("max_level", MAX_LEVEL)
        return {**LIMITS, "level": (0.0, float(level))}

    # -- SCPI -------------------------------------------------------------------------------------
    def _fail(self, err: Exception, what: str) -> DeviceError:
        """The one-line error for a VISA failure while doing ``what``."""
        code = getattr(err, "error_code", None)
        if code == self._pyvisa.constants.StatusCode.error_timeout:
            self._stale = True
            return DeviceTimeoutError(f"{self.name}: no answer from the generator to {what} "
                                      f"within {self.reply_timeout:g} s: check that it is on "
                                      f"and reachable at {self.resource}", self.name)
        text = one_line(str(err).splitlines()[0] if str(err) else type(err).__name__)
        if not self.identity:  # pyvisa-py connects lazily: a refused connection shows here
            return DeviceNotAvailableError(f"{self.name}: cannot open {self.resource} ({text}): "
                                           "check the resource string and that the generator "
                                           "is on and reachable", self.name)
        return DeviceNotAvailableError(f"{self.name}: lost the generator at {self.resource} "
                                       f"during {what} ({text}): check the cable or network",
                                       self.name)

    def _io(self, command: str, reply: bool) -> str:
        if self._inst is None:
            raise DeviceError(f"{self.name}: not open", self.name)
        errors = (self._pyvisa.errors.VisaIOError, OSError)
        with self._io_lock:
            try:
                if self._stale and reply:
                    self._drop_late_replies()
                if not reply:
                    self._inst.write(command)
                    return ""
                return str(self._inst.query(command)).strip()
            except errors as err:
                failure = self._fail(err, repr(command[:40]))
        if self.identity:  # configured: its output may be on
            self._emergency_off()
        raise failure

    def _drop_late_replies(self) -> None:
        """After a reply timed out: clear the session, so that the next query does not
        read the late answer to the last one."""
        self._stale = False
        try:
            self._inst.clear()
        except (self._pyvisa.errors.VisaIOError, NotImplementedError) as err:
            logger.debug("%s: clear after a timeout: %s", self.name, err)

    def write(self, command: str) -> None:
        """Send one SCPI command (no reply expected)."""
        self._io(command, reply=False)

    def query(self, command: str) -> str:
        """Send a query and return its reply, stripped."""
        return self._io(command, reply=True)

    def errors(self) -> list[tuple[int, str]]:
        """Empty the generator's error queue: ``[(code, text), ...]``, oldest first."""
        return read_error_queue(self.query, self.name, self.max_error_reads)

    def command(self, *commands: str) -> None:
        """Send a batch of settings, then read the error queue; on an error, output off and
        raise :class:`GeneratorError` naming the first error."""
        with self._io_lock:
            for c in commands:
                self.write(c)
            errs = self.errors()
        if errs:
            self._emergency_off()
            code, text = errs[0]
            what = commands[0] if len(commands) == 1 else f"{commands[0]} ... {commands[-1]}"
            raise GeneratorError(f"{self.name}: the generator refused {what[:60]!r}: {code} "
                                 f"{text}; output turned off", self.name, code, text)

    def output_is_on(self) -> bool:
        return self.query("OUTP?").strip() in ("1", "ON")

    def output_problem(self) -> str:
        """``""`` while the output is on with no error queued, else why not (an error turns
        the output off). Raises a :class:`DeviceError` when the generator does not answer."""
        errs = self.errors()
        if errs:
            self._emergency_off()
            why = "; ".join(f"{c} {t}" for c, t in errs)
            return f"{self.name}: generator error {why}; output turned off"
        if not self.output_is_on():
            return f"{self.name}: the generator's output went off (front panel or another " \
                   "program)"
        return ""

    # -- life cycle -------------------------------------------------------------------------------
    def _open_internal(self) -> None:
        pv = self._pyvisa
        if self._rm is None:
            try:
                self._rm = pv.ResourceManager(*([self.backend] if self.backend else []))
            except (ValueError, OSError) as err:
                why = one_line(str(err).splitlines()[0] if str(err) else type(err).__name__)
                raise DeviceNotAvailableError(
                    f"{self.name}: no VISA library for backend {self.backend or 'default'} "
                    f"({why}): {INSTALL} gives PyVISA with pyvisa-py (backend \"@py\")",
                    self.name) from err
        try:
            self._inst = self._rm.open_resource(
                self.resource, read_termination="\n", write_termination="\n",
                timeout=round(self.reply_timeout * 1000), open_timeout=round(
                    self.reply_timeout * 1000))
        except (pv.errors.Error, ValueError, OSError) as err:
            why = one_line(str(err).splitlines()[0] if str(err) else type(err).__name__)
            self._release()
            raise DeviceNotAvailableError(f"{self.name}: cannot open {self.resource} ({why}): "
                                          "check the resource string and that the generator "
                                          "is on and reachable", self.name) from err
        try:
            self._configure()
        except BaseException:
            self._release()
            raise
        atexit.register(self.shutdown)

    def _configure(self) -> None:
        ident = self.query("*IDN?")
        if not IDENTITY.match(ident):
            raise DeviceInitializationError(
                f"{self.name}: {self.resource} is not a Keysight 33500/33600 generator "
                f"(identity {ident[:60]!r})", self.name)
        self.identity = ident
        self.write("OUTP OFF")
        self.write("*RST")
        self.write("*CLS")
        self.command(f"OUTP:LOAD {self.load}", "VOLT:OFFS 0")

    def _emergency_off(self) -> None:
        """``OUTP OFF`` now, never waiting more than ``reply_timeout`` s (errors logged)."""
        if self._state is DeviceState.RUNNING:
            self._state = DeviceState.OPEN
        try:
            self._off_bounded()
        except DeviceError as err:
            logger.error("%s: could not turn the output off: %s", self.name, err)

    def _off_bounded(self) -> None:
        """``OUTP OFF`` from a helper thread, waited for ``2 reply_timeout`` s at most (a
        backend's write may block on a generator that stopped reading)."""
        inst = self._inst
        if inst is None:
            return
        mine = self._io_lock.acquire(blocking=False)  # free, or held by this thread
        failed: list[Exception] = []
        done = threading.Event()

        def send() -> None:
            locked = mine or self._io_lock.acquire(timeout=self.reply_timeout)
            try:
                inst.write("OUTP OFF")
            except Exception as err:  # any failure of the link is reported below
                failed.append(err)
            finally:
                if locked and not mine:
                    self._io_lock.release()
                done.set()

        try:
            threading.Thread(target=send, name=f"{self.name}-off", daemon=True).start()
            if not done.wait(2 * self.reply_timeout):
                raise DeviceTimeoutError(f"{self.name}: OUTP OFF not sent within "
                                         f"{2 * self.reply_timeout:g} s: turn the generator's "
                                         "output off by hand", self.name)
        finally:
            if mine:
                self._io_lock.release()
        if failed:
            raise self._fail(failed[0], "OUTP OFF")

    def _set_waveform_internal(self, waveform: Waveform, params: dict[str, float]) -> None:
        allowed = _PARAMS[waveform]
        extra = set(params) - allowed
        if extra:
            raise ValueError(f"{self.name}: {waveform.value} takes {sorted(allowed)}, "
                             f"not {sorted(extra)}")
        self._check_ranges(params)
        if waveform is Waveform.SINE:
            self.command("FUNC SIN", f"FREQ {params.get('frequency', 1000.0):.9g}")
            self._unit, self._per_level = "VPP", 2.0
        elif waveform is Waveform.RANDOM:
            self.command("FUNC NOIS", f"FUNC:NOIS:BAND {params.get('f_stop', 200.0):.9g}")
            self._unit, self._per_level = "VRMS", 1.0
        else:
            counts, rate, per_level = self._arbitrary(waveform, params)
            # the arb playing cannot be cleared: a built-in function first
            self.command("FUNC SIN", "DATA:VOL:CLE")
            self.command(f"DATA:ARB:DAC {ARB_NAME}," + ",".join(map(str, counts.tolist())),
                         f"FUNC:ARB {ARB_NAME}", "FUNC ARB", f"FUNC:ARB:SRAT {rate:.9g}")
            self._unit, self._per_level = "VPP", per_level
        if self.level > 0:  # the level's meaning changed with the waveform: set it again
            self._set_level_internal(self.level)

    def _check_ranges(self, params: dict[str, float]) -> None:
        for key, (low, high) in LIMITS.items():
            if key in params and not low <= params[key] <= high:
                raise ValueError(f"{self.name}: {key} {params[key]:g} Hz outside the "
                                 f"generator's {low:g}..{high:g} Hz")

    def _arbitrary(self, waveform: Waveform, params: dict[str, float]
                   ) -> tuple[NDArray[np.int64], float, float]:
        """DAC counts of a chirp or burst-random waveform, its sample rate (Sa/s) and the
        volts peak to peak per volt of level."""
        from processing.excitation import burst_random, periodic_chirp

        f0, f1 = params.get("f_start", 0.0), params.get("f_stop", 200.0)
        period = params.get("period", 1.0)
        n_periods = self.bursts if waveform is Waveform.BURST_RANDOM else 1
        n = max(8, math.ceil(period * ARB_SAMPLES_PER_CYCLE * f1))
        rate = n / period
        if n * n_periods > self.arb_points or not ARB_RATES[0] <= rate <= ARB_RATES[1]:
            raise ValueError(f"{self.name}: a {waveform.value} to {f1:g} Hz over {period:g} s "
                             f"needs {n * n_periods} samples at {rate:.6g} Sa/s, beyond the "
                             f"{self.arb_points} (option arb_points) the generator is given: "
                             "shorten the block (nperseg) or lower f_stop")
        if waveform is Waveform.CHIRP:
            x = periodic_chirp(1, n, rate, band=(f0, f1))
            return np.round(x * DAC_FULL).astype(np.int64), rate, 2.0
        x = burst_random(n_periods, n, rate, burst_fraction=params.get("burst", 0.5),
                         band=(f0, f1), seed=self.seed)[0]
        peak = float(np.max(np.abs(x)))  # x is unit RMS within the bursts
        return np.round(x / peak * DAC_FULL).astype(np.int64), rate, 2.0 * peak

    def _set_level_internal(self, level: float) -> None:
        if level > self.max_level:
            raise ValueError(f"{self.name}: level {level:g} V above the station's limit "
                             f"{self.max_level:g} V (option max_level)")
        value = level * self._per_level
        vpp = value * (2 * math.sqrt(2) if self._unit == "VRMS" else 1.0)
        if vpp > MAX_VPP[self.load] or value < MIN_VPP:
            raise ValueError(f"{self.name}: level {level:g} V is {value:.4g} {self._unit} for "
                             f"this waveform, outside the generator's {MIN_VPP:g}.."
                             f"{MAX_VPP[self.load]:g} Vpp into load {self.load}")
        self.command(f"VOLT:UNIT {self._unit}", f"VOLT {value:.6g}")

    def _output_on_internal(self) -> None:
        if self.waveform is None:
            raise DeviceError(f"{self.name}: choose a waveform before turning the output on",
                              self.name)
        self.command("OUTP ON")

    def _output_off_internal(self) -> None:
        self._off_bounded()

    def _release(self) -> None:
        inst, self._inst = self._inst, None
        try:
            if inst is not None:
                inst.close()
            if self._own_rm and self._rm is not None:
                self._rm.close()
        except (self._pyvisa.errors.Error, OSError) as err:
            logger.debug("%s: closing the VISA session: %s", self.name, err)
        if self._own_rm:
            self._rm = None

    def _shutdown_internal(self) -> None:
        atexit.unregister(self.shutdown)
        self._release()
