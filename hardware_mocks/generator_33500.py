"""Simulated Keysight 33500-series function generator: SCPI over a TCP socket on 127.0.0.1.

The generator's raw SCPI port (5025 on a real one) on an ephemeral port: PyVISA opens it
as ``TCPIP0::127.0.0.1::PORT::SOCKET`` (:attr:`Generator33500.resource`). One command per
line (LF); queries answer one LF-terminated line; settings answer nothing and report a
failure in the error queue (``SYST:ERR?``), as the 33500 does. The subset it speaks (an
optional ``SOUR:``/``SOUR1:`` prefix and a leading ``:`` are accepted; short forms only)::

    *IDN?  *RST  *CLS  SYST:ERR?            -> +0,"No error" when the queue is empty
    OUTP ON|OFF|1|0   OUTP?                 OUTP:LOAD INF|<ohm>   OUTP:LOAD?
    FUNC SIN|NOIS|ARB FUNC?                 FREQ <Hz>             FUNC:NOIS:BAND <Hz>
    VOLT <value>      VOLT?                 VOLT:UNIT VPP|VRMS    VOLT:OFFS <V>
    DATA:VOL:CLE      DATA:ARB:DAC <name>,<counts>...    DATA:ARB <name>,<-1..1>...
    FUNC:ARB <name>   FUNC:ARB:SRAT <Sa/s>

Error codes: ``-113`` undefined header, ``-221`` settings conflict (clearing the waveform
memory while an arbitrary waveform plays, a name already in memory), ``-222`` data out of
range, ``-224`` illegal parameter value, ``-350`` queue overflow (20 entries). Like the real
instrument it has no watchdog and no ramp: the output keeps its state on an error, when
the host goes away and when nobody talks to it.

Given a :class:`~hardware_mocks.physics.BenchPhysics` it is the generator of an amplifier
and shaker on the bench (:class:`~hardware_mocks.bench_drive.BenchDrive`): attached to an
excitation DOF it pushes with ``force_per_volt`` times its output voltage: sine, noise (the
random multisine of :meth:`~hardware_mocks.bench_drive.BenchDrive.multisine`, flat from
0 Hz to the noise bandwidth, at the RMS set, VPP read as 2 sqrt(2) V RMS) or the selected
arbitrary waveform, played at its sample rate (linear between samples) over and over.
Faults: :attr:`Generator33500.silent` (stops reading and answering), :meth:`push_error`
(an error in the queue), :meth:`drop` (closes the connection).

Example
-------
>>> with Generator33500() as gen:  # doctest: +SKIP
...     print(gen.resource)  # open with drivers.generator_visa.VisaGenerator, backend "@py"
"""

from __future__ import annotations

import logging
import selectors
import socket
import threading
import time
from collections import deque
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.bench_drive import BenchDrive
from hardware_mocks.physics import BenchPhysics

__all__ = ["IDENTITY", "Generator33500"]

logger = logging.getLogger(__name__)

IDENTITY = "Keysight Technologies,33511B,SIM0000001,4.00-3.05-1.19-2.00-52-00"
ERRORS = {
    -113: "Undefined header",
    -221: "Settings conflict",
    -222: "Data out of range",
    -224: "Illegal parameter value",
    -350: "Queue overflow",
}
QUEUE = 20
MAX_VPP = {"INF": 20.0, "50": 10.0}
DAC_FULL = 32767
_NUMBERS = {  # header -> attribute, low, high
    "FREQ": ("frequency", 1e-6, 20e6),
    "FUNC:NOIS:BAND": ("band", 0.001, 20e6),
    "FUNC:ARB:SRAT": ("srate", 1e-6, 160e6),
    "VOLT:OFFS": ("offset", 0.0, 0.0),  # the bench's amplifier takes no offset
}


class Generator33500(BenchDrive):
    """The 33500 as seen from its LAN socket, and as a force source on the bench.

    Parameters
    ----------
    physics : BenchPhysics, optional
        The bench to drive; without it the generator drives nothing.
    force_per_volt : float
        Force on the structure per volt of output, N/V (amplifier and shaker).
    seed, sensor : int
        As :class:`~hardware_mocks.bench_drive.BenchDrive`.
    exc : int, optional
        Excitation DOF index it is attached to at first (None: detached).
    """

    def __init__(self, physics: BenchPhysics | None = None, *, force_per_volt: float = 50.0,
                 seed: int = 0, sensor: int = 0, exc: int | None = None) -> None:
        super().__init__(physics, force_per_volt, seed, sensor)
        self.commands: list[str] = []
        #: stop reading and answering (commands wait in the socket until it is cleared)
        self.silent = False
        self.arbs: dict[str, NDArray[np.float64]] = {}
        self._errors: deque[int] = deque()
        self._error_text: dict[int, str] = {}
        self._lock = threading.Lock()
        self._t_origin = time.monotonic()
        self._reset()
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = int(self._listener.getsockname()[1])
        self._client: socket.socket | None = None
        self._rx = bytearray()
        self._stop = threading.Event()
        self._drop = threading.Event()
        self.connections = 0
        self._thread = threading.Thread(target=self._run, name="mock-33500", daemon=True)
        self._thread.start()
        if exc is not None:
            self.attach(exc)

    def _reset(self) -> None:
        self.function = "SIN"
        self.frequency = 1000.0
        self.band = 1e6
        self.srate = 40e3
        self.arb: str | None = None
        self.unit = "VPP"
        self.volt = 0.1
        self.offset = 0.0
        self.load = "50"
        self.output = False
        self._on_since = time.monotonic()  # when the output last came on

    @property
    def resource(self) -> str:
        """The VISA resource string of its socket."""
        return f"TCPIP0::127.0.0.1::{self.port}::SOCKET"

    @property
    def errors(self) -> list[int]:
        """Codes waiting in the error queue."""
        with self._lock:
            return list(self._errors)

    def push_error(self, code: int, text: str) -> None:
        """Put an error in the queue, as the instrument does when something goes wrong."""
        with self._lock:
            self._error_text[code] = text
            self._fail(code)

    def drop(self) -> None:
        """Close the host's connection (a pulled LAN cable); returns once it is closed."""
        self._drop.set()
        deadline = time.monotonic() + 2.0
        while self._drop.is_set() and time.monotonic() < deadline:
            time.sleep(0.005)

    # -- the output on the bench ------------------------------------------------------------------
    def peak_volts(self) -> float:
        """Peak output now, V (0 while the output is off)."""
        with self._lock:
            return self._peak() if self.output else 0.0

    def _peak(self) -> float:
        if self.function == "NOIS":
            rms = self.volt if self.unit == "VRMS" else self.volt / (2 * np.sqrt(2))
            return float(rms)  # the noise is unit RMS: its "peak" scale is its RMS
        if self.function == "ARB" and self.unit == "VRMS":
            wave = self.arbs.get(self.arb or "")
            rms = float(np.sqrt(np.mean(wave**2))) if wave is not None and wave.size else 1.0
            return float(self.volt / max(rms, 1e-12))
        return float(self.volt / 2 if self.unit == "VPP" else self.volt * np.sqrt(2))

    def force(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Force on the structure (N) at host instants ``t`` (s, ``time.monotonic()``); 0 before
        the output came on (a front end started just before asks for its past)."""
        t = np.asarray(t, dtype=float)
        out = np.zeros_like(t)
        with self._lock:
            if not self.output:
                return out
            scale = self._peak()
            func, f_sine, band, srate = self.function, self.frequency, self.band, self.srate
            wave = self.arbs.get(self.arb or "")
            on = np.flatnonzero(t >= self._on_since)
        tau = t[on] - self._t_origin
        if func == "SIN":
            unit = np.sin(2 * np.pi * f_sine * tau)
        elif func == "NOIS":
            unit = self.multisine(tau, 0.0, band)
        elif wave is None or wave.size == 0:
            unit = np.zeros_like(tau)
        else:
            pos = np.mod(tau * srate, wave.size)
            k = np.floor(pos).astype(np.int64)
            frac = pos - k
            unit = wave[k] * (1 - frac) + wave[(k + 1) % wave.size] * frac
        out[on] = self.force_per_volt * scale * unit
        return out

    # -- firmware ---------------------------------------------------------------------------------
    def _fail(self, code: int) -> None:
        if len(self._errors) >= QUEUE:
            self._errors[-1] = -350
        else:
            self._errors.append(code)

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._listener, selectors.EVENT_READ)
        try:
            while not self._stop.is_set():
                if self._drop.is_set():
                    self._close_client(sel)
                    self._drop.clear()
                for key, _ in sel.select(0.01):
                    if key.fileobj is self._listener:
                        self._accept(sel)
                    elif self.silent:  # the bytes wait in the socket
                        time.sleep(0.01)
                    else:
                        self._receive(sel)
        finally:
            # what the host sent before the end is read, as the instrument would have (its
            # last commands wait in the socket when the shutdown comes first)
            while (self._client is not None and not self.silent
                   and any(key.fileobj is self._client for key, _ in sel.select(0))):
                self._receive(sel)
            self._close_client(sel)
            sel.close()
            self._listener.close()

    def _accept(self, sel: selectors.BaseSelector) -> None:
        conn, _ = self._listener.accept()
        self._close_client(sel)  # one host at a time: a new connection replaces the old
        self._client = conn
        self.connections += 1
        sel.register(conn, selectors.EVENT_READ)

    def _close_client(self, sel: selectors.BaseSelector) -> None:
        client, self._client = self._client, None
        self._rx.clear()
        if client is not None:
            sel.unregister(client)
            client.close()

    def _receive(self, sel: selectors.BaseSelector) -> None:
        assert self._client is not None
        try:
            data = self._client.recv(65536)
        except OSError:
            data = b""
        if not data:  # the host closed its end
            self._close_client(sel)
            return
        self._rx += data
        while b"\n" in self._rx and not self.silent:
            line, _, rest = self._rx.partition(b"\n")
            self._rx = bytearray(rest)
            with self._lock:
                reply = self._command(line.decode("ascii", "replace").strip())
            if reply is not None:
                try:
                    self._client.sendall(reply.encode("ascii") + b"\n")
                except OSError:
                    self._close_client(sel)
                    return

    def _command(self, cmd: str) -> str | None:
        if not cmd:
            return None
        self.commands.append(cmd if len(cmd) <= 80 else cmd[:80] + "...")
        head, _, arg = cmd.partition(" ")
        head = head.upper().lstrip(":")
        for prefix in ("SOUR1:", "SOUR:"):
            head = head.removeprefix(prefix)
        arg = arg.strip()
        queries = {
            "*IDN?": lambda: IDENTITY, "OUTP?": lambda: "1" if self.output else "0",
            "FUNC?": lambda: self.function, "VOLT?": lambda: f"{self.volt:+.9E}",
            "OUTP:LOAD?": lambda: "9.9E+37" if self.load == "INF" else f"{self.load}",
            "SYST:ERR?": self._next_error,
        }
        if head in queries:
            return queries[head]()
        if head == "*RST":
            self._reset()
        elif head == "*CLS":
            self._errors.clear()
        elif head.startswith("DATA:"):
            self._data(head, arg)
        else:
            self._setting(head, arg)
        return None

    def _next_error(self) -> str:
        code = self._errors.popleft() if self._errors else 0
        text = self._error_text.get(code) or ERRORS.get(code, "No error")
        return f'{code:+d},"{text}"'

    def _choice(self, arg: str, allowed: tuple[str, ...]) -> str | None:
        word = arg.upper()
        if word in allowed:
            return word
        self._fail(-224)
        return None

    def _setting(self, head: str, arg: str) -> None:
        if head == "OUTP":
            if (word := self._choice(arg, ("ON", "OFF", "1", "0"))) is not None:
                on = word in ("ON", "1")
                if on and not self.output:
                    self._on_since = time.monotonic()
                self.output = on
        elif head == "FUNC":
            if (word := self._choice(arg, ("SIN", "NOIS", "ARB"))) is not None:
                if word == "ARB" and self.arb is None:
                    self._fail(-221)
                else:
                    self.function = word
        elif head == "FUNC:ARB":
            if arg.upper() in self.arbs:
                self.arb = arg.upper()
            else:
                self._fail(-224)
        elif head == "VOLT:UNIT":
            if (word := self._choice(arg, ("VPP", "VRMS"))) is not None:
                self.unit = word
        elif head == "OUTP:LOAD":
            self._set_load(arg)
        elif head == "VOLT":
            self._set_volt(arg)
        elif head in _NUMBERS:
            attr, low, high = _NUMBERS[head]
            value = self._number(arg, low, high)
            if value is not None:
                setattr(self, attr, value)
        else:
            self._fail(-113)

    def _set_load(self, arg: str) -> None:
        if arg.upper() in ("INF", "9.9E+37"):
            self.load = "INF"
        elif self._number(arg, 50.0, 50.0) is not None:  # the simulated amplifier: 50 or INF
            self.load = "50"

    def _set_volt(self, arg: str) -> None:
        per_vpp = 1.0 if self.unit == "VPP" else 2 * np.sqrt(2)
        value = self._number(arg, 0.001 / per_vpp, MAX_VPP[self.load] / per_vpp)
        if value is not None:
            self.volt = value

    def _data(self, head: str, arg: str) -> None:
        if head == "DATA:VOL:CLE":
            if self.function == "ARB":
                self._fail(-221)
            else:
                self.arbs.clear()
                self.arb = None
            return
        if head not in ("DATA:ARB:DAC", "DATA:ARB"):
            self._fail(-113)
            return
        name, _, values = arg.partition(",")
        name = name.strip().upper()
        try:
            wave = np.array([float(v) for v in values.split(",")])
        except ValueError:
            self._fail(-224)
            return
        if head == "DATA:ARB:DAC":
            wave = wave / DAC_FULL
        if not name or name in self.arbs:
            self._fail(-221)
        elif wave.size < 8 or not np.all(np.abs(wave) <= 1.0):
            self._fail(-222)
        else:
            self.arbs[name] = wave

    # -- life -------------------------------------------------------------------------------------
    def shutdown(self) -> None:
        """Stop the firmware, close the socket and leave the bench (idempotent)."""
        self.detach_from_bench()
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(2.0)

    def __enter__(self) -> Generator33500:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.shutdown()
