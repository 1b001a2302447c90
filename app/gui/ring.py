"""A fixed-size ring buffer of streamed samples that live plots reveal at their own rate.

Streams deliver samples in reads (a tenth or a twenty-fifth of a second each); a plot that
drew each read when it arrived would move only as often as the stream is read. The ring
keeps every sample received and reveals them by the time elapsed between redraws, staying
at most ``lag`` s behind the newest sample: every redraw that finds samples not shown yet
shows them (the redraw timer, not the read cadence, sets the frame rate), every sample is
shown once, none is dropped, and a stall of the GUI thread is caught up at once. More than
one read behind, it reveals a quarter faster than real time until it is back within one
read (about a read's duration behind the stream, as drawing each read on arrival would be).

No Qt here: the views call :meth:`RevealRing.add` and :meth:`RevealRing.advance` from the
GUI thread.

Example
-------
>>> ring = RevealRing(n_ch=2, fs=100.0, seconds=1.0)
>>> ring.add(np.ones((2, 10)), t_read=0.0)
>>> ring.advance(0.05)  # 50 ms later: 5 of the 10 samples are revealed
True
>>> ring.shown, int(np.isfinite(ring.view()[0]).sum())
(5, 5)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["RevealRing"]


class RevealRing:
    """The last ``seconds`` of ``n_ch`` channels, plus room for samples not revealed yet.

    Parameters
    ----------
    n_ch : int
        Channels.
    fs : float
        Sample rate, Hz.
    seconds : float
        Length of :meth:`view`, s.
    lag : float
        Largest delay of the revealed samples behind the newest, s.
    """

    def __init__(self, n_ch: int, fs: float, seconds: float, lag: float = 0.3) -> None:
        self.fs, self.lag = fs, lag
        self.n = max(2, round(seconds * fs))
        self.cap = self.n + max(1, int(np.ceil(2 * lag * fs))) + 1
        self._data = np.full((n_ch, self.cap), np.nan)
        self.received = 0  # samples per channel received
        self.shown = 0  # samples per channel revealed
        self._pos = 0.0  # ``shown`` with its fraction of a sample
        self._reads: list[tuple[int, float]] = []  # (received after a read, its t_read)
        self._chunk = 1  # samples of the latest read

    def add(self, data: NDArray[np.float64], t_read: float) -> None:
        """Append ``data`` (n_ch, k), read at ``t_read`` (``time.monotonic()``)."""
        k = data.shape[1]
        if k > self.cap:  # more than the ring holds: only the newest can ever be shown
            self.received += k - self.cap
            data, k = data[:, -self.cap:], self.cap
        idx = (self.received + np.arange(k)) % self.cap
        self._data[:, idx] = data
        self.received += k
        self._chunk = k
        self._reads.append((self.received, t_read))

    def advance(self, dt: float, catch_up: bool = False) -> bool:
        """Reveal ``dt`` s more (all of it with ``catch_up``); True if new samples show."""
        newest = float(self.received)
        # never more than ``lag`` behind, nor so far behind that unrevealed samples are
        # overwritten by newer ones
        behind = min(self.lag * self.fs, self.cap - self.n - 1)
        speed = 1.25 if newest - self._pos > self._chunk else 1.0
        self._pos = newest if catch_up else min(newest, max(self._pos + speed * dt * self.fs,
                                                            newest - behind))
        if int(self._pos) <= self.shown:
            return False
        self.shown = int(self._pos)
        return True

    def view(self) -> NDArray[np.float64]:
        """The last ``n`` revealed samples of every channel, oldest first (NaN before the
        first sample)."""
        idx = np.arange(self.shown - self.n, self.shown)
        out = self._data[:, idx % self.cap]
        out[:, idx < max(0, self.received - self.cap)] = np.nan  # overwritten: never here
        return out

    def latencies(self, now: float) -> list[float]:
        """Read-to-screen delays (s) of the reads now wholly revealed, each reported once."""
        out = []
        while self._reads and self._reads[0][0] <= self.shown:
            out.append(now - self._reads.pop(0)[1])
        return out
