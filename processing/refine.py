"""Response-point locations refined from the data (beyond the article).

A measured point location error ``e_p`` of a triaxial sensor at point ``p``
moves its rows of E, so the synthesised rigid-body motions no longer match the
measured FRFs: row ``r`` (direction ``d_r``) of the mass-line residual is
``H_r - E_r Y = -e_p . (d_r x omega)`` to first order, with ``Y`` the model's
acceleration at O and ``omega`` its angular part. Given the identified M, K, C
the offsets follow from one regularised linear least-squares solve over the
mass-line lines; :func:`processing.identify.identify` alternates this with the
identification (``IdentifyOptions.refine_points``).

The forces tie the frame: a translation of the whole response cloud relative to
the excitation points breaks the symmetry of M and is seen; the small ridge
term (``ridge`` times the mean diagonal) only settles what the data do not fix.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from processing.geometry import response_matrix

__all__ = ["point_offsets"]


def point_offsets(
    freq: NDArray[np.float64],
    H: NDArray[np.complex128],
    resp_xyz: NDArray[np.float64],
    resp_dirs: NDArray[np.float64],
    T: NDArray[np.float64],
    M: NDArray[np.float64],
    K: NDArray[np.float64],
    C: NDArray[np.float64],
    *,
    shapes: NDArray[np.complex128] | None = None,
    ridge: float = 1e-3,
    applied: NDArray[np.float64] | None = None,
    D: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Estimated location error (n_resp, 3), m, of each response DOF's point.

    Channels at the same coordinates share one offset. ``freq``/``H`` are the
    lines to use (the mass line), H (n_resp, n_exc, n_lines) accelerance.
    The corrected locations are ``resp_xyz - offsets``. ``shapes`` (n_shapes,
    n_lines) are frequency shapes of elastic leakage (see
    :func:`processing.selection.mode_shape_basis`); a free real multiple of each per
    FRF is eliminated first, so leakage is not taken for a location error.
    ``applied`` (n_resp, 3), m: corrections already subtracted from the nominal
    locations; the ridge then holds the total correction (applied + returned), not
    the step, so repeated rounds settle instead of drifting along what the data
    do not fix. ``D`` is the structural damping of ``K* = K + j w C + j D`` (none when
    omitted).
    """
    w = 2 * np.pi * np.asarray(freq, dtype=float)
    E = response_matrix(resp_xyz, resp_dirs)
    Z = K[None] + 1j * w[:, None, None] * C[None] - (w**2)[:, None, None] * M[None]
    if D is not None:
        Z = Z + 1j * D[None]
    Y = -(w**2)[:, None, None] * np.linalg.solve(Z, np.broadcast_to(T, (w.size, *T.shape)))
    R = H - np.einsum("ra,lae->rel", E, Y)  # (n_r, n_e, n_l)
    d = resp_dirs / np.linalg.norm(resp_dirs, axis=1, keepdims=True)
    _, point = np.unique(np.round(resp_xyz, 9), axis=0, return_inverse=True)
    point = point.ravel()
    n_p = int(point.max()) + 1
    omega = np.moveaxis(Y[:, 3:, :], 1, -1)  # (n_l, n_e, 3)
    dxo = np.cross(d[:, None, None, :], omega[None], axis=-1)  # (n_r, n_l, n_e, 3)
    onehot = np.eye(n_p)[point]  # (n_r, n_p)
    A = -np.einsum("rlek,rp->relpk", dxo, onehot).reshape(-1, 3 * n_p)  # (n_r n_e n_l, 3 n_p)
    n_r, n_e, n_l = R.shape
    # real-stack along frequency per FRF: (n_r n_e, 2 n_l) and (n_r n_e, 2 n_l, 3 n_p)
    A4 = np.concatenate([A.real, A.imag], axis=0).reshape(2, n_r * n_e, n_l, -1)
    A3 = np.moveaxis(A4, 0, 1).reshape(n_r * n_e, 2 * n_l, -1)
    r2 = np.concatenate([R.real, R.imag], axis=-1).reshape(n_r * n_e, 2 * n_l)
    if shapes is not None and len(shapes):
        S = np.concatenate([np.asarray(shapes).real, np.asarray(shapes).imag], axis=-1).T
        Q, _ = np.linalg.qr(S)  # (2 n_l, s): the same for every FRF
        r2 = r2 - (r2 @ Q) @ Q.T
        A3 = A3 - np.einsum("ls,fsk->flk", Q, np.einsum("ls,flk->fsk", Q, A3))
    Ar = A3.reshape(-1, A3.shape[-1])
    rr = r2.ravel()
    N = Ar.T @ Ar
    N += ridge * np.mean(np.diag(N)) * np.eye(3 * n_p)
    rhs = Ar.T @ rr
    if applied is not None:  # ridge on the total: (N + l I) e = A^T r - l c
        first = np.unique(point, return_index=True)[1]
        c = np.asarray(applied, float)[first].ravel()
        rhs = rhs - ridge * np.mean(np.diag(Ar.T @ Ar)) * c
    e = np.linalg.solve(N, rhs)
    return np.asarray(e.reshape(n_p, 3)[point])
