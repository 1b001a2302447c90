"""What a simulated digitiser's inputs carry, sample by sample: the bench's physics on a clock.

:class:`InputSignals` is shared by the simulated front ends (the FE-16 on CAN,
:mod:`hardware_mocks.frontend_device`, and the NI-DAQmx modules,
:mod:`hardware_mocks.nidaqmx_sim`): each input is wired to a response DOF of the bench, to
the force on it, or to one shaker's force sensor. Each hit on the shared
:class:`~hardware_mocks.physics.BenchPhysics` and the force of every attached continuous
source (a shaker) are turned into the model's accelerations by linear convolution with the
model's band-limited impulse responses (:func:`hardware_mocks.signals.simulate`, nothing
wraps around) on the device's own sample grid, plus sensor noise. Continuous forces are
sampled in blocks of ``source_block`` s, :data:`LOOKAHEAD` samples ahead of the samples
taken: the response starting more than that many samples before its force (below 1e-5 of
the peak) is left out, and a change of the shaker's output shows up within
``source_block`` s.

Example
-------
>>> sig = InputSignals(physics, [0, 1, FORCE], 3)  # doctest: +SKIP
>>> clock = DeviceClock(1024.0); clock.start(); sig.start(clock)  # doctest: +SKIP
>>> sig.advance(clock.due()); x = sig.take(100)  # (3, 100) m/s^2 and N  # doctest: +SKIP
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.physics import BenchPhysics, DeviceClock, sampled_pulse
from hardware_mocks.signals import simulate

__all__ = ["FORCE", "LOOKAHEAD", "InputSignals", "shaker_force"]

logger = logging.getLogger(__name__)

FORCE = -1  #: wiring code: the input carries the hammer force (and every shaker's)
#: samples of the non-causal lead of the band-limited response that are simulated
LOOKAHEAD = 64


def shaker_force(sensor: int) -> int:
    """Wiring code of an input that carries the force sensor ``sensor`` of a shaker only
    (:attr:`hardware_mocks.shaker_device.ShakerDevice.sensor`)."""
    return -2 - sensor


class InputSignals:
    """The physical values (m/s^2, N) on a device's inputs, produced in order.

    Parameters
    ----------
    physics : BenchPhysics
        The bench.
    wiring : sequence of int or None
        Per input: index of the bench response DOF it measures, :data:`FORCE`,
        :func:`shaker_force`, or None (open); inputs beyond the list (up to ``n_inputs``)
        are open.
    n_inputs : int
        Number of inputs of the device.
    accel_noise, force_noise : float
        Sensor noise, m/s^2 RMS and N RMS (may be changed at any time).
    tail : float, optional
        Length of each hit's computed response, s (default: until the model's
        impulse response has decayed to 1e-7 of its peak).
    source_block : float
        Continuous forces (shakers) are simulated this many seconds at a time.
    seed : int
        Seed of the noise.
    """

    def __init__(self, physics: BenchPhysics, wiring: Sequence[int | None], n_inputs: int, *,
                 accel_noise: float = 0.0, force_noise: float = 0.0,
                 tail: float | None = None, source_block: float = 0.1, seed: int = 0) -> None:
        if len(wiring) > n_inputs:
            raise ValueError(f"{len(wiring)} inputs wired, the device has {n_inputs}")
        self.physics = physics
        self.wiring = list(wiring)
        self.n_inputs = n_inputs
        self.accel_noise = accel_noise
        self.force_noise = force_noise
        self.tail = tail
        self.source_block = source_block
        self._rng = np.random.default_rng(seed)
        wired = [(i, w) for i, w in enumerate(self.wiring) if w is not None]
        self._resp_rows = [i for i, w in wired if w >= 0]
        self._resp_dofs = [w for _, w in wired if w >= 0]
        self._force_rows = [i for i, w in wired if w == FORCE]
        self._sensor_rows = [i for i, w in wired if w < FORCE]
        self.clock = DeviceClock(1024.0)
        self.produced = 0  # samples taken since start
        self._pending = np.zeros((n_inputs, 0))
        self._hit_cursor = len(physics.hits())
        self._forced_until = 0  # continuous forces simulated up to this sample

    def start(self, clock: DeviceClock) -> None:
        """Begin a new stream on ``clock`` (started): hits made before now are left out, the
        shakers' forces are simulated from before the start so their response is steady."""
        ir = self.physics.impulse_response(clock.true_rate, 0)
        self.clock = clock
        self.produced = 0
        self._pending = np.zeros((self.n_inputs, 0))
        self._hit_cursor = len(self.physics.hits())
        self._forced_until = -(ir.h.shape[-1] - ir.lead)

    def advance(self, due: int) -> None:
        """Simulate what the hits made so far and the shakers add up to sample ``due``."""
        self._absorb_hits()
        self._absorb_sources(due)

    def take(self, n: int) -> NDArray[np.float64]:
        """The next ``n`` samples of every input, (n_inputs, n), noise included."""
        out = np.zeros((self.n_inputs, n))
        k = min(n, self._pending.shape[1])
        out[:, :k] = self._pending[:, :k]
        self._pending = self._pending[:, k:]
        self.produced += n
        if self.accel_noise:
            out[self._resp_rows] += self.accel_noise * self._rng.standard_normal(
                (len(self._resp_rows), n))
        if self.force_noise:
            rows = self._force_rows + self._sensor_rows
            out[rows] += self.force_noise * self._rng.standard_normal((len(rows), n))
        return out

    def _add_pending(self, signal: NDArray[np.float64], k_start: int, what: str = "") -> None:
        """Add ``signal`` (n_inputs, n), starting at device sample ``k_start``, to what is
        still to be taken. Samples already taken are left out; for a ``what`` (a hit) this
        is reported when more than its :data:`LOOKAHEAD` samples of lead are lost."""
        start = k_start - self.produced
        if start < 0:
            if what and -start > LOOKAHEAD:
                logger.warning("mock front end: %s registered %d samples late", what,
                               -start - LOOKAHEAD)
            signal, start = signal[:, -start:], 0
        if signal.shape[1] == 0:
            return
        end = start + signal.shape[1]
        if end > self._pending.shape[1]:
            grow = np.zeros((self.n_inputs, end - self._pending.shape[1]))
            self._pending = np.concatenate([self._pending, grow], axis=1)
        self._pending[:, start:end] += signal

    def _signal(self, force: NDArray[np.float64], acc: NDArray[np.float64],
                sensor: int | None = None) -> NDArray[np.float64]:
        """Inputs (n_inputs, n) from the force on the bench and all response DOFs'
        accelerations; ``sensor``: the force sensor that measures it (a shaker's), if any."""
        signal = np.zeros((self.n_inputs, acc.shape[1]))
        signal[self._resp_rows] = acc[self._resp_dofs]
        signal[self._force_rows] = force
        if sensor is not None:
            rows = [i for i, w in enumerate(self.wiring) if w == shaker_force(sensor)]
            signal[rows] = force
        return signal

    def _absorb_hits(self) -> None:
        """Add the response to each new hit to the samples still to be taken."""
        new = self.physics.hits(self._hit_cursor)
        self._hit_cursor += len(new)
        rate = self.clock.true_rate
        for hit in new:
            ir = self.physics.impulse_response(rate, hit.exc)
            k0 = int(np.floor((hit.t0 - self.clock.t_first) * rate)) - LOOKAHEAD
            n = (int(np.ceil(self.tail * rate)) if self.tail is not None
                 else int(np.ceil(hit.duration * rate)) + LOOKAHEAD + ir.h.shape[-1] - ir.lead)
            force = sampled_pulse(self.clock.instants(k0, n), 1.0 / rate, [hit])
            self._add_pending(self._signal(force, simulate(ir, force[None, :])), k0, "hit")

    def _absorb_sources(self, due: int) -> None:
        """Simulate the continuous forces (shakers) one block ahead of sample ``due``."""
        rate = self.clock.true_rate
        block = max(1, int(np.ceil(self.source_block * rate)))
        until = due + LOOKAHEAD + block
        while self._forced_until < until:
            a = self._forced_until
            n = max(block, until - a)
            self._forced_until = a + n
            for exc, sensor, f in self.physics.source_forces(self.clock.instants(a, n)):
                ir = self.physics.impulse_response(rate, exc)
                padded = np.zeros(LOOKAHEAD + n + ir.h.shape[-1] - ir.lead)
                padded[LOOKAHEAD : LOOKAHEAD + n] = f
                self._add_pending(self._signal(padded, simulate(ir, padded[None, :]), sensor),
                                  a - LOOKAHEAD)
