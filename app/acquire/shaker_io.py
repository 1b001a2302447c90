"""The shaker procedure's two devices: the drive (output, ramps, watchdog) and the block stream.

:class:`ShakerDrive` sets the plan's waveform and level, ramps the output up and
down while the front end keeps streaming, checks after each block that the
output is still on, and feeds an SG-1's watchdog from the calling (worker)
thread. :class:`BlockStream` reads the front end about ten times a second and
cuts blocks of ``nperseg`` samples: consecutive for random and chirp, starting
at each burst (found on the force) for burst random.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from app.acquire.plan import TestPlan
from app.acquire.procedure import StopRequestedError
from app.acquire.streams import READ_TIMEOUT
from drivers.base import AcquisitionFrontEnd, ExcitationDevice
from drivers.errors import DeviceError, DeviceTimeoutError
from drivers.shaker_scpi import ScpiShaker, ShakerError

__all__ = ["BURST_PRE", "BlockStream", "ShakerDrive", "ShakerDrives", "burst_onset"]

logger = logging.getLogger(__name__)

#: samples kept before a detected burst onset
BURST_PRE = 2


class ShakerDrive:
    """The excitation device as the procedure drives it (worker thread only).

    Parameters
    ----------
    device : ExcitationDevice
        Built, not opened.
    plan : TestPlan
        Its ``[shaker]`` section and ``record.fs`` (the burst and chirp period is one
        block, ``nperseg / fs`` s).
    heartbeat : float
        SG-1 watchdog time, s; :meth:`beat` sends a heartbeat at most every fifth of it.
    """

    def __init__(self, device: ExcitationDevice, plan: TestPlan, heartbeat: float) -> None:
        self.device = device
        self.settings = plan.shaker
        self.fs = plan.record.fs
        self.heartbeat = heartbeat
        self.scpi = isinstance(device, ScpiShaker)
        self.driving = False
        self._last_beat = 0.0
        #: set by the procedure: True once the operator asked to stop (checked while ramping)
        self.should_stop: Callable[[], bool] = lambda: False

    def open(self) -> None:
        """Open the device and arm its watchdog (fed by :meth:`beat`)."""
        self.device.open()
        if isinstance(self.device, ScpiShaker) and self.heartbeat > 0:
            self.device.command(f"SYST:HEART:TIM {self.heartbeat:g}")

    def beat(self) -> None:
        """Feed the watchdog (call it from the worker after every read)."""
        now = time.monotonic()
        if (isinstance(self.device, ScpiShaker) and self.heartbeat > 0
                and now - self._last_beat >= self.heartbeat / 5):
            self.device.write("SYST:HEART")
            self._last_beat = now

    def _params(self) -> dict[str, float]:
        s = self.settings
        period = s.nperseg / self.fs
        if s.waveform == "random":
            return {"f_start": s.f_start, "f_stop": s.f_stop}
        if s.waveform == "chirp":
            return {"f_start": s.f_start, "f_stop": s.f_stop, "period": period}
        return {"f_start": s.f_start, "f_stop": s.f_stop, "period": period, "burst": s.duty}

    def on(self, stream: BlockStream) -> None:
        """Waveform, level, output on; stream through the ramp and the settling time."""
        self.start_output()
        self.wait_ramp(stream)
        self._discard(stream, self.settings.settle)
        logger.info("%s: %s at %g V, ramped and settled", self.device.name,
                    self.settings.waveform, self.settings.level)

    def start_output(self) -> None:
        """Waveform, level, output on (its ramp starts)."""
        s = self.settings
        dev = self.device
        dev.set_waveform(s.waveform, **self._params())
        dev.set_level(s.level)
        dev.start()
        self.driving = True

    def wait_ramp(self, stream: BlockStream) -> None:
        """Stream until the output has ramped up to its level (the ramp time, without
        an SG-1 to ask)."""
        s = self.settings
        dev = self.device
        deadline = time.monotonic() + s.ramp + 3.0
        if isinstance(dev, ScpiShaker):
            while abs(dev.output_level() - s.level) > 1e-6 * max(1.0, s.level):
                self._stop_if_asked()
                problem = self.check()
                if problem:
                    raise ShakerError(problem, dev.name, 0, problem)
                if time.monotonic() > deadline:
                    raise DeviceTimeoutError(f"{dev.name}: output ramp not done in "
                                             f"{s.ramp + 3.0:g} s", dev.name)
                stream.discard(stream.CHUNK)
        else:
            self._discard(stream, s.ramp)

    def _stop_if_asked(self) -> None:
        if self.should_stop():
            self.emergency_off()
            raise StopRequestedError

    def _discard(self, stream: BlockStream, seconds: float) -> None:
        """Stream and drop ``seconds`` one read at a time, turning the output off at once
        when a stop is asked meanwhile."""
        end = time.monotonic() + seconds
        while True:
            self._stop_if_asked()
            stream.discard(min(stream.CHUNK, max(end - time.monotonic(), 0.0)))
            if time.monotonic() >= end:
                return

    def check(self) -> str:
        """"" while the output is on, else why it went off (device errors read)."""
        dev = self.device
        if isinstance(dev, ScpiShaker):
            if dev.output_is_on():
                return ""
            errs = dev.errors()
            why = "; ".join(f"{c} {t}" for c, t in errs) or "no error reported"
            return f"{dev.name}: output went off during the block ({why})"
        return dev.output_problem()  # a generator's queue and output, an NI-DAQmx task

    def off(self, stream: BlockStream) -> None:
        """Ramp the output down and turn it off, streaming until it is at 0."""
        dev = self.device
        dev.stop()
        self.driving = False
        if isinstance(dev, ScpiShaker):
            deadline = time.monotonic() + self.settings.ramp + 3.0
            while dev.output_level() > 0 and time.monotonic() < deadline:
                stream.discard(stream.CHUNK)
        else:
            stream.discard(self.settings.ramp)

    def emergency_off(self) -> None:
        """Output off now, whatever the state (errors logged, never raised)."""
        self.driving = False
        try:
            self.device.stop()
            if isinstance(self.device, ScpiShaker):
                self.device.write("OUTP OFF")
        except DeviceError as err:
            logger.error("%s: could not turn the output off: %s", self.device.name, err)

    def shutdown(self) -> None:
        """Output off and release the device (idempotent; errors logged)."""
        self.driving = False
        try:
            self.device.shutdown()
        except DeviceError as err:
            logger.error("%s: shutdown failed: %s", self.device.name, err)


class ShakerDrives:
    """Several :class:`ShakerDrive` driven at once (one per shaker of a drive), as one.

    The outputs go on together, each ramp is waited for, then the settling time once;
    :meth:`check` reports the first output that went off; off, emergency off and
    shutdown act on every shaker.
    """

    def __init__(self, drives: Sequence[ShakerDrive]) -> None:
        self.drives = list(drives)

    @property
    def driving(self) -> bool:
        return any(d.driving for d in self.drives)

    @property
    def should_stop(self) -> Callable[[], bool]:
        return self.drives[0].should_stop

    @should_stop.setter
    def should_stop(self, fn: Callable[[], bool]) -> None:
        for d in self.drives:
            d.should_stop = fn

    def open(self) -> None:
        for d in self.drives:
            d.open()

    def beat(self) -> None:
        for d in self.drives:
            d.beat()

    def on(self, stream: BlockStream) -> None:
        for d in self.drives:
            d.start_output()
        for d in self.drives:
            d.wait_ramp(stream)
        first = self.drives[0]
        first._discard(stream, first.settings.settle)
        logger.info("%s: %s at %g V, ramped and settled",
                    ", ".join(d.device.name for d in self.drives), first.settings.waveform,
                    first.settings.level)

    def check(self) -> str:
        return next((p for d in self.drives if (p := d.check())), "")

    def off(self, stream: BlockStream) -> None:
        for d in self.drives:  # every output down at once, then each waited for
            d.device.stop()
            d.driving = False
        for d in self.drives:
            d.off(stream)

    def emergency_off(self) -> None:
        for d in self.drives:
            d.emergency_off()

    def shutdown(self) -> None:
        for d in self.drives:
            d.shutdown()


def burst_onset(force: NDArray[np.float64], quiet: int, threshold: float) -> int | None:
    """First sample where ``|force|`` exceeds ``threshold`` after ``quiet`` samples below it.

    Examples
    --------
    >>> burst_onset(np.array([0, 3.0, 0, 0, 0, 0.01, 2, 1]), quiet=3, threshold=0.1)
    6
    """
    f = np.abs(np.asarray(force, dtype=float))
    loud = ~(f <= threshold)  # NaN counts as loud: a lost sample is no proof of silence
    c = np.concatenate([[0], np.cumsum(loud)])
    k = np.arange(quiet, f.size)
    ok = loud[quiet:] & (c[k] - c[k - quiet] == 0)
    hits = np.flatnonzero(ok)
    return int(k[hits[0]]) if hits.size else None


class BlockStream:
    """Blocks of the plan's rows (force first) from the front end, worker thread only.

    Parameters
    ----------
    frontend : AcquisitionFrontEnd
        Opened.
    rows : sequence of int
        Rows of its blocks to keep: the force, then the plan's responses.
    plan : TestPlan
    beat : callable
        Called after every read (the shaker's watchdog).
    samples : callable, optional
        Called after every read with the rows just read, (len(rows), n).
    """

    CHUNK = 0.1  # s per read

    def __init__(self, frontend: AcquisitionFrontEnd, rows: Sequence[int], plan: TestPlan,
                 beat: Callable[[], None],
                 samples: Callable[[NDArray[np.float64]], None] | None = None) -> None:
        self.fe = frontend
        self.samples = samples
        self.rows = list(rows)
        self.n = plan.shaker.nperseg
        self.burst = plan.shaker.waveform == "burst-random"
        self.quiet = max(2, int(0.5 * (1.0 - plan.shaker.duty) * self.n))
        self.beat = beat
        self._buf = np.zeros((len(self.rows), 0))
        self._bad_seen = 0

    def start(self) -> None:
        self.fe.start()
        self._buf = np.zeros((len(self.rows), 0))
        self._bad_seen = self.fe.health.bad_frames

    def stop(self) -> None:
        self.fe.stop()

    def read(self) -> None:
        """Read about 0.1 s into the buffer and feed the watchdog (device errors raise)."""
        n = max(1, int(self.fe.fs * self.CHUNK))
        block = self.fe.read_block(n, timeout=READ_TIMEOUT)
        self.beat()
        rows = block.data[self.rows]
        if self.samples is not None:
            self.samples(rows)
        self._buf = np.concatenate([self._buf, rows], axis=1)
        if self._buf.shape[1] > 4 * self.n:  # no block found in that much: keep the newest
            self._buf = self._buf[:, -2 * self.n:]

    def discard(self, seconds: float) -> None:
        """Stream ``seconds`` and drop them (ramps, settling)."""
        end = time.monotonic() + seconds
        while True:
            self.read()
            self._buf = self._buf[:, :0]
            if time.monotonic() >= end:
                return

    def restart_blocks(self) -> None:
        """The next block starts with the next samples read."""
        self._buf = self._buf[:, :0]

    def take_partial(self) -> NDArray[np.float64] | None:
        """The samples of the block in progress, NaN-padded to a block (None if none);
        the buffer is emptied."""
        k = min(self._buf.shape[1], self.n)
        if k == 0:
            return None
        out = np.full((self._buf.shape[0], self.n), np.nan)
        out[:, :k] = self._buf[:, :k]
        self._buf = self._buf[:, :0]
        return out

    def take_bad_frames(self) -> int:
        """Corrupted frames seen since the last call."""
        now = self.fe.health.bad_frames
        n, self._bad_seen = now - self._bad_seen, now
        return n

    def next_block(self) -> NDArray[np.float64] | None:
        """Read once; return the next complete block (rows, nperseg) or None yet."""
        self.read()
        start = 0
        if self.burst:
            f = self._buf[0]
            finite = np.abs(f[np.isfinite(f)])
            if finite.size == 0 or finite.max() == 0:
                return None
            k = burst_onset(f, self.quiet, 0.02 * float(finite.max()))
            if k is None:
                return None
            start = max(0, k - BURST_PRE)
        if self._buf.shape[1] - start < self.n:
            return None
        out = self._buf[:, start:start + self.n].copy()
        # a burst's block ends in its quiet tail, which is the next burst's quiet lead
        keep = start + self.n - (self.quiet if self.burst else 0)
        self._buf = self._buf[:, keep:]
        return out
