"""FRFs synthesised from identified M, K, C and their error against measurement.

``H_syn(w) = E (M - (K + j w C) / w^2)^-1 T`` (article eq. 5), the comparison of
the article's Figs. 9 and 13, per FRF and overall.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["SynthesisError", "synthesis_error", "synthesise"]


def synthesise(
    freq: NDArray[np.float64],
    E: NDArray[np.float64],
    T: NDArray[np.float64],
    M: NDArray[np.float64],
    K: NDArray[np.float64],
    C: NDArray[np.float64],
) -> NDArray[np.complex128]:
    """Accelerance FRFs (n_resp, n_exc, n_f) of the identified rigid-body model."""
    w = 2 * np.pi * np.asarray(freq, dtype=float)
    Z = K[None] + 1j * w[:, None, None] * C[None] - (w**2)[:, None, None] * M[None]
    A = -(w**2)[:, None, None] * np.linalg.solve(Z, np.broadcast_to(T, (len(w), *T.shape)))
    return np.einsum("ra,fae->ref", E, A)


@dataclass(frozen=True)
class SynthesisError:
    """Relative error of synthesised FRFs over a band.

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
) -> SynthesisError:
    sel = (freq >= band[0]) & (freq <= band[1])
    D = H[..., sel] - H_syn[..., sel]
    num = np.sum(np.abs(D) ** 2, axis=-1)
    den = np.sum(np.abs(H[..., sel]) ** 2, axis=-1)
    per = np.sqrt(num / np.where(den > 0, den, np.inf))
    overall = float(np.sqrt(num.sum() / max(den.sum(), 1e-300)))
    return SynthesisError(
        band,
        per,
        overall,
        np.abs(H.sum(axis=(0, 1))),
        np.abs(H_syn.sum(axis=(0, 1))),
    )
