"""Time responses of the bench model that do not wrap around, for records of any length.

:meth:`hardware_mocks.model.BodyOnMounts.time_response` convolves circularly over
twice the record length. When the mounts' slowest rigid-body mode has not died
out within that length (the block's 6 Hz mode decays with a 3.2 s time constant),
the tail of every impulse response folds back into the record. Measured on the
``block`` bench at 2048 Hz, a hit 10 ms into the record: the largest error is 6.8 %
of the peak response for a 0.25 s record, 1.3 % for 1 s, 0.3 % for 2 s, 2e-7 for 8 s.
Here the response is a linear
convolution with the model's band-limited impulse response, whose length is
chosen from the slowest decay of the model, so records of any length (and a
long recording cut into blocks) are exact to ``tail_tol``.

The discrete system is defined by its frequency response: equal to the model's
exact FRF below ``fs / 2.56`` (the usable band of a DAQ with anti-alias
filters), so an FRF estimated from these signals must converge there to
``BodyOnMounts.frf``. That roll-off is zero-phase, hence not causal: a response
starts a few samples before its force (1 % of the peak 4 samples ahead, 4e-6 at
64 samples, on the engine). Start transient records a few dozen samples before
the force, as a hammer test's pre-trigger does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from hardware_mocks.model import BodyOnMounts
from processing.geometry import excitation_matrix, response_matrix

__all__ = [
    "ImpulseResponse",
    "frf_laplace",
    "half_sine",
    "impulse_response",
    "settling_time",
    "simulate",
]


def settling_time(model: BodyOnMounts) -> float:
    """The slowest decay time constant ``1 / (zeta omega_n)`` of the model's modes, s."""
    rm = model.rigid_modes()
    rates = list(rm.damping * 2 * np.pi * rm.frequency)
    rates += [m.damping * 2 * np.pi * m.frequency for m in model.elastic_modes]
    rates = [r for r in rates if r > 0]
    return 1.0 / min(rates)


@dataclass(frozen=True)
class ImpulseResponse:
    """Two-sided impulse responses ``h`` (n_resp, n_exc, n_taps), lag ``-n_taps // 2`` first."""

    h: NDArray[np.float64]
    fs: float

    @property
    def lead(self) -> int:
        """Number of taps before lag 0 (the non-causal ringing of the ideal band limit)."""
        return self.h.shape[-1] // 2


def impulse_response(
    model: BodyOnMounts,
    fs: float,
    resp_xyz: ArrayLike,
    resp_dirs: ArrayLike,
    exc_xyz: ArrayLike,
    exc_dirs: ArrayLike,
    *,
    passband: float = 1 / 2.56,
    tail_tol: float = 1e-7,
) -> ImpulseResponse:
    """Impulse responses of the model through an ideal anti-aliased front end, (m/s^2)/N per sample.

    The discrete system's frequency response is the model's exact FRF up to
    ``passband * fs`` (a DAQ's usable band, fs/2.56 by default), rolled off by a
    raised cosine to zero at Nyquist. Without the roll-off, the FRF's jump at
    Nyquist would ring (decaying only as 1/lag) on both sides of every transient.
    The FRF is sampled on a grid fine enough that the decay over half its period
    is below ``tail_tol``; the inverse FFT, centred on lag 0, is the impulse
    response to that accuracy.
    """
    if not 0 < passband <= 0.5:
        raise ValueError(f"passband must be in (0, 0.5] of fs, got {passband}")
    n_half = int(np.ceil(-np.log(tail_tol) * settling_time(model) * fs))
    n = int(2 ** np.ceil(np.log2(2 * max(n_half, 64))))
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    H = model.frf(freq, resp_xyz, resp_dirs, exc_xyz, exc_dirs)
    f_pass, f_nyq = passband * fs, fs / 2
    if f_pass < f_nyq:
        x = np.clip((freq - f_pass) / (f_nyq - f_pass), 0.0, 1.0)
        H *= 0.5 * (1 + np.cos(np.pi * x))
    h = np.fft.irfft(H, n, axis=-1)
    return ImpulseResponse(np.fft.fftshift(h, axes=-1), float(fs))


def simulate(ir: ImpulseResponse, force: ArrayLike) -> NDArray[np.float64]:
    """Accelerations (n_resp, n) for forces (n_exc, n), N, sampled at ``ir.fs``.

    A linear convolution: the force is zero before the first and after the last
    sample, nothing wraps around.
    """
    f = np.atleast_2d(np.asarray(force, dtype=float))
    n_exc = ir.h.shape[1]
    if f.shape[0] != n_exc:
        raise ValueError(f"force has {f.shape[0]} channels, the impulse responses {n_exc}")
    n = f.shape[-1]
    y = scipy.signal.oaconvolve(ir.h, f[None, :, :], mode="full", axes=-1)
    return np.asarray(y.sum(axis=1)[:, ir.lead : ir.lead + n])


def half_sine(n: int, fs: float, t0: float, duration: float, peak: float) -> NDArray[np.float64]:
    """A half-sine force pulse of ``peak`` N lasting ``duration`` s from ``t0`` s, n samples."""
    t = np.arange(n) / fs - t0
    inside = (t >= 0) & (t <= duration)
    return np.where(inside, peak * np.sin(np.pi * np.clip(t, 0, duration) / duration), 0.0)


def frf_laplace(
    model: BodyOnMounts,
    s: ArrayLike,
    resp_xyz: ArrayLike,
    resp_dirs: ArrayLike,
    exc_xyz: ArrayLike,
    exc_dirs: ArrayLike,
) -> NDArray[np.complex128]:
    """The model's accelerance at complex Laplace variables ``s`` (rad/s), (n_resp, n_exc, n_s).

    ``s = j omega`` gives :meth:`BodyOnMounts.frf`; ``s = j omega + 1/tau`` gives what
    an exponential window of time constant ``tau`` turns the FRF into.
    """
    s = np.asarray(s, dtype=complex)
    E = response_matrix(resp_xyz, resp_dirs)
    T = excitation_matrix(exc_xyz, exc_dirs)
    Z = model.K[None] + s[:, None, None] * model.C[None] + (s**2)[:, None, None] * model.M[None]
    A = (s**2)[:, None, None] * np.linalg.inv(Z)
    H = np.einsum("ra,fab,be->ref", E, A, T)
    rd = np.asarray(resp_dirs, float)
    rd = rd / np.linalg.norm(rd, axis=1, keepdims=True)
    ed = np.asarray(exc_dirs, float)
    ed = ed / np.linalg.norm(ed, axis=1, keepdims=True)
    for mode in model.elastic_modes:  # a few modes
        pr = np.sum(mode.shape(resp_xyz) * rd, axis=1)
        pe = np.sum(mode.shape(exc_xyz) * ed, axis=1)
        wr = 2 * np.pi * mode.frequency
        b = s**2 / (wr**2 + 2 * mode.damping * wr * s + s**2)
        H += pr[:, None, None] * pe[None, :, None] * b[None, None, :]
    return np.asarray(H)
