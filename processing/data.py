"""Data model shared by every layer: geometry and FRF sets.

All values are SI. Frequency is the last axis. FRFs are accelerances
(m/s^2 per N) between response DOFs (rows) and excitation DOFs (columns).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["ESTIMATORS", "FRFSet", "Geometry", "InputError"]

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
