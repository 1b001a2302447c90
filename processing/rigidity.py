"""Rigidity check (article section 5.1, Fig. 8): predict each accelerometer from the others.

For each response node (the DOFs of one triaxial accelerometer), the rigid-body
accelerances at O are fitted to the *other* nodes' FRFs,
``X = pinv(E_others) H_others``, and the node's FRFs predicted as ``E_node X``
(:func:`processing.geometry.response_matrix`). Where the body moves rigidly the
prediction matches the measurement; elastic modes (or a loose sensor, or a wrong
coordinate) make them differ. The relative error per line,
``||H_pred - H||_F / ||H||_F`` over the node's DOFs and all excitations, is given per
node and overall; the rigid band runs from the lowest line up to the first
sustained stretch where the worst node's error exceeds the threshold. The
identification bounds its mass-line band by it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.data import FRFSet
from processing.geometry import GeometryError, response_matrix

__all__ = ["DEFAULT_RIGIDITY_THRESHOLD", "RigidityCheck", "rigidity_check"]

#: Largest relative prediction error still called rigid.
DEFAULT_RIGIDITY_THRESHOLD = 0.10


@dataclass(frozen=True)
class RigidityCheck:
    """Result of :func:`rigidity_check`.

    Attributes
    ----------
    freq : (n_f,) Hz
    nodes : (n_nodes,) response node ids, in order of first appearance
    error : (n_nodes, n_f) relative prediction error of each node (NaN where it has no signal)
    overall : (n_f,) relative error of all nodes together
    predicted : (n_resp, n_exc, n_f) each response DOF predicted from the other nodes
    threshold : float
    band : (f_low, f_high) Hz, or None when not even the lowest line is rigid
    """

    freq: NDArray[np.float64]
    nodes: NDArray[np.int64]
    error: NDArray[np.float64]
    overall: NDArray[np.float64]
    predicted: NDArray[np.complex128]
    threshold: float
    band: tuple[float, float] | None

    def __post_init__(self) -> None:
        n_f = self.freq.size
        if self.error.shape != (self.nodes.size, n_f) or self.overall.shape != (n_f,):
            raise ValueError("rigidity error arrays do not match nodes x lines")
        if self.predicted.ndim != 3 or self.predicted.shape[-1] != n_f:
            raise ValueError("predicted FRFs must have shape (n_resp, n_exc, n_f)")

    @property
    def worst(self) -> NDArray[np.float64]:
        """(n_f,) error of the worst node at each line."""
        with np.errstate(invalid="ignore"):
            return np.asarray(np.max(np.where(np.isnan(self.error), -np.inf, self.error), axis=0))

    def band_at(self, threshold: float, sustain: int = 3, fmin: float = 0.0) -> (
        tuple[float, float] | None
    ):
        """The rigid band (Hz) for another threshold (see :func:`rigidity_check`)."""
        worst = self.worst
        valid = (self.freq >= fmin) & np.isfinite(worst)
        return _rigid_band(self.freq, worst, valid, threshold, sustain)

    def error_floor(self, fmin: float = 0.0) -> float:
        """Lower quartile of the worst node's error over the lines (the noise floor)."""
        worst = self.worst
        valid = (self.freq >= fmin) & np.isfinite(worst)
        return float(np.percentile(worst[valid], 25)) if np.any(valid) else 0.0

    @property
    def passed(self) -> bool:
        """True when some band at the bottom of the spectrum is rigid."""
        return self.band is not None

    def summary(self) -> str:
        if self.band is None:
            return (
                f"rigidity check failed: prediction error above {self.threshold:.0%} "
                "from the lowest line"
            )
        return (
            f"body rigid from {self.band[0]:g} to {self.band[1]:g} Hz "
            f"(rigid-body prediction error of every accelerometer <= {self.threshold:.0%})"
        )


def _prediction_matrix(xyz: NDArray[np.float64], dirs: NDArray[np.float64],
                       groups: NDArray[np.int64], nodes: NDArray[np.int64]) -> NDArray[np.float64]:
    """R (n_resp, n_resp): row block of node n = E_n pinv(E_others), zero on n's own columns."""
    E = response_matrix(xyz, dirs)
    n_resp = E.shape[0]
    R = np.zeros((n_resp, n_resp))
    for k, node in enumerate(nodes):  # set-up over nodes (a handful), not a hot path
        own = groups == k
        Eo = E[~own]
        if np.linalg.matrix_rank(Eo / np.maximum(np.abs(Eo).max(axis=0), 1e-12)) < 6:
            raise GeometryError(
                f"rigidity check: the response DOFs other than node {node} do not span the six "
                "rigid-body motions (are the other nodes collinear?): measure at least three "
                "non-collinear triaxial points"
            )
        R[np.ix_(own, ~own)] = E[own] @ np.linalg.pinv(Eo)
    return R


def rigidity_check(
    frfs: FRFSet,
    *,
    threshold: float = DEFAULT_RIGIDITY_THRESHOLD,
    sustain: int = 3,
    fmin: float = 0.0,
) -> RigidityCheck:
    """Predict every accelerometer from the others by rigid-body kinematics.

    Parameters
    ----------
    frfs : FRFSet
        Accelerances; the response DOFs are grouped by node (one node, one accelerometer).
    threshold : float
        Largest relative error called rigid (10 % by default).
    sustain : int
        Consecutive lines above the threshold that end the rigid band; shorter
        excursions (a noisy line, an anti-resonance) do not.
    fmin : float
        Lowest frequency considered for the band, Hz (lines below, e.g. 0 Hz, are ignored).

    Raises
    ------
    GeometryError
        With fewer than three response nodes, or when the other nodes of some node
        cannot determine the six rigid-body motions.

    Examples
    --------
    >>> from hardware_mocks.benches import get_bench  # doctest: +SKIP
    >>> rigidity_check(get_bench("engine").frfset()).band  # doctest: +SKIP
    """
    if not 0 < threshold:
        raise ValueError(f"rigidity threshold must be positive, got {threshold}")
    if sustain < 1:
        raise ValueError(f"sustain must be >= 1 line, got {sustain}")
    nodes, first, groups = np.unique(frfs.resp_nodes, return_index=True, return_inverse=True)
    if nodes.size < 3:
        raise GeometryError(
            f"rigidity check needs at least 3 response nodes (each predicted from >= 2 others), "
            f"got {nodes.size}"
        )
    order = np.argsort(first)  # nodes in order of first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    nodes, groups = nodes[order], rank[groups]
    R = _prediction_matrix(frfs.resp_xyz, frfs.resp_dirs, groups, nodes)
    H = frfs.H
    pred = np.einsum("rs,sef->ref", R, H)
    onehot = (groups[None, :] == np.arange(nodes.size)[:, None]).astype(float)  # (n_nodes, n_resp)
    num = onehot @ np.sum(np.abs(pred - H) ** 2, axis=1)  # (n_nodes, n_f)
    den = onehot @ np.sum(np.abs(H) ** 2, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.sqrt(num / den)
        overall = np.sqrt(num.sum(axis=0) / den.sum(axis=0))
    err = np.where(den > 0, err, np.nan)
    overall = np.where(den.sum(axis=0) > 0, overall, np.nan)
    worst = np.max(np.where(np.isnan(err), -np.inf, err), axis=0)
    valid = (frfs.freq >= fmin) & np.isfinite(worst)
    band = _rigid_band(frfs.freq, worst, valid, threshold, sustain)
    return RigidityCheck(frfs.freq, nodes, err, overall, pred, float(threshold), band)


def _rigid_band(
    freq: NDArray[np.float64], worst: NDArray[np.float64], valid: NDArray[np.bool_],
    threshold: float, sustain: int,
) -> tuple[float, float] | None:
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        return None
    e = worst[idx]
    over = e > threshold
    # first line that starts `sustain` consecutive lines above the threshold
    c = np.concatenate([[0], np.cumsum(over)])
    k = min(sustain, over.size)
    starts = np.flatnonzero(c[k:] - c[:-k] >= k)
    end = starts[0] if starts.size else over.size
    if end == 0:
        return None
    return float(freq[idx[0]]), float(freq[idx[end - 1]])
