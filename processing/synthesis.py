"""FRFs synthesised from identified M, K, C (, D) and their error against measurement.

``H_syn(w) = E (M - (K + j w C + j D) / w^2)^-1 T`` (article eq. 5, with the structural
damping D), the comparison of the article's Figs. 9 and 13, per FRF and overall.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from processing._kernels import sumsq_rows

__all__ = ["SynthesisFit", "synthesis_error", "synthesise"]


def synthesise(
    freq: NDArray[np.float64],
    E: NDArray[np.float64],
    T: NDArray[np.float64],
    M: NDArray[np.float64],
    K: NDArray[np.float64],
    C: NDArray[np.float64],
    D: NDArray[np.float64] | None = None,
    stiffening: NDArray[np.float64] | None = None,
    decay: float = 0.0,
) -> NDArray[np.complex128]:
    """Accelerance FRFs (n_resp, n_exc, n_f) of the identified rigid-body model.

    Computed by modal superposition of the 12 first-order modes of
    ``M q'' + C q' + (K + j D) q = T f`` (one 12x12 eigenproblem, then one product for all
    lines: the state-space resolvent at ``s = j w`` is ``(K + j D + s C + s^2 M)^-1``
    exactly, a complex stiffness included); falls back to one 6x6 solve per line when the
    modes are nearly defective. ``D`` is the structural damping (none when omitted);
    ``stiffening`` the mounts' ``K(w) / K`` on the lines (K and D stiffen: one 6x6 solve per
    line, ``g (K + j D) + j w C - w^2 M``). ``decay`` (1/s): the FRFs as an exponential
    window ``exp(-decay t)`` on force and responses leaves them, the model's at
    ``s = j w + decay`` (the Laplace shift the identification's windowed fit uses).
    """
    w = 2 * np.pi * np.asarray(freq, dtype=float)
    s = 1j * w + decay
    Kc: NDArray[np.float64] | NDArray[np.complex128] = (
        K if D is None or not np.any(D) else K + 1j * D)
    modal = None if stiffening is not None else _modal_receptance(E, T, M, Kc, C)
    if modal is None:
        g = np.ones_like(w) if stiffening is None else np.asarray(stiffening, dtype=float)
        Z = (g[:, None, None] * Kc[None] + s[:, None, None] * C[None]
             + (s**2)[:, None, None] * M[None])
        A = (s**2)[:, None, None] * np.linalg.solve(Z, np.broadcast_to(T, (len(w), *T.shape)))
        return np.einsum("ra,fae->ref", E, A)
    R, lam = modal  # (n_r * n_e, 12), (12,)
    G = (s**2)[None, :] / (s[None, :] - lam[:, None])  # (12, n_f)
    return (R @ G).reshape(E.shape[0], T.shape[1], w.size)


def _modal_receptance(
    E: NDArray[np.float64], T: NDArray[np.float64], M: NDArray[np.float64],
    K: NDArray[np.floating] | NDArray[np.complexfloating], C: NDArray[np.float64],
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]] | None:
    """Residues ``E V_q diag(.) W M^-1 T`` flattened (n_r n_e, 12) and the 12 poles."""
    try:
        Minv = np.linalg.inv(M)
        A = np.block([[np.zeros((6, 6)), np.eye(6)], [-Minv @ K, -Minv @ C]])
        lam, V = scipy.linalg.eig(A)
        if not np.all(np.isfinite(lam)) or np.linalg.cond(V) > 1e8:
            return None
        W = np.linalg.inv(V)
    except (np.linalg.LinAlgError, ValueError):
        return None
    left = E @ V[:6]  # (n_r, 12)
    right = W[:, 6:] @ (Minv @ T)  # (12, n_e)
    R = (left[:, None, :] * right.T[None, :, :]).reshape(-1, lam.size)
    return R, lam


@dataclass(frozen=True)
class SynthesisFit:
    """How well the FRFs synthesised from M, K, C fit the measured ones over a band.

    ``per_frf`` (n_resp, n_exc): ``||H - H_syn|| / ||H||`` over the band's lines;
    ``overall``: the same over all FRFs; ``sum_measured`` and ``sum_synthesised``:
    modulus of the sum of all FRFs per line (the curves of the article's Figs. 9, 13).
    """

    band: tuple[float, float]
    per_frf: NDArray[np.float64]
    overall: float
    sum_measured: NDArray[np.float64]
    sum_synthesised: NDArray[np.float64]


def synthesis_error(
    freq: NDArray[np.float64],
    H: NDArray[np.complex128],
    H_syn: NDArray[np.complex128],
    band: tuple[float, float],
) -> SynthesisFit:
    """:class:`SynthesisFit` of ``H_syn`` against ``H`` (n_resp, n_exc, n_f) over ``band`` (Hz)."""
    sel = (freq >= band[0]) & (freq <= band[1])
    lo, hi = np.flatnonzero(sel)[[0, -1]] if np.any(sel) else (0, -1)
    Hb = H[..., lo : hi + 1]
    num = sumsq_rows(Hb - H_syn[..., lo : hi + 1])
    den = sumsq_rows(Hb)
    per = np.sqrt(num / np.where(den > 0, den, np.inf))
    overall = float(np.sqrt(num.sum() / max(den.sum(), 1e-300)))
    return SynthesisFit(
        band,
        per,
        overall,
        np.abs(H.sum(axis=(0, 1))),
        np.abs(H_syn.sum(axis=(0, 1))),
    )
