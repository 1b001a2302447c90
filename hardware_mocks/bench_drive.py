"""What the simulated shaker generators share: an output that, amplified, pushes on the bench.

:class:`BenchDrive` is the bench side of a generator mock (the SG-1 of
:mod:`hardware_mocks.shaker_device`, the 33500 of :mod:`hardware_mocks.generator_33500`):
a :class:`~hardware_mocks.physics.ForceSource` attached to one excitation DOF
(:meth:`BenchDrive.attach`) that pushes with ``force_per_volt`` times the generator's
output voltage, and the random signal both generators make: a random-phase multisine,
flat over a band, unit RMS (:meth:`BenchDrive.multisine`). Each device keeps its own
command set and its own ``force(t)``.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.physics import BenchPhysics

__all__ = ["RANDOM_LINES", "RANDOM_PERIOD", "BenchDrive"]

#: random multisine: longest period (s) and most lines
RANDOM_PERIOD = 16.0
RANDOM_LINES = 4096


class BenchDrive:
    """A generator's output on the bench: attachment, force scale and random signal.

    Parameters
    ----------
    physics : BenchPhysics, optional
        The bench to drive; without it the generator drives nothing.
    force_per_volt : float
        Force on the structure per volt of output, N/V (amplifier and shaker).
    seed : int
        Seed of the random signal's phases (two shakers driven at once: two seeds).
    sensor : int
        Its force sensor: the front-end input wired to
        :func:`~hardware_mocks.frontend_device.shaker_force` of it shows this force alone.
    """

    def __init__(self, physics: BenchPhysics | None, force_per_volt: float, seed: int,
                 sensor: int) -> None:
        self.physics = physics
        self.force_per_volt = force_per_volt
        self.sensor = sensor
        self._exc: int | None = None
        #: host times (``time.monotonic()``) it was attached at, one a point
        self.attached_at: list[float] = []
        self._seed = seed
        self._multisine: tuple[tuple[float, float], NDArray[np.float64],
                               NDArray[np.float64]] | None = None

    @property
    def exc(self) -> int | None:
        """Excitation DOF index the shaker pushes on, None while detached."""
        return self._exc

    def attach(self, exc: int | None) -> None:
        """Attach the shaker's stinger to excitation DOF ``exc`` of the bench (None detaches)."""
        if exc is not None:
            if self.physics is None:
                raise ValueError("this shaker has no bench to attach to (physics=None)")
            n = len(self.physics.bench.exc_nodes)
            if not 0 <= exc < n:
                raise ValueError(f"excitation index {exc} out of range 0..{n - 1}")
            self.physics.add_source(self)
            self.attached_at.append(time.monotonic())
        self._exc = exc

    def detach_from_bench(self) -> None:
        """Leave the bench for good (the device shuts down)."""
        if self.physics is not None:
            self.physics.remove_source(self)

    def force(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Force (N) at host instants ``t`` (s, ``time.monotonic()``); each device's own."""
        raise NotImplementedError

    def shutdown(self) -> None:
        """Stop the device and leave the bench (idempotent); each device's own."""
        raise NotImplementedError

    def _fail(self, code: int) -> None:
        """Queue SCPI error ``code`` (each generator mock keeps its own error queue)."""
        raise NotImplementedError

    def _number(self, arg: str, low: float, high: float) -> float | None:
        """A command's number argument within ``[low, high]``; else None, with -224 (not a
        number) or -222 (out of range) queued as the generators do."""
        try:
            value = float(arg)
        except ValueError:
            self._fail(-224)
            return None
        if not low <= value <= high:
            self._fail(-222)
            return None
        return value

    def multisine(self, tau: NDArray[np.float64], f0: float, f1: float) -> NDArray[np.float64]:
        """Unit-RMS random-phase multisine over ``[f0, f1]`` Hz at times ``tau`` (s): at most
        :data:`RANDOM_LINES` lines, a period of at least :data:`RANDOM_PERIOD` s."""
        if self._multisine is None or self._multisine[0] != (f0, f1):
            df = max(1.0 / RANDOM_PERIOD, (f1 - f0) / RANDOM_LINES)
            freqs = np.arange(np.ceil(f0 / df), np.floor(f1 / df) + 1) * df
            freqs = freqs[freqs > 0]
            if freqs.size == 0:
                freqs = np.array([max(f0, df)])
            phases = np.random.default_rng(self._seed).uniform(0, 2 * np.pi, freqs.size)
            self._multisine = ((f0, f1), freqs, phases)
        _, freqs, phases = self._multisine
        amp = np.sqrt(2.0 / freqs.size)
        out = np.empty_like(tau)
        for i in range(0, tau.size, 256):  # bounded memory: 256 x n_lines at a time
            chunk = tau[i : i + 256]
            out[i : i + 256] = amp * np.cos(2 * np.pi * np.outer(chunk, freqs) + phases).sum(
                axis=1)
        return out
