"""The coherence gate: FRF values below a coherence threshold are kept out of the identification.

The article requires coherence above 0.8 on every FRF used (section 5). The gate
flags each FRF value (response, excitation, line) below the threshold, the lines
where any FRF fails (those the identification must not select), and summarises
how many values were dropped, in which FRFs and over which frequency ranges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["DEFAULT_COHERENCE_THRESHOLD", "CoherenceGate", "coherence_gate"]

#: The article's minimum coherence (section 5).
DEFAULT_COHERENCE_THRESHOLD = 0.8


@dataclass(frozen=True)
class CoherenceGate:
    """Which FRF values pass the coherence threshold.

    Attributes
    ----------
    threshold : float
    freq : (n_f,) Hz
    mask : (n_resp, n_exc, n_f) bool
        True where the FRF value is usable (coherence >= threshold, NaN fails).
    line_ok : (n_f,) bool
        True on lines where every FRF passes: the lines the identification may select.
    dropped_per_frf : (n_resp, n_exc) int
        Lines dropped in each FRF.
    ranges : tuple of (f_low, f_high) Hz
        Contiguous frequency ranges of the lines that are not ``line_ok``.
    """

    threshold: float
    freq: NDArray[np.float64]
    mask: NDArray[np.bool_]
    line_ok: NDArray[np.bool_]
    dropped_per_frf: NDArray[np.int64]
    ranges: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        n_f = self.freq.shape[-1]
        if self.mask.ndim != 3 or self.mask.shape[-1] != n_f:
            raise ValueError(f"mask must have shape (n_resp, n_exc, {n_f}), got {self.mask.shape}")
        if self.line_ok.shape != (n_f,) or self.dropped_per_frf.shape != self.mask.shape[:2]:
            raise ValueError("line_ok / dropped_per_frf shapes do not match the mask")

    @property
    def n_dropped(self) -> int:
        """FRF values (response x excitation x line) below the threshold."""
        return int(self.mask.size - np.count_nonzero(self.mask))

    @property
    def n_lines_dropped(self) -> int:
        """Lines where at least one FRF is below the threshold."""
        return int(self.line_ok.size - np.count_nonzero(self.line_ok))

    @property
    def frfs_affected(self) -> tuple[tuple[int, int], ...]:
        """(response, excitation) index pairs of the FRFs with at least one dropped line."""
        r, e = np.nonzero(self.dropped_per_frf)
        return tuple(zip(r.tolist(), e.tolist(), strict=True))

    def summary(self) -> str:
        """One line: what was dropped and where."""
        if self.n_dropped == 0:
            return f"coherence >= {self.threshold:g} on every FRF value"
        where = ", ".join(f"{lo:g}-{hi:g} Hz" for lo, hi in self.ranges[:6])
        more = f" and {len(self.ranges) - 6} more ranges" if len(self.ranges) > 6 else ""
        return (
            f"coherence < {self.threshold:g}: {self.n_dropped} of {self.mask.size} FRF values "
            f"in {len(self.frfs_affected)} of {self.dropped_per_frf.size} FRFs; "
            f"{self.n_lines_dropped} of {self.line_ok.size} lines excluded ({where}{more})"
        )


def _runs(bad: NDArray[np.bool_], freq: NDArray[np.float64]) -> tuple[tuple[float, float], ...]:
    edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1) - 1
    return tuple(zip(freq[starts].tolist(), freq[stops].tolist(), strict=True))


def coherence_gate(
    coherence: ArrayLike,
    freq: ArrayLike,
    threshold: float = DEFAULT_COHERENCE_THRESHOLD,
) -> CoherenceGate:
    """Flag FRF values whose coherence is below ``threshold``.

    Parameters
    ----------
    coherence : (n_resp, n_exc, n_f) array in [0, 1]
    freq : (n_f,) Hz
    threshold : float
        Minimum coherence (0.8, the article's, by default).

    Examples
    --------
    >>> import numpy as np
    >>> coh = np.ones((2, 1, 5)); coh[1, 0, 2:4] = 0.5
    >>> gate = coherence_gate(coh, np.arange(5.0))
    >>> gate.line_ok.tolist(), gate.ranges
    ([True, True, False, False, True], ((2.0, 3.0),))
    """
    coh = np.asarray(coherence, dtype=float)
    f = np.asarray(freq, dtype=float).ravel()
    if coh.ndim != 3 or coh.shape[-1] != f.size:
        raise ValueError(f"coherence must have shape (n_resp, n_exc, {f.size}), got {coh.shape}")
    if not 0 <= threshold <= 1:
        raise ValueError(f"coherence threshold must be in [0, 1], got {threshold}")
    mask = coh >= threshold  # NaN compares False: dropped
    line_ok = np.all(mask, axis=(0, 1))
    dropped = np.sum(~mask, axis=-1).astype(np.int64)
    return CoherenceGate(float(threshold), f, mask, line_ok, dropped, _runs(~line_ok, f))
