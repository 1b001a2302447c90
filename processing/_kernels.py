"""Small numeric kernels shared by the identification modules (no I/O)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["real_times_complex", "sumsq_columns", "sumsq_rows"]


def sumsq_columns(Z: NDArray[np.complexfloating]) -> NDArray[np.float64]:
    """``sum |Z[..., j]|^2`` over all leading axes, per index j of the last axis.

    One pass over the interleaved real/imaginary view, with no temporary the size
    of Z (the last axis must be contiguous, as in any slice of a C-ordered array).
    """
    Z = np.asarray(Z, dtype=np.complex128)
    if Z.strides[-1] != Z.itemsize:
        Z = np.ascontiguousarray(Z)
    V = Z.view(np.float64)
    lead = "abcdefgh"[: Z.ndim - 1]
    s = np.einsum(f"{lead}k,{lead}k->k", V, V)
    return np.asarray(s.reshape(Z.shape[-1], 2).sum(axis=1))


def sumsq_rows(Z: NDArray[np.complexfloating]) -> NDArray[np.float64]:
    """``sum_j |Z[..., j]|^2`` over the last axis, for each leading index."""
    Z = np.asarray(Z, dtype=np.complex128)
    if Z.strides[-1] != Z.itemsize:
        Z = np.ascontiguousarray(Z)
    V = Z.view(np.float64)
    lead = "abcdefgh"[: Z.ndim - 1]
    return np.asarray(np.einsum(f"{lead}k,{lead}k->{lead}", V, V))


def real_times_complex(A: NDArray[np.floating], Z: NDArray[np.complexfloating]) -> (
    NDArray[np.complex128]
):
    """``A @ Z`` for real A (p, n) and complex Z (n, m), as one real product on Z's view."""
    V = np.ascontiguousarray(Z, dtype=np.complex128).view(np.float64)  # (n, 2m)
    return np.asarray(np.ascontiguousarray(A @ V).view(np.complex128))
