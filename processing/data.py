"""Data model shared by every layer: geometry and FRF sets.

All values are SI. Frequency is the last axis. FRFs are accelerances
(m/s^2 per N) between response DOFs (rows) and excitation DOFs (columns).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["ESTIMATORS", "MAX_UNDEFINED_SHARE", "FRFSet", "Geometry", "InputError", "dof_label",
           "finite_frfs"]

#: the FRF estimators the spectra compute (:mod:`processing.spectral`)
ESTIMATORS = ("H1", "H2", "Hv")


class InputError(ValueError):
    """Input data are unusable; the message names the problem and what to do."""


@dataclass(frozen=True)
class Geometry:
    """Node coordinates in the global frame, m."""

    node_ids: NDArray[np.int64]
    xyz: NDArray[np.float64]

    def __post_init__(self) -> None:
        ids = np.asarray(self.node_ids, dtype=np.int64).ravel()
        xyz = np.asarray(self.xyz, dtype=float).reshape(-1, 3)
        if ids.shape[0] != xyz.shape[0]:
            raise InputError(f"geometry has {ids.shape[0]} node ids but {xyz.shape[0]} points")
        if np.unique(ids).size != ids.size:
            raise InputError("geometry has duplicate node ids: give each node one coordinate set")
        if not np.all(np.isfinite(xyz)):
            raise InputError("geometry has NaN or infinite coordinates: fix the node table")
        object.__setattr__(self, "node_ids", ids)
        object.__setattr__(self, "xyz", xyz)

    def coordinates(self, nodes: NDArray[np.int64], what: str = "node") -> NDArray[np.float64]:
        """Coordinates of ``nodes`` (n, 3); raises InputError naming any node without one."""
        nodes = np.asarray(nodes, dtype=np.int64)
        order = np.argsort(self.node_ids)
        pos = np.searchsorted(self.node_ids, nodes, sorter=order)
        pos = np.clip(pos, 0, self.node_ids.size - 1)
        idx = order[pos]
        missing = self.node_ids[idx] != nodes
        if np.any(missing):
            bad = ", ".join(str(n) for n in np.unique(nodes[missing])[:5])
            raise InputError(
                f"{what} node(s) {bad} have no coordinates: add them to the geometry "
                "(UFF dataset 15 or 2411)"
            )
        return self.xyz[idx]


@dataclass(frozen=True)
class FRFSet:
    """Accelerance FRFs with their measured DOFs.

    Attributes
    ----------
    freq : (n_f,) Hz
    H : (n_resp, n_exc, n_f) complex, (m/s^2)/N
    resp_nodes, exc_nodes : node ids of each response / excitation DOF
    resp_dirs, exc_dirs : (n, 3) unit vectors in the global frame
    geometry : node coordinates
    coherence : optional (n_resp, n_exc, n_f) ordinary (or multiple) coherence

    How the FRFs were obtained (given or estimated here, windows, averages, the hammer's
    band) is not theirs to carry: it is the :class:`processing.measurement.Provenance` of
    the :class:`processing.measurement.Measurement` that holds them.
    """

    freq: NDArray[np.float64]
    H: NDArray[np.complex128]
    resp_nodes: NDArray[np.int64]
    resp_dirs: NDArray[np.float64]
    exc_nodes: NDArray[np.int64]
    exc_dirs: NDArray[np.float64]
    geometry: Geometry
    coherence: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        freq = np.asarray(self.freq, dtype=float).ravel()
        H = np.asarray(self.H)
        if H.ndim != 3:
            raise InputError(f"H must have shape (n_resp, n_exc, n_freq), got {H.shape}")
        H = H.astype(np.complex128, copy=False)
        n_r, n_e, n_f = H.shape
        if freq.size != n_f:
            raise InputError(f"{freq.size} frequencies but H has {n_f} lines")
        rn = np.asarray(self.resp_nodes, dtype=np.int64).ravel()
        en = np.asarray(self.exc_nodes, dtype=np.int64).ravel()
        rd = np.asarray(self.resp_dirs, dtype=float).reshape(-1, 3)
        ed = np.asarray(self.exc_dirs, dtype=float).reshape(-1, 3)
        if rn.size != n_r or rd.shape[0] != n_r:
            raise InputError(f"H has {n_r} response DOFs but {rn.size} response nodes/dirs")
        if en.size != n_e or ed.shape[0] != n_e:
            raise InputError(f"H has {n_e} excitation DOFs but {en.size} excitation nodes/dirs")
        coh = self.coherence
        if coh is not None:
            coh = np.asarray(coh, dtype=float)
            if coh.shape != H.shape:
                raise InputError(f"coherence shape {coh.shape} differs from H shape {H.shape}")
        object.__setattr__(self, "freq", freq)
        object.__setattr__(self, "H", H)
        object.__setattr__(self, "resp_nodes", rn)
        object.__setattr__(self, "exc_nodes", en)
        object.__setattr__(self, "resp_dirs", rd / np.linalg.norm(rd, axis=1, keepdims=True))
        object.__setattr__(self, "exc_dirs", ed / np.linalg.norm(ed, axis=1, keepdims=True))
        object.__setattr__(self, "coherence", coh)

    def select_lines(self, fmax: float | None = None) -> FRFSet:
        """The set on its lines above 0 Hz and up to ``fmax`` Hz (every line above 0 Hz when
        None), where accelerance and coherence are defined; NaN coherence counts as 0 (it
        fails the coherence gate). Returns ``self`` when nothing changes.

        Parameters
        ----------
        fmax : highest line kept, Hz (the usable band of a measurement is fs / 2.56, where
            the front ends' anti-alias filters start to shape the data:
            :meth:`anti_alias_fmax`)
        """
        keep = self.freq > 0
        if fmax is not None:
            keep &= self.freq <= fmax
        coh = self.coherence
        if np.all(keep) and (coh is None or np.all(np.isfinite(coh))):
            return self
        if coh is not None:
            coh = np.nan_to_num(coh[..., keep])
        return FRFSet(self.freq[keep], self.H[..., keep], self.resp_nodes, self.resp_dirs,
                      self.exc_nodes, self.exc_dirs, self.geometry, coh)

    def anti_alias_fmax(self) -> float:
        """fs / 2.56, Hz, for a set whose last line is the Nyquist frequency fs / 2 (a
        measured spectrum): above it the front ends' anti-alias filters shape the data."""
        return float(self.freq[-1] / 1.28)

    @property
    def resp_xyz(self) -> NDArray[np.float64]:
        return self.geometry.coordinates(self.resp_nodes, "response")

    @property
    def exc_xyz(self) -> NDArray[np.float64]:
        return self.geometry.coordinates(self.exc_nodes, "excitation")


#: largest share of an FRF set's lines that NaN or infinite FRF values may take out of it
#: (more: the set is refused, naming the FRFs; a few bad lines are left out with a word)
MAX_UNDEFINED_SHARE = 0.1
#: FRFs and line ranges a message names at most (then "and N more")
_NAMED = 4


def dof_label(node: int, direction: NDArray[np.float64]) -> str:
    """``12+X`` for node 12 along +X (``12(0.71,0.71,0)`` off the global axes)."""
    d = np.asarray(direction, dtype=float)
    k = int(np.argmax(np.abs(d)))
    if np.isclose(abs(d[k]), 1.0, atol=1e-6):
        return f"{node}{'+' if d[k] > 0 else '-'}{'XYZ'[k]}"
    return f"{node}({','.join(f'{v:.2g}' for v in d)})"


def _named(items: list[str], noun: str) -> str:
    """``noun a, b, c`` with at most :data:`_NAMED` items, then ``and N more``."""
    more = len(items) - _NAMED
    return (f"{noun} " + ", ".join(items[:_NAMED])
            + (f" and {more} more" if more > 0 else ""))


def _frf_names(frf: FRFSet, bad: NDArray[np.bool_]) -> str:
    """The FRFs (response/excitation DOFs) with a bad value somewhere, compactly."""
    pairs = [f"{dof_label(frf.resp_nodes[r], frf.resp_dirs[r])}/"
             f"{dof_label(frf.exc_nodes[e], frf.exc_dirs[e])}" for r, e in np.argwhere(bad)]
    return _named(pairs, "FRF" if len(pairs) == 1 else "FRFs") + " (response/excitation)"


def _line_ranges(freq: NDArray[np.float64], lines: NDArray[np.bool_]) -> str:
    """``12.5-13, 40 Hz``: the runs of consecutive lines, compactly."""
    idx = np.flatnonzero(lines)
    starts = np.r_[0, np.flatnonzero(np.diff(idx) > 1) + 1]
    ends = np.r_[starts[1:] - 1, idx.size - 1]
    runs = [f"{freq[idx[a]]:g}" if a == b else f"{freq[idx[a]]:g}-{freq[idx[b]]:g}"
            for a, b in zip(starts, ends, strict=True)]
    more = len(runs) - _NAMED
    return ", ".join(runs[:_NAMED]) + (f" and {more} more ranges" if more > 0 else "") + " Hz"


def _lines(n: int) -> str:
    return f"{n} line{'s' if n != 1 else ''}"


def finite_frfs(frf: FRFSet, name: str = "the FRFs") -> tuple[FRFSet, tuple[str, ...]]:
    """The set without its NaN or infinite values, and one line naming each kind found.

    A line where any FRF value is NaN or infinite is left out of every FRF (the rigid-body
    fits solve all FRFs of a line together); a NaN or infinite coherence value counts as
    coherence 0 (that FRF value is weighed as noise: next to no weight in the fit). Each
    line names the FRFs by response/excitation DOF (``12+X/3-Z``) and the frequencies.

    Parameters
    ----------
    frf : the FRF set as read
    name : what the messages call it (a file's name)

    Returns
    -------
    (FRFSet, tuple of str)
        ``frf`` itself and no line when every value is finite.

    Raises
    ------
    InputError
        Every FRF value undefined, or more than :data:`MAX_UNDEFINED_SHARE` of the lines
        (or all but one) hold an undefined FRF value: one line naming the FRFs and lines.
    """
    H, coh = frf.H, frf.coherence
    bad_h = ~np.isfinite(H)
    bad_c = None if coh is None else ~np.isfinite(coh)
    if not bad_h.any() and (bad_c is None or not bad_c.any()):
        return frf, ()
    n_f = frf.freq.size
    if bad_h.all():
        raise InputError(f"{name}: every FRF value is NaN or infinite: re-export the FRFs")
    said: list[str] = []
    keep = ~np.any(bad_h, axis=(0, 1))
    n_out = n_f - int(np.count_nonzero(keep))
    if n_out:
        frfs = _frf_names(frf, np.any(bad_h, axis=2))
        ranges = _line_ranges(frf.freq, ~keep)
        if n_out > MAX_UNDEFINED_SHARE * n_f or n_f - n_out < 2:
            raise InputError(f"{name}: NaN or infinite values in {frfs} on {n_out} of {n_f} "
                             f"lines ({ranges}): more than {MAX_UNDEFINED_SHARE:.0%} of the "
                             "lines; re-measure or re-export those FRFs, or leave their DOFs "
                             "out of the file")
        said.append(f"{name}: NaN or infinite values in {frfs} on {_lines(n_out)} ({ranges}): "
                    "those lines are left out of every FRF")
    if bad_c is not None:
        bad_c = bad_c & keep
        if bad_c.any():
            assert coh is not None
            on = np.any(bad_c, axis=(0, 1))
            said.append(f"{name}: NaN or infinite coherence in "
                        f"{_frf_names(frf, np.any(bad_c, axis=2))} on "
                        f"{_lines(int(np.count_nonzero(on)))} ({_line_ranges(frf.freq, on)}): "
                        "those values count as coherence 0 (next to no weight in the fit)")
            coh = np.where(bad_c, 0.0, coh)
    out = FRFSet(frf.freq[keep], H[..., keep], frf.resp_nodes, frf.resp_dirs, frf.exc_nodes,
                 frf.exc_dirs, frf.geometry, None if coh is None else coh[..., keep])
    return out, tuple(said)
