"""What the mock devices share: the bench's physics on the host's clock, and device clocks.

:class:`BenchPhysics` holds a bench (body on mounts with its geometry) and the
hits made on it, timed on the host's ``time.monotonic()`` clock. Every mock
samples this one physical world with its own :class:`DeviceClock`, so the
hammer digitiser sees the force pulse of a hit and the front end sees the
accelerations the model predicts for it, each on its own sample grid.

A hit is a half-sine force pulse ``peak * sin(pi (t - t0) / duration)`` for
``t0 <= t <= t0 + duration``. Devices sample it as its mean over each sample
interval (an ideal anti-alias box filter), which is exact to integrate. The built-in
benches are hit with a hard tip (:data:`TIP_DURATION`, :data:`TIP_PEAK`): its force
stays within 20 dB of its peak up to 1.30 / duration (:func:`pulse_band`).

Continuous excitation (a shaker) is a :class:`ForceSource` added with
:meth:`BenchPhysics.add_source`: anything with an ``exc`` attribute (the
excitation DOF it drives, or None while detached) and a ``force(t)`` method
giving its force (N) at host instants. Responses are linear convolutions with
the model's band-limited impulse responses (:func:`hardware_mocks.signals.simulate`,
which never wraps around), cached per sample rate and excitation DOF.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hardware_mocks.benches import Bench
from hardware_mocks.signals import ImpulseResponse, impulse_response, simulate

__all__ = ["HEARTBEAT", "REPLY_TIMEOUT", "STALL_TIMEOUT", "TIMING_SCATTER", "TIP_DURATION",
           "TIP_PEAK",
           "BenchPhysics", "DeviceClock", "ForceSource", "Hit", "pulse_band", "sampled_pulse"]

# The mock devices are threads on the host the acquisition shares with other work: on a
# loaded machine (load 10 on 2 cores) a mock front end's frames came up to 0.27 s apart
# (20 s of streaming), and a mock's answer or the worker's heartbeat can be as late. The
# drivers of a mock bench are given these times (station options); a real device's keep
# their own (0.5 s each).
#: seconds of silence after which a driver takes a mock device for stopped (``stall_timeout``)
STALL_TIMEOUT = 2.0
#: seconds a driver waits for a mock device's answer to a command (``reply_timeout``)
REPLY_TIMEOUT = 2.0
#: scatter of a mock device's frame arrival times, s, with which a driver still takes its
#: clock for measured (``timing_scatter``; a real device's 5 ms): a mock's frames leave late
#: at the source when the host is loaded, which a real device's never do (at load 7 on 2
#: cores a mock front end scattered by 25 ms and a hammer run paused; in a plain ``make test``
#: on 2 cores the serial mock hammer once scattered by 277 ms): a quarter of STALL_TIMEOUT
TIMING_SCATTER = 0.5
#: the watchdog armed on a mock shaker, s (``heartbeat``): its output goes off when nobody
#: has fed it for this long
HEARTBEAT = 2.0


class ForceSource(Protocol):
    """A continuous force on the bench, e.g. a shaker: see :meth:`BenchPhysics.add_source`."""

    @property
    def exc(self) -> int | None:
        """Excitation DOF index the source drives, or None while it is detached."""
        ...

    def force(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Force (N) at host instants ``t`` (s, ``time.monotonic()``)."""
        ...


#: s, the built-in benches' hammer pulse: a hard tip whose force is 20 dB under its peak at
#: 521 Hz (:func:`pulse_band`), above the Nyquist frequency of every built-in plan (their
#: band is fs / 2.56 = 400 Hz at 1024 Hz; the force is 12 dB down there, sampling included);
#: a 4 ms (soft) pulse was 20 dB down from 325 Hz and had its spectral zero (1.5 / duration,
#: 375 Hz) inside that band. Not shorter: the mock devices sample a pulse as its mean over
#: each sample (no anti-alias filter), so a force channel on another device (the hammer's
#: 4096 Hz digitiser, resampled) misses what folds into the front end's band from above its
#: Nyquist frequency; from a 1 ms pulse that was 2.8 % of the force on the mass line (the
#: mass 0.7 % off), from this one 0.13 % (4 ms: 0.1 %).
TIP_DURATION = 0.0025
#: N, the tip's peak: the impulse ``2 peak duration / pi`` (0.51 N s) of the same swing as the
#: former 200 N, 4 ms pulse (a harder tip shortens the contact and raises the peak, the
#: momentum given stays), so the force under the rigid-body modes is as before.
TIP_PEAK = 320.0


def pulse_band(duration: float, drop_db: float = 20.0) -> float:
    """Hz: the frequency up to which a half-sine pulse of ``duration`` s keeps its force
    spectrum within ``drop_db`` of its value at 0 Hz.

    The pulse's spectrum relative to 0 Hz is ``cos(pi x) / (1 - 4 x^2)``, ``x = f duration``,
    falling monotonically to its first zero at ``x = 1.5``; 20 dB (0.1) is reached at
    ``x = 1.30``. (A device's sampling, the mean over each sample, takes off another
    ``sinc(f / fs)``: 2.3 dB at 400 Hz of 1024 Hz.)

    >>> round(pulse_band(0.001))
    1300
    """
    if not duration > 0 or not drop_db > 0:
        raise ValueError(f"duration and drop_db must be positive, got {duration}, {drop_db}")
    from scipy.optimize import brentq

    level = 10.0 ** (-drop_db / 20.0)
    if level >= np.pi / 4:  # reached on the flat top, before x = 0.5
        lo, hi = 1e-9, 0.5 - 1e-9
    else:
        lo, hi = 0.5 + 1e-9, 1.5
    x = brentq(lambda x: np.cos(np.pi * x) / (1.0 - 4.0 * x * x) - level, lo, hi, xtol=1e-12)
    return float(x) / duration


@dataclass(frozen=True)
class Hit:
    """One hammer impact: pulse start ``t0`` (host s), excitation DOF index, peak N, duration s."""

    t0: float
    exc: int
    peak: float
    duration: float


def _pulse_integral(t: NDArray[np.float64], hit: Hit) -> NDArray[np.float64]:
    u = np.clip((t - hit.t0) / hit.duration, 0.0, 1.0)
    return hit.peak * hit.duration / np.pi * (1.0 - np.cos(np.pi * u))


def sampled_pulse(t: ArrayLike, dt: float, hits: list[Hit]) -> NDArray[np.float64]:
    """Force samples at host instants ``t`` (s): each pulse's mean over ``[t - dt/2, t + dt/2]``."""
    t = np.asarray(t, dtype=float)
    out = np.zeros_like(t)
    for hit in hits:
        out += (_pulse_integral(t + dt / 2, hit) - _pulse_integral(t - dt / 2, hit)) / dt
    return out


class DeviceClock:
    """A device's sample clock relative to the host's ``time.monotonic()``.

    Sample ``k`` after a start at host time ``t_start`` is taken at
    ``t_start + offset + k / (fs * (1 + ppm * 1e-6))``.

    Parameters
    ----------
    fs : float
        Nominal rate, Hz.
    ppm : float
        Clock error, parts per million (positive: the device runs fast).
    offset : float
        Delay between the start command and the first sample, s.
    """

    def __init__(self, fs: float, ppm: float = 0.0, offset: float = 0.0) -> None:
        self.fs = fs
        self.ppm = ppm
        self.offset = offset
        self.t_first = 0.0

    @property
    def true_rate(self) -> float:
        return self.fs * (1.0 + self.ppm * 1e-6)

    def start(self, now: float | None = None) -> None:
        self.t_first = (time.monotonic() if now is None else now) + self.offset

    def due(self, now: float | None = None) -> int:
        """How many samples have been taken by host time ``now``."""
        now = time.monotonic() if now is None else now
        return max(0, int(np.floor((now - self.t_first) * self.true_rate)) + 1)

    def instants(self, first: int, n: int) -> NDArray[np.float64]:
        """Host times of samples ``first .. first + n - 1``."""
        return self.t_first + (first + np.arange(n)) / self.true_rate


class BenchPhysics:
    """The bench as the mocks see it: a model, its measurement geometry and the hits made.

    Parameters
    ----------
    bench : Bench
        From :func:`hardware_mocks.benches.get_bench`.
    """

    def __init__(self, bench: Bench) -> None:
        self.bench = bench
        g = bench.geometry
        self.resp_xyz = g.coordinates(bench.resp_nodes)
        self.exc_xyz = g.coordinates(bench.exc_nodes)
        self._hits: list[Hit] = []
        self._sources: list[ForceSource] = []
        self._irs: dict[tuple[float, int], ImpulseResponse] = {}
        self._lock = threading.Lock()

    def hit(self, exc: int = 0, peak: float = TIP_PEAK, duration: float = TIP_DURATION,
            delay: float = 0.05, double: tuple[float, float] | None = None) -> list[Hit]:
        """Hit excitation DOF ``exc`` ``delay`` s from now.

        ``double = (gap s, ratio)`` adds a rebound: a second pulse ``gap`` s after
        the first, ``ratio`` times as strong (a double hit).
        """
        if not 0 <= exc < len(self.bench.exc_nodes):
            n = len(self.bench.exc_nodes)
            raise ValueError(f"excitation index {exc} out of range 0..{n - 1}")
        t0 = time.monotonic() + delay
        hits = [Hit(t0, exc, peak, duration)]
        if double is not None:
            gap, ratio = double
            hits.append(Hit(t0 + gap, exc, peak * ratio, duration))
        with self._lock:
            self._hits.extend(hits)
        return hits

    def hits(self, since: int = 0) -> list[Hit]:
        """Hits made so far, from index ``since`` on (consumers keep their own cursor)."""
        with self._lock:
            return self._hits[since:]

    def force(self, t: ArrayLike, dt: float) -> NDArray[np.float64]:
        """Hammer force (N) sampled at host instants ``t`` with sample interval ``dt``."""
        return sampled_pulse(t, dt, self.hits())

    def add_source(self, source: ForceSource) -> None:
        """Add a continuous force source (a shaker); its ``exc`` may change at any time."""
        with self._lock:
            if source not in self._sources:
                self._sources.append(source)

    def remove_source(self, source: ForceSource) -> None:
        with self._lock:
            if source in self._sources:
                self._sources.remove(source)

    def source_forces(self, t: NDArray[np.float64]
                      ) -> list[tuple[int, int | None, NDArray[np.float64]]]:
        """``(excitation DOF, force sensor, force N)`` of each attached source at host instants
        ``t``; the sensor is the source's ``sensor`` attribute (None without one)."""
        with self._lock:
            sources = list(self._sources)
        out = []
        n = len(self.bench.exc_nodes)
        for src in sources:
            exc = src.exc
            if exc is None:
                continue
            if not 0 <= exc < n:
                raise ValueError(f"force source drives excitation {exc}, "
                                 f"out of range 0..{n - 1}")
            out.append((exc, getattr(src, "sensor", None),
                        np.asarray(src.force(t), dtype=float)))
        return out

    def continuous_force(self, t: NDArray[np.float64]) -> dict[int, NDArray[np.float64]]:
        """Force (N) of the attached sources at host instants ``t``, by excitation DOF."""
        with self._lock:
            sources = list(self._sources)
        out: dict[int, NDArray[np.float64]] = {}
        for src in sources:
            exc = src.exc
            if exc is None:
                continue
            if not 0 <= exc < len(self.bench.exc_nodes):
                raise ValueError(f"force source drives excitation {exc}, "
                                 f"out of range 0..{len(self.bench.exc_nodes) - 1}")
            f = np.asarray(src.force(t), dtype=float)
            out[exc] = out[exc] + f if exc in out else f
        return out

    def impulse_response(self, fs: float, exc: int) -> ImpulseResponse:
        """Band-limited impulse responses (n_resp, 1, n_taps) of every response DOF to ``exc``.

        See :func:`hardware_mocks.signals.impulse_response`; cached per ``(fs, exc)``.
        """
        key = (float(fs), int(exc))
        with self._lock:
            ir = self._irs.get(key)
        if ir is None:
            b = self.bench
            ir = impulse_response(b.model, fs, self.resp_xyz, b.resp_dirs,
                                  self.exc_xyz[exc : exc + 1], b.exc_dirs[exc : exc + 1])
            with self._lock:
                self._irs[key] = ir
        return ir

    def response(self, hit_force: NDArray[np.float64], exc: int, fs: float,
                 resp_index: ArrayLike | None = None) -> NDArray[np.float64]:
        """Accelerations (n_resp, n) for a force history on one excitation DOF, sampled at ``fs``.

        A linear convolution (:func:`hardware_mocks.signals.simulate`): the force is
        zero before and after the given samples, nothing wraps around. The response
        equals the model's exact FRF below ``fs / 2.56`` and rolls off to Nyquist.
        ``resp_index`` selects response DOFs.
        """
        idx = np.arange(len(self.bench.resp_nodes)) if resp_index is None else np.asarray(
            resp_index, dtype=np.int64)
        acc = simulate(self.impulse_response(fs, exc), np.asarray(hit_force, float)[None, :])
        return acc[idx]
