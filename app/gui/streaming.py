"""Live streams for the Station view's level meters and the GUI benchmark.

A :class:`StreamThread` (a QThread) reads blocks from a :class:`BlockSource` as fast as
the source delivers them and puts each block on a queue; nothing in it touches a widget.
The GUI side (:class:`app.gui.views.levels.LevelsWidget`) drains the queue from a QTimer,
so no block is dropped however slowly the GUI draws; per-channel peaks and a ring buffer of
the last seconds are updated with ``setData`` on existing items.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from PySide6 import QtCore

from app.report.analysis import message_of
from drivers.base import AcquisitionFrontEnd, ChannelConfig
from drivers.errors import DeviceError

__all__ = ["Block", "BlockSource", "DeviceSource", "StreamThread", "SyntheticSource"]


@dataclass(frozen=True)
class Block:
    """One block of every channel: samples (n_ch, n) in physical units, overloaded flags."""

    data: NDArray[np.float64]
    overloaded: NDArray[np.bool_]
    t_read: float


class BlockSource:
    """Where blocks come from; subclasses open, read and close a stream."""

    names: tuple[str, ...] = ()
    #: full-scale range of each channel in its physical unit (N, m/s^2)
    full_scale: NDArray[np.float64] = np.zeros(0)
    fs: float = 1.0

    def open(self) -> None:
        """Start streaming (stream thread)."""

    def read(self) -> Block:
        """The next block (stream thread); raises on a device failure."""
        raise NotImplementedError

    def close(self) -> None:
        """Stop streaming (stream thread), idempotent."""


def full_scale(channels: Sequence[ChannelConfig]) -> NDArray[np.float64]:
    """Full-scale range of each channel in its unit: range (V) x 1000 / sensitivity (mV/unit)."""
    return np.array([c.full_scale for c in channels])


class DeviceSource(BlockSource):
    """Blocks from acquisition front ends, read in turn (one block of each, stacked).

    Parameters
    ----------
    devices : front ends (created, not opened); opened and shut down here
    block : seconds per block (25 reads a second, so that the 30 Hz redraws show new data
        at least 20 times a second; the usual advice of about ten reads a second is for
        long recordings, a level meter needs less latency)
    """

    def __init__(self, devices: Sequence[AcquisitionFrontEnd], block: float = 0.04) -> None:
        self.devices = list(devices)
        chans = [c for d in self.devices for c in d.channels]
        self.names = tuple(c.name for c in chans)
        self.full_scale = full_scale(chans)
        self.fs = self.devices[0].fs if self.devices else 1.0
        self._n = [max(1, round(block * d.fs)) for d in self.devices]

    def open(self) -> None:
        for d in self.devices:
            d.open()
            d.start()

    def read(self) -> Block:
        rows, over = [], []
        n_min = min(self._n)
        for d, n in zip(self.devices, self._n, strict=True):
            b = d.read_block(n)
            # devices at other rates: keep the first n_min samples' worth, decimated
            step = max(1, n // n_min)
            rows.append(b.data[:, ::step][:, :n_min])
            over += [c.name in b.overloaded for c in d.channels]
        return Block(np.vstack(rows), np.array(over), time.monotonic())

    def close(self) -> None:
        for d in self.devices:
            try:
                d.shutdown()
            except DeviceError:
                pass


class SyntheticSource(BlockSource):
    """A paced synthetic stream (decaying sines and noise), for the benchmark and demos.

    Parameters
    ----------
    n_channels : channels (the first is a force in N, the others accelerations in m/s^2)
    fs : sample rate, Hz
    block : seconds per block
    """

    def __init__(self, n_channels: int = 25, fs: float = 1024.0, block: float = 0.05) -> None:
        self.names = ("F", *(f"a{k}" for k in range(1, n_channels)))
        self.full_scale = np.array([2222.0] + [490.0] * (n_channels - 1))
        self.fs = fs
        self._n = max(1, round(block * fs))
        self._k = 0
        self._rng = np.random.default_rng(0)
        self._freq = 5.0 + 3.0 * np.arange(n_channels)
        self._t0 = 0.0

    def open(self) -> None:
        self._t0 = time.monotonic()
        self._k = 0

    def read(self) -> Block:
        due = self._t0 + (self._k + self._n) / self.fs
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        t = (self._k + np.arange(self._n)) / self.fs
        data = 50.0 * np.sin(2 * np.pi * self._freq[:, None] * t[None, :])
        data += self._rng.standard_normal(data.shape)
        self._k += self._n
        return Block(data, np.abs(data).max(axis=1) >= self.full_scale, time.monotonic())


class StreamThread(QtCore.QThread):
    """Reads a source in its own thread; blocks go to ``queue``, a failure to ``failed``.

    Signals
    -------
    failed(str)
        The source raised; one line. The thread then ends (the source is closed).
    """

    failed = QtCore.Signal(str)

    def __init__(self, source: BlockSource, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.source = source
        self.queue: queue.SimpleQueue[Block] = queue.SimpleQueue()
        self.blocks = 0
        self.samples = 0  # per channel
        self._stop = False

    def run(self) -> None:
        try:
            self.source.open()
            while not self._stop:
                block = self.source.read()
                self.queue.put(block)
                self.blocks += 1
                self.samples += block.data.shape[1]
        except (DeviceError, OSError, ValueError) as err:
            self.failed.emit(message_of(err))
        finally:
            self.source.close()

    def stop(self, timeout_ms: int = 5000) -> None:
        """Ask the loop to end after the current block and wait for it (idempotent)."""
        self._stop = True
        if self.isRunning():
            self.wait(timeout_ms)

    def drain(self) -> list[Block]:
        """Every block queued so far (GUI thread)."""
        out: list[Block] = []
        while True:
            try:
                out.append(self.queue.get_nowait())
            except queue.Empty:
                return out
