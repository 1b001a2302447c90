"""Time windows for impact testing and the correction of the damping the exponential window adds.

An exponential window ``w(t) = exp(-t / tau)`` applied to the force *and* the
responses of a record, with ``t`` counted from the first sample of the record,
turns the measured pair into the input and output of another linear system,
the measured one with every pole moved left by ``a = 1 / tau``:

    y(t) w(t) = integral h(t - u) w(t - u) f(u) w(u) du   =>   H_w(j omega) = H(j omega + a)

So the FRF estimated from windowed records is exact for that system, and what
it adds is known exactly:

- a mode (omega_n, zeta) appears with decay rate ``zeta omega_n + a``: to first
  order the window adds ``1 / (tau omega_n)`` to the damping ratio
  (:func:`correct_modal_damping` removes it exactly);
- the dynamic stiffness identified at O from windowed accelerances,
  ``K*_m(omega) = omega^2 (M X_w - T) X_w^+``, is
  ``K*_m = -(omega^2 / s^2)(K + s C)`` with ``s = j omega + a``; the inertia (mass
  line) is unaffected. :func:`correct_dynamic_stiffness` recovers ``K + j omega C``.

A force window keeps the pulse and removes the noise of the force channel
elsewhere; it multiplies the exponential window on the force channel.

:func:`window_samples` gives the spectral windows (Hann, ...) the Welch estimates use.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "correct_dynamic_stiffness",
    "correct_modal_damping",
    "exponential_tau",
    "exponential_window",
    "force_window",
    "window_samples",
]


def force_window(n: int, stop: ArrayLike, taper: ArrayLike = 0, start: ArrayLike = 0) -> NDArray[
    np.float64
]:
    """Force window(s): 1 on ``[start, stop)``, a half-cosine to 0 over ``taper`` samples, then 0.

    Parameters
    ----------
    n : int
        Record length, samples.
    stop, taper, start : int or (k,) arrays of int, samples
        One window per element (broadcast together); ``start`` defaults to 0.

    Returns
    -------
    (n,) or (k, n) array

    Examples
    --------
    >>> force_window(6, stop=2, taper=2)
    array([1.  , 1.  , 0.75, 0.25, 0.  , 0.  ])
    """
    stop_a, taper_a, start_a = np.broadcast_arrays(
        np.asarray(stop, int), np.asarray(taper, int), np.asarray(start, int)
    )
    if np.any(taper_a < 0) or np.any(stop_a < start_a):
        raise ValueError("force window needs taper >= 0 and stop >= start")
    i = np.arange(n)
    s, t, b = stop_a[..., None], taper_a[..., None], start_a[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        ramp = 0.5 * (1 + np.cos(np.pi * (i - s + 1) / (t + 1)))
    w = np.where(i < s, 1.0, np.where(i < s + t, ramp, 0.0))
    return np.where(i < b, 0.0, w)


def exponential_window(n: int, fs: float, tau: float) -> NDArray[np.float64]:
    """``exp(-t / tau)`` for ``t = k / fs``, k = 0..n-1 (tau in s), counted from the record start.

    Apply it to the force and every response of the record; see the module notes.
    """
    if not tau > 0:
        raise ValueError(f"exponential window time constant must be positive, got {tau}")
    return np.exp(-np.arange(n) / (fs * tau))


def exponential_tau(duration: float, end_value: float = 0.01) -> float:
    """Time constant (s) of an exponential window falling to ``end_value`` after ``duration`` s."""
    if not 0 < end_value < 1:
        raise ValueError(f"end_value must be in (0, 1), got {end_value}")
    return float(duration / -np.log(end_value))


def correct_modal_damping(
    freq: ArrayLike, zeta: ArrayLike, tau: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Natural frequencies (Hz) and damping ratios without the exponential window's damping.

    The pole ``-zeta w + j w sqrt(1 - zeta^2)`` identified on windowed data is moved
    right by ``1 / tau``; to first order ``zeta_true = zeta - 1 / (tau omega_n)``.

    Examples
    --------
    >>> f, z = correct_modal_damping(10.0, 0.05, tau=1.0)
    >>> round(float(z), 4)  # 0.05 - 1/(2 pi 10)
    0.0341
    """
    w = 2 * np.pi * np.asarray(freq, dtype=float)
    z = np.asarray(zeta, dtype=float)
    pole = -z * w + 1j * w * np.sqrt(np.clip(1 - z**2, 0.0, None)) + 1.0 / tau
    wn = np.abs(pole)
    return wn / (2 * np.pi), -pole.real / wn


def correct_dynamic_stiffness(
    kstar: ArrayLike, freq: ArrayLike, tau: float
) -> NDArray[np.complex128]:
    """``K + j omega C`` from a dynamic stiffness identified on exponentially windowed FRFs.

    Parameters
    ----------
    kstar : (..., n_f) complex
        Identified ``K*_m(omega)`` (e.g. (6, 6, n_f)), frequency last.
    freq : (n_f,) Hz, all > 0
    tau : float
        Exponential window time constant, s.

    Notes
    -----
    With ``a = 1 / tau`` and ``s = j omega + a``:
    ``P = -(s^2 / omega^2) K*_m = K + a C + j omega C``,
    so ``C = Im P / omega`` and ``K + j omega C = P - a Im(P) / omega``. Exact for a
    viscous model (K, C constant); for a frequency-dependent K* it holds to first
    order in ``a / omega``.
    """
    f = np.asarray(freq, dtype=float)
    if np.any(f <= 0):
        raise ValueError("correct_dynamic_stiffness needs frequencies above 0 Hz")
    w = 2 * np.pi * f
    a = 1.0 / tau
    P = (1 - 1j * a / w) ** 2 * np.asarray(kstar, dtype=complex)
    return np.asarray(P - a * P.imag / w)


#: the cosine-sum windows by the names :func:`scipy.signal.get_window` takes for them, and
#: their coefficients as SciPy's ``general_cosine`` sums them
_COSINE_WINDOWS: dict[str, tuple[float, ...]] = {
    **dict.fromkeys(("hann", "han"), (0.5, 0.5)),
    **dict.fromkeys(("hamming", "hamm", "ham"), (0.54, 1.0 - 0.54)),
    **dict.fromkeys(("blackman", "black", "blk"), (0.42, 0.50, 0.08)),
    **dict.fromkeys(("flattop", "flat", "flt"),
                    (0.21557895, 0.41663158, 0.277263158, 0.083578947, 0.006947368)),
    **dict.fromkeys(("boxcar", "box", "ones", "rect", "rectangular"), (1.0,)),
}


def window_samples(window: str | tuple[object, ...] | ArrayLike, n: int) -> NDArray[np.float64]:
    """The periodic window of ``n`` samples that :func:`scipy.signal.get_window` gives for
    ``window`` (a name or a name and its parameters), or ``window`` itself (samples).

    Hann, Hamming, Blackman, flat top and rectangular are summed here as SciPy sums them
    (the same bits, tested): importing ``scipy.signal`` takes about 40 MB and 0.3 s, which
    every time-data identification would pay for a Hann window. Raises ``ValueError`` or
    ``TypeError`` (from SciPy) for a window it does not know.
    """
    if isinstance(window, str) and window in _COSINE_WINDOWS:
        if n <= 1:
            return np.ones(n)
        fac = np.linspace(-np.pi, np.pi, n + 1)  # periodic: one more, the last dropped
        w = np.zeros(n + 1)
        for k, a in enumerate(_COSINE_WINDOWS[window]):
            w += a * np.cos(k * fac)
        return w[:-1]
    if isinstance(window, (str, tuple)):
        import scipy.signal  # any other named window

        return np.asarray(scipy.signal.get_window(window, n), dtype=float)
    return np.asarray(window, dtype=float)
