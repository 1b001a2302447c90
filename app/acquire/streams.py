"""Continuous streams from the front end and the hammer, triggered hit records on one time base.

:class:`HitStreams` reads the reference front end (the responses) and the force
device in chunks of about 0.1 s (ten reads a second, see ``PITFALLS.md``),
finds hits on the force by its trigger level, and cuts one record per hit on the
front end's sample grid. When the force comes from another device (the hammer's
own digitiser), its clock is fitted and the force resampled onto the front end's
instants with :mod:`drivers.sync`; a hit whose streams cannot be aligned, or that
lost samples, is returned with the reason and never used.

Host timing aligns the two clocks to about a millisecond only. When the front end
also records the hammer's force (``sync_row``, a common channel), each hit is
aligned on it: :func:`drivers.sync.signal_delay` measures the remaining delay
between the resampled hammer force and the front end's copy to a small fraction
of a sample, and the hammer's clock fit is shifted by it before resampling again.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from drivers.base import AcquisitionFrontEnd, StreamingFrontEnd, TimeBlock
from drivers.errors import SyncError
from drivers.sync import ClockFit, align, check_alignment, fit_clock, signal_delay

__all__ = ["READ_TIMEOUT", "HitStreams", "RawHit"]

logger = logging.getLogger(__name__)

#: seconds a read of a chunk (0.1 s of samples) may take before it fails: a guard against a
#: device that keeps answering but sends no samples. A device that stops answering is told
#: by its driver's stall timeout (0.5 s, the mock benches' 2 s), counted while its reader
#: listens, so a host too loaded to read for a while is not taken for a failure.
READ_TIMEOUT = 10.0


@dataclass(frozen=True)
class RawHit:
    """One hit record: ``data`` (n_ch, n) force row first, at ``fs``; ``problem`` if unusable.

    ``sync`` is the common channel's record (front end, N) and ``sync_offset`` the
    correction it gave to the host-timed alignment, s (NaN when not aligned on one).
    """

    data: NDArray[np.float64]
    force_raw: NDArray[np.float64] | None
    bad_frames: int
    missing: int
    problem: str = ""
    sync: NDArray[np.float64] | None = None
    sync_offset: float = float("nan")


#: a common channel whose copy of the force correlates less than this is not the same signal
MIN_SYNC_CORRELATION = 0.9
#: largest correction of the host-timed alignment believed, s
MAX_SYNC_OFFSET = 0.02


class _Buffer:
    """The recent samples of one stream: ``data[:, k]`` is device sample ``first + k``."""

    def __init__(self, n_ch: int, keep: int) -> None:
        self.data = np.zeros((n_ch, 0))
        self.first = 0
        self.keep = keep

    @property
    def end(self) -> int:
        return self.first + self.data.shape[1]

    def add(self, block: TimeBlock) -> None:
        if self.data.shape[1] == 0:
            self.first = block.first_sample
        self.data = np.concatenate([self.data, block.data], axis=1)
        drop = self.data.shape[1] - self.keep
        if drop > 0:
            self.data = self.data[:, drop:]
            self.first += drop

    def slice(self, start: int, stop: int) -> NDArray[np.float64]:
        if start < self.first or stop > self.end:
            raise SyncError(f"samples {start}..{stop} are not buffered ({self.first}..{self.end})")
        return self.data[:, start - self.first:stop - self.first]


class HitStreams:
    """Streams of one hammer test, read by the procedure's worker thread.

    Parameters
    ----------
    ref : AcquisitionFrontEnd
        The front end with the response channels (the reference clock).
    resp_rows : sequence of int
        Rows of ``ref``'s blocks that are the plan's responses, in order.
    force_dev : AcquisitionFrontEnd
        The device with the force channel (``ref`` itself, or the hammer digitiser).
    force_row : int
        Row of the force in ``force_dev``'s blocks.
    n_before, n_record : int
        Samples kept before the trigger and the record length, at ``ref.fs``.
    level : float
        Trigger level, N (rising).
    sync_row : int, optional
        Row of ``ref``'s blocks that records the same force (a common channel): each hit
        of a separate force device is aligned on it to a fraction of a sample.
    samples : callable, optional
        Called after every read with the force and response rows just read, (1 + n_resp,
        n) at ``ref.fs`` (a separate device's force stretched to ``n``: for display only),
        and the host time of their first sample (``ref``'s estimate, or None).
    """

    CHUNK = 0.1  # s per read

    def __init__(self, ref: AcquisitionFrontEnd, resp_rows: list[int],
                 force_dev: AcquisitionFrontEnd, force_row: int, n_before: int, n_record: int,
                 level: float, sync_row: int | None = None,
                 samples: Callable[[NDArray[np.float64], float | None], None] | None = None
                 ) -> None:
        self.ref, self.force_dev = ref, force_dev
        self.samples = samples
        self.separate = force_dev is not ref
        if self.separate and not (isinstance(ref, StreamingFrontEnd)
                                  and isinstance(force_dev, StreamingFrontEnd)):
            raise ValueError(f"{force_dev.name} and {ref.name}: a separate force device is "
                             "aligned by the clocks of streaming front ends only: record the "
                             "force on the front end instead")
        self.sync_row = sync_row if self.separate else None
        self.resp_rows = resp_rows
        self.force_row = force_row
        self.n_before, self.n_record = n_before, n_record
        self.level = level
        keep = n_record * 2 + int(4 * ref.fs)
        self._ref = _Buffer(len(ref.channels), keep)
        ratio = force_dev.fs / ref.fs
        self._force = _Buffer(len(force_dev.channels), int(keep * ratio) + 64)
        self._searched = 0
        self._armed_from = 0

    @property
    def raw_pad(self) -> int:
        """Samples of the force device kept on each side of a hit beyond its record (room
        for the common-channel correction)."""
        if self.sync_row is None:
            return 16
        return 16 + int(np.ceil(MAX_SYNC_OFFSET * self.force_dev.fs))

    def raw_length(self, n_store: int) -> int:
        """Most force-device samples of one hit record of ``n_store`` front-end samples."""
        return int(np.ceil(n_store * self.force_dev.fs / self.ref.fs)) + 4 * self.raw_pad + 64

    @property
    def bad_frames(self) -> int:
        n = self.ref.health.bad_frames
        return n + (self.force_dev.health.bad_frames if self.separate else 0)

    def start(self) -> None:
        """Start streaming (both devices, one after the other: clocks are fitted later)."""
        self.ref.start()
        if self.separate:
            self.force_dev.start()
        self._ref = _Buffer(self._ref.data.shape[0], self._ref.keep)
        self._force = _Buffer(self._force.data.shape[0], self._force.keep)
        self._searched = self._armed_from = 0

    def stop(self) -> None:
        for dev in (self.ref, self.force_dev) if self.separate else (self.ref,):
            dev.stop()

    def read(self) -> None:
        """Read about 0.1 s from every stream (blocks until it is in; device errors raise)."""
        ref = self.ref.read_block(max(1, int(self.ref.fs * self.CHUNK)), timeout=READ_TIMEOUT)
        self._ref.add(ref)
        force = ref.data[self.force_row]
        if self.separate:
            block = self.force_dev.read_block(max(1, int(self.force_dev.fs * self.CHUNK)),
                                              timeout=READ_TIMEOUT)
            self._force.add(block)
            f = block.data[self.force_row]
            n = ref.data.shape[1]
            force = np.interp(np.linspace(0, f.size - 1, n), np.arange(f.size), f)
        if self.samples is not None:
            self.samples(np.vstack([force[None], ref.data[self.resp_rows]]), ref.host_time)

    def settle(self, seconds: float = 0.7) -> None:
        """Stream ``seconds`` so the clocks can be measured before the first hit."""
        for _ in range(max(1, round(seconds / self.CHUNK))):
            self.read()
        self._searched = (self._force if self.separate else self._ref).end

    def _fits(self) -> tuple[ClockFit, ClockFit]:
        ref, force = self.ref, self.force_dev
        assert isinstance(ref, StreamingFrontEnd) and isinstance(force, StreamingFrontEnd)
        fits = [fit_clock(dev.clock_pairs(), dev.fs) for dev in (ref, force)]
        for dev, fit in zip((ref, force), fits, strict=True):  # each to its own station limit
            check_alignment({dev.name: fit}, max_residual=dev.timing_scatter)
        return fits[0], fits[1]

    def next_trigger(self) -> int | None:
        """Device sample index (of the force stream) of the next trigger, or None yet."""
        buf = self._force if self.separate else self._ref
        row = self.force_row
        lo = max(self._searched, buf.first + 1, self._armed_from)
        if buf.end - lo < 1:
            return None
        f = buf.data[row, lo - 1 - buf.first:]
        with np.errstate(invalid="ignore"):
            cross = np.flatnonzero((f[:-1] < self.level) & (f[1:] >= self.level))
        if cross.size == 0:
            self._searched = buf.end
            return None
        k = lo + int(cross[0])
        self._searched = k + 1
        return k

    def record(self, trigger: int, margin: int) -> RawHit:
        """Wait for and cut the record of the hit that triggered at ``trigger``.

        The record spans ``n_before + margin`` samples before the trigger to
        ``n_record - n_before + margin`` after it, on the front end's grid.
        """
        bad0 = self.bad_frames
        length = self.n_record + 2 * margin
        if not self.separate:
            start = trigger - self.n_before - margin
            while self._ref.end < start + length:
                self.read()
            self._arm_after(trigger)
            block = self._ref.slice(start, start + length)
            data = np.vstack([block[self.force_row][None], block[self.resp_rows]])
            return self._finish(data, None, bad0)
        ref_fit, f_fit = self._fits()
        t_trig = float(f_fit.host_time(trigger))
        k_ref = round((t_trig - ref_fit.t0) * ref_fit.rate)
        start = k_ref - self.n_before - margin
        ratio = self.force_dev.fs / self.ref.fs
        pad = self.raw_pad
        while True:
            t_end = float(ref_fit.host_time(start + length))
            f_stop = int(np.ceil((t_end - f_fit.t0) * f_fit.rate)) + pad
            if self._ref.end >= start + length and self._force.end >= f_stop:
                break
            self.read()
        self._arm_after(trigger)
        ref_fit, f_fit = self._fits()  # refit with the latest frames
        t0 = float(ref_fit.host_time(start))
        f_start = max(int(np.floor((t0 - f_fit.t0) * f_fit.rate)) - pad, self._force.first)
        f_stop = min(f_stop + pad, self._force.end)
        ref_block = TimeBlock(self._ref.slice(start, start + length), self.ref.fs,
                              self.ref.channels, start)
        raw = self._force.slice(f_start, f_stop)
        force_raw = raw[self.force_row].copy()
        sync = None if self.sync_row is None else ref_block.data[self.sync_row].copy()
        n_lost = int(np.count_nonzero(np.isnan(raw).any(axis=0)))
        resp = ref_block.data[self.resp_rows]
        if n_lost:
            data = np.vstack([np.full((1, length), np.nan), resp])
            return self._finish(data, force_raw, bad0, f"{n_lost} force samples lost", sync)
        other = TimeBlock(raw, self.force_dev.fs, self.force_dev.channels, f_start)
        offset = float("nan")
        try:
            aligned = align(ref_block, ref_fit, other, f_fit, self.force_dev.name)
            if sync is not None:
                aligned, offset = self._align_on(sync, ref_block, ref_fit, other, f_fit)
        except SyncError as err:
            data = np.vstack([np.full((1, length), np.nan), resp])
            return self._finish(data, force_raw, bad0, f"streams not aligned: {err}", sync)
        logger.debug("hit aligned: force %d..%d (x%.3g) onto front end %d..%d, common-channel "
                     "correction %.1f us", f_start, f_stop, ratio, start, start + length,
                     offset * 1e6)
        return self._finish(np.vstack([aligned.data[self.force_row][None], resp]), force_raw,
                            bad0, "", sync, offset)

    def _align_on(self, sync: NDArray[np.float64], ref_block: TimeBlock, ref_fit: ClockFit,
                  other: TimeBlock, f_fit: ClockFit) -> tuple[TimeBlock, float]:
        """Re-align ``other`` so its force matches the common channel ``sync`` (s offset)."""
        if np.any(np.isnan(sync)):
            raise SyncError("the common channel lost samples during the hit")
        total = 0.0
        fit = f_fit
        aligned = align(ref_block, ref_fit, other, fit, self.force_dev.name)
        for _ in range(3):  # converges in one step; the others check it
            delay, corr = signal_delay(sync, aligned.data[self.force_row], self.ref.fs)
            if corr < MIN_SYNC_CORRELATION:
                raise SyncError(f"the front end's common channel does not match "
                                f"{self.force_dev.name}'s force (correlation {corr:.2f})")
            total += delay
            if abs(total) > MAX_SYNC_OFFSET:
                raise SyncError(f"common channel {total * 1e3:.1f} ms off the host-timed "
                                f"alignment (limit {MAX_SYNC_OFFSET * 1e3:g} ms)")
            fit = replace(fit, t0=fit.t0 - delay)
            aligned = align(ref_block, ref_fit, other, fit, self.force_dev.name)
            if abs(delay) * self.ref.fs < 1e-4:
                break
        return aligned, total

    def _arm_after(self, trigger: int) -> None:
        ratio = self.force_dev.fs / self.ref.fs if self.separate else 1.0
        self._armed_from = trigger + int((self.n_record - self.n_before) * ratio)

    def _finish(self, data: NDArray[np.float64], force_raw: NDArray[np.float64] | None,
                bad0: int, problem: str = "", sync: NDArray[np.float64] | None = None,
                sync_offset: float = float("nan")) -> RawHit:
        missing = int(np.count_nonzero(np.isnan(data).any(axis=0)))
        bad = self.bad_frames - bad0
        if missing and not problem:
            problem = f"{missing} samples lost"
        if problem and bad:
            problem += f" ({bad} corrupted frames)"
        return RawHit(data, force_raw, bad, missing, problem, sync, sync_offset)

