"""Free decay of a structure ringing after its excitation stopped, and the noise it rings over.

A structure left to itself rings as a sum of damped sinusoids whose poles every channel
shares: :func:`free_decay` fits them on a stretch with no excitation and continues them, so
the ringing an earlier hit or burst leaves in a record can be taken off it, and the tail a
record cuts off can be put back (:mod:`processing.impact`, :mod:`processing.excitation`).
:func:`noise_sigma` reads each channel's white noise from its second differences.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["CARRY_MIN", "CARRY_ORDER", "CARRY_RANK", "CARRY_STRETCH", "FOLD_WRAPS", "free_decay",
           "noise_sigma"]


#: longest stretch before a record fitted by :func:`free_decay`, s
CARRY_STRETCH = 1.5
#: shortest such stretch, s (shorter: the record is used as it is)
CARRY_MIN = 0.25
#: order of the linear prediction of :func:`free_decay` (at most a quarter of the stretch)
CARRY_ORDER = 60
#: a singular value of the prediction's normalised data matrix counts as signal above this
#: many times the square root of its rows (the singular values of unit white noise)
CARRY_RANK = 2.0
#: periods a folded continuation sums at most (:func:`free_decay` with ``fold``)
FOLD_WRAPS = 64


def free_decay(seg: NDArray[np.float64], n_out: int, sigma: NDArray[np.float64],
               order: int = CARRY_ORDER, fold: bool = False) -> NDArray[np.float64]:
    """The continuation over ``n_out`` samples of a free decay ``seg`` (n_ch, n_s); with
    ``fold``, its whole future folded onto ``n_out`` samples (sample j the sum of the
    continuation at j, j + n_out, j + 2 n_out, ...: what a record of ``n_out`` samples
    ending with ``seg`` lacks to hold the periodic response, :data:`FOLD_WRAPS` at most).

    The channels of a structure ringing freely share their poles: each channel, over its
    noise ``sigma`` (n_ch,), is predicted from its previous ``order`` samples by one set of
    coefficients for all channels (least squares, truncated to the singular values above
    :data:`CARRY_RANK` times the unit noise's: Kumaresan-Tufts); the roots of the
    prediction polynomial are the poles (those outside the unit circle brought onto it: a
    free decay does not grow), each channel's complex amplitudes are fitted to its samples,
    and the sum of damped sinusoids continued after ``seg``'s last sample. Zeros when
    nothing stands out of the noise.

    >>> t = np.arange(600) / 100.0
    >>> x = np.exp(-0.3 * t) * np.cos(2 * np.pi * 3.0 * t)
    >>> future = free_decay(x[None, :400], 200, np.array([1e-3]))
    >>> bool(np.allclose(future[0], x[400:], atol=1e-6))
    True
    >>> t = np.arange(4000) / 100.0
    >>> x = np.exp(-0.3 * t) * np.cos(2 * np.pi * 3.0 * t)
    >>> folded = free_decay(x[None, :400], 200, np.array([1e-3]), fold=True)
    >>> bool(np.allclose(folded[0], x[400:].reshape(-1, 200).sum(axis=0), atol=1e-4))
    True
    """
    seg = np.asarray(seg, dtype=float)
    # a channel without noise (simulated, or flat) is scaled by its precision instead:
    # divided by almost nothing its moments overflow
    peak = np.max(np.abs(seg), axis=-1) if seg.size else np.zeros(seg.shape[0])
    sigma = np.maximum(np.asarray(sigma, dtype=float), np.where(peak > 0, 1e-9 * peak, 1.0))
    y = seg / sigma[:, None]
    n_ch, n_s = y.shape
    r = int(min(order, n_s // 4))
    if r < 2:
        return np.zeros((n_ch, n_out))
    w = np.lib.stride_tricks.sliding_window_view(y, r + 1, axis=-1)
    A = w[..., :r][..., ::-1].reshape(-1, r)  # column i: the sample i + 1 before
    b = w[..., r].reshape(-1)
    s2, V = np.linalg.eigh(A.T @ A)  # the squared singular values and right vectors of A
    keep = s2 > CARRY_RANK**2 * A.shape[0]
    if not keep.any():
        return np.zeros((n_ch, n_out))
    Vk = V[:, keep]
    a = Vk @ ((Vk.T @ (A.T @ b)) / s2[keep])
    z = np.roots(np.r_[1.0, -a])
    z = np.where(np.abs(z) > 1, z / np.abs(z), z)
    amp = np.linalg.lstsq(_powers(z, 0, n_s), y.T.astype(complex), rcond=None)[0]
    zn = _powers(z, n_s, n_out)
    if fold:  # the geometric sum over the periods, at most FOLD_WRAPS (an undamped pole)
        zL = z**n_out
        near = np.abs(1 - zL) < 1e-9
        zn = zn * np.where(near, FOLD_WRAPS, (1 - zL**FOLD_WRAPS) / np.where(near, 1, 1 - zL))
    out = np.real(zn @ amp).T
    return np.asarray(out * sigma[:, None], dtype=np.float64)


def _powers(z: NDArray[Any], first: int, n: int) -> NDArray[np.complex128]:
    """``z ** k`` for k = first .. first + n - 1 (rows) and every pole (columns), as
    exp(k log z): a third of the time of complex powers. A decayed pole's powers below the
    smallest double are 0 (numpy 2.4 flags that underflow in a complex exp; earlier
    versions did not)."""
    logz = np.log(np.where(z == 0, 1e-300, z))
    with np.errstate(under="ignore"):
        return np.asarray(np.exp(np.arange(first, first + n)[:, None] * logz[None, :]),
                          dtype=np.complex128)


def noise_sigma(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Standard deviation of each row's white noise, from the second differences (robust:
    the median absolute deviation; slow signals, offsets and drifts barely contribute)."""
    d2 = np.diff(np.asarray(x, dtype=float), 2, axis=-1)
    mad = np.median(np.abs(d2 - np.median(d2, axis=-1, keepdims=True)), axis=-1)
    return np.asarray(1.4826 * mad / np.sqrt(6.0), dtype=np.float64)
