"""Peaks of a line spectrum by prominence, and its running median, as array operations.

The same answers as ``scipy.signal.find_peaks(x, prominence=p)[0]`` and
``scipy.ndimage.median_filter(x, size, mode="nearest")`` (the tests hold them to it), without
importing ``scipy.signal``: since SciPy 1.17 that import parses the docstrings of the whole
module and pulls in ``scipy.stats``, about 0.3 s at every start of ``insitu identify``, which
needs nothing else from it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def local_maxima(x: NDArray[np.float64]) -> NDArray[np.intp]:
    """Indices of the local maxima of ``x``: samples (or the middle of a flat run of equal
    samples, rounded down) higher than both neighbours; the first and last samples are
    never maxima."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3:
        return np.zeros(0, dtype=np.intp)
    # runs of equal samples: their first and last indices and their value
    starts = np.flatnonzero(np.concatenate(([True], x[1:] != x[:-1])))
    ends = np.concatenate((starts[1:] - 1, [x.size - 1]))
    v = x[starts]
    inner = np.arange(1, v.size - 1)
    peak = inner[(v[inner - 1] < v[inner]) & (v[inner + 1] < v[inner])]
    return np.asarray((starts[peak] + ends[peak]) // 2, dtype=np.intp)


def prominences(x: NDArray[np.float64], peaks: NDArray[np.intp]) -> NDArray[np.float64]:
    """Each peak's prominence: its height over the higher of the two lowest samples between it
    and the nearest strictly higher sample on either side (or the end of ``x``)."""
    x = np.asarray(x, dtype=np.float64)
    if peaks.size == 0:
        return np.zeros(0)
    idx = np.arange(x.size)
    top = x[peaks][:, None]  # (n_peaks, 1)
    higher = x[None, :] > top
    left = np.where(higher & (idx < peaks[:, None]), idx, -1).max(axis=1) + 1
    right = np.where(higher & (idx > peaks[:, None]), idx, x.size).min(axis=1) - 1
    left_min = np.where((idx >= left[:, None]) & (idx <= peaks[:, None]), x, np.inf).min(axis=1)
    right_min = np.where((idx >= peaks[:, None]) & (idx <= right[:, None]), x, np.inf).min(axis=1)
    return np.asarray(x[peaks] - np.maximum(left_min, right_min))


def find_prominent(x: NDArray[np.float64], prominence: float) -> NDArray[np.intp]:
    """Indices of the local maxima of ``x`` whose prominence is at least ``prominence``."""
    peaks = local_maxima(x)
    return peaks[prominences(x, peaks) >= prominence]


def running_median(x: NDArray[np.float64], size: int) -> NDArray[np.float64]:
    """The median of each sample's centred window of ``size`` samples (odd), the ends extended
    with the first and last samples."""
    if size < 1 or size % 2 == 0:
        raise ValueError(f"running_median: the window must be an odd number of samples, not {size}")
    x = np.asarray(x, dtype=np.float64)
    padded = np.pad(x, size // 2, mode="edge")
    return np.asarray(np.median(np.lib.stride_tricks.sliding_window_view(padded, size), axis=1))
