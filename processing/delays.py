"""Each response channel's delay against the force, read from the FRFs' phase.

A front end whose channels are not sampled at one instant (a multiplexed converter, modules
with different filter delays, a response channel sampled a fraction of a sample after the
force) records response ``r`` late by ``tau_r``: its FRFs are ``H_r(w) exp(-j w tau_r)``.
Above the rigid-body modes a rigid body's accelerance is nearly real, so a delay of half a
sample turns it by a few tenths of a radian where the mass line is read: the mass line's
imaginary parts, which carry the damping, then carry the delay, and the inertia parameters
err by several per cent.

:func:`estimate_delays` reads each channel's delay from the phase of the measured FRFs
against the FRFs the fitted rigid-body model synthesises (:mod:`processing.synthesis`): a
weighted least-squares line through the origin of the phase residual on ``w``, over every
excitation column, with the weight of each value its modulus squared over its noise, made
robust (Huber weights, a few rounds) against lines the rigid model does not hold.
:meth:`ChannelDelays.shifted` takes the delays out of FRFs, :meth:`ChannelDelays.units` out
of the per-hit or per-block spectra (:mod:`processing.units`). Only differences between the
force and the responses show in an FRF: a delay common to every channel, the force's
included, does not, and needs no correction.

Examples
--------
>>> import numpy as np
>>> f = np.linspace(40.0, 80.0, 41)
>>> model = np.ones((2, 3, f.size)) * np.array([1.0, -2.0])[:, None, None]
>>> tau = np.array([1e-4, -3e-4])
>>> measured = model * np.exp(-2j * np.pi * f * tau[:, None, None])
>>> d = estimate_delays(f, measured, model)
>>> np.allclose(d.seconds, tau)
True
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from processing.data import InputError

if TYPE_CHECKING:
    from processing.units import TimeUnits

__all__ = ["ChannelDelays", "estimate_delays", "realness_delays"]

#: Huber's constant on the phase residual, in robust standard deviations
HUBER = 2.0
#: rounds of the robust weights
ROBUST_ROUNDS = 4
#: delays tried by :func:`realness_delays` in each of its rounds, and its rounds (each
#: narrows the span to a few steps of the round before)
REAL_GRID = 41
REAL_ROUNDS = 4


@dataclass(frozen=True)
class ChannelDelays:
    """Each response channel's delay against the force, s (positive: recorded late).

    ``seconds`` and ``std`` (n_resp,); ``lines`` the number of lines they were read on;
    ``misfit`` the weighted RMS phase (rad) of the FRFs against the model as they were
    given, before these delays are taken out (how well they fit it).
    """

    seconds: NDArray[np.float64]
    std: NDArray[np.float64]
    lines: int = 0
    misfit: float = 0.0

    def __post_init__(self) -> None:
        s, d = np.asarray(self.seconds, float), np.asarray(self.std, float)
        if s.ndim != 1 or d.shape != s.shape:
            raise InputError(f"channel delays: one delay and one std a channel, got "
                             f"{s.shape} and {d.shape}")
        object.__setattr__(self, "seconds", s)
        object.__setattr__(self, "std", d)

    def __add__(self, other: ChannelDelays) -> ChannelDelays:
        """The delays of two corrections one after the other (the later's std)."""
        return ChannelDelays(self.seconds + other.seconds, other.std, other.lines,
                             other.misfit)

    def phase(self, freq: NDArray[np.float64]) -> NDArray[np.complex128]:
        """(n_resp, n_f) the factor ``exp(j w tau_r)`` that takes the delays out."""
        w = 2 * np.pi * np.asarray(freq, dtype=float)
        return np.asarray(np.exp(1j * self.seconds[:, None] * w[None, :]))

    def shifted(self, freq: NDArray[np.float64], H: NDArray[np.complex128],
                ) -> NDArray[np.complex128]:
        """FRFs ``H`` (n_resp, n_exc, n_f) with the delays taken out."""
        return np.asarray(H * self.phase(freq)[:, None, :])

    def units(self, units: TimeUnits) -> TimeUnits:
        """The per-unit spectra with the delays taken out of each cross-spectrum (the
        FRFs they form are then :meth:`shifted`)."""
        cols = tuple(dataclasses.replace(c, Sfx=c.Sfx * self.phase(c.freq)[None])
                     for c in units.columns)
        return dataclasses.replace(units, columns=cols)


def estimate_delays(freq: NDArray[np.float64], H: NDArray[np.complex128],
                    model: NDArray[np.complex128],
                    weights: NDArray[np.float64] | None = None) -> ChannelDelays:
    """Each channel's delay from the phase of ``H`` against ``model``.

    Parameters
    ----------
    freq : (n_f,) Hz, the lines to read (where the model holds: above the rigid-body modes,
        under the elastic ones)
    H, model : (n_resp, n_exc, n_f) measured and synthesised accelerances
    weights : (n_exc, n_f) weight of each column on each line (0 leaves it out), default 1

    Returns
    -------
    ChannelDelays
        ``tau_r`` minimising ``sum W (angle(H / model) + w tau_r)^2`` with
        ``W = |model|^2`` times the weights and Huber's robust weights, and its standard
        deviation from the residual's scatter.
    """
    w = 2 * np.pi * np.asarray(freq, dtype=float)
    H, model = np.asarray(H), np.asarray(model)
    if H.shape != model.shape or H.shape[-1] != w.size or w.size < 2:
        raise InputError(f"channel delays: FRFs {H.shape} and model {model.shape} on "
                         f"{w.size} lines (at least 2)")
    colw = np.ones(H.shape[1:]) if weights is None else np.asarray(weights, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.angle(H / model)
    W = np.abs(model) ** 2 * colw[None]
    W = np.where(np.isfinite(phi) & (W > 0), W, 0.0)
    phi = np.where(W > 0, phi, 0.0)
    rob = np.ones_like(W)
    tau = np.zeros(H.shape[0])
    for _ in range(ROBUST_ROUNDS):
        tau = _slope(W * rob, w, phi)
        res = phi + w * tau[:, None, None]
        # each value's residual in units of its own noise: W stands for 1 / variance
        z = np.abs(res) * np.sqrt(W)
        scale = 1.4826 * _median_where(z, W > 0)
        u = z / (HUBER * scale[:, None, None] + 1e-300)
        rob = np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1.0))
    Wr = W * rob
    res = phi + w * tau[:, None, None]
    n = np.maximum((Wr > 0).sum(axis=(1, 2)), 2)
    den = (Wr * w**2).sum(axis=(1, 2))
    s2 = (Wr * res**2).sum(axis=(1, 2)) / (n - 1)
    std = np.sqrt(s2 / np.where(den > 0, den, np.inf))
    misfit = float(np.sqrt((W * phi**2).sum() / max(float(W.sum()), 1e-300)))
    return ChannelDelays(tau, std, int(w.size), misfit)


def realness_delays(freq: NDArray[np.float64], H: NDArray[np.complex128],
                    use: NDArray[np.bool_], most: float) -> ChannelDelays:
    """Each channel's delay from the FRFs alone, with no model: the delay that brings its
    values nearest the real axis.

    Under its elastic modes a lightly damped body's accelerances are nearly real (sums over
    real modes) but near its resonances, so a delay shows as each channel's values turning
    off the real axis in proportion to ``w``. Each value counts once, whatever its modulus
    (resonances, where damping turns the values, are a few lines among many): the delay
    maximises the mean ``|cos(angle(H) + w tau)|`` over the values ``use`` keeps, searched
    within ``+-most`` s on a grid narrowed round by round, then refined as a robust
    line through the origin of the phase off the real axis (:func:`estimate_delays`
    against the nearest real values), which also gives its std. Meant for FRFs a first fit
    cannot read the delays against (their phase too far off for the bands it chooses).

    Parameters
    ----------
    freq : (n_f,) Hz
    H : (n_resp, n_exc, n_f) accelerances
    use : (n_exc, n_f) the values to read (lines under the first elastic mode, columns
        the fit would weigh)
    most : largest delay searched, s (half a period of the top line is one sample or more)
    """
    w = 2 * np.pi * np.asarray(freq, dtype=float)
    H = np.asarray(H)
    if H.ndim != 3 or np.shape(use) != H.shape[1:] or w.size != H.shape[-1] or most <= 0:
        raise InputError(f"channel delays: FRFs {H.shape}, values to read {np.shape(use)}, "
                         f"{w.size} lines, span {most:g} s")
    keep = np.asarray(use, bool)[None] & np.isfinite(H) & (np.abs(H) > 0)
    if not np.any(keep):
        raise InputError("channel delays: no value to read them on")
    ph = np.where(keep, np.angle(np.where(keep, H, 1.0)), 0.0)
    # the grid search on the lines with a value read: cos(angle + w tau) from the values'
    # cos and sin and each line's turn, one delay of the grid at a time (n_r, n_e, n_l)
    lines = np.asarray(use, bool).any(axis=0)
    cp, sp, k_l = np.cos(ph[..., lines]), np.sin(ph[..., lines]), keep[..., lines].astype(float)
    w_l = w[lines]
    centre, half = np.zeros(H.shape[0]), float(most)
    score = np.empty((H.shape[0], REAL_GRID))
    for _ in range(REAL_ROUNDS):
        taus = centre[:, None] + np.linspace(-half, half, REAL_GRID)[None]  # (n_r, g)
        for j in range(REAL_GRID):
            turn = taus[:, j, None] * w_l  # (n_r, n_l)
            score[:, j] = np.einsum("rel,rel->r", np.abs(
                cp * np.cos(turn)[:, None] - sp * np.sin(turn)[:, None]), k_l)
        centre = taus[np.arange(H.shape[0]), np.argmax(score, axis=1)]
        half *= 4.0 / (REAL_GRID - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = H / np.abs(H)  # each value counts once
    nearest = np.sign(np.cos(ph + w * centre[:, None, None]))  # the real axis's side
    return estimate_delays(freq, np.where(keep, unit, np.nan), nearest,
                           np.asarray(use, dtype=float))


def _slope(W: NDArray[np.float64], w: NDArray[np.float64],
           phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per channel, ``tau`` of the weighted line ``phi = -w tau`` through the origin."""
    den = (W * w**2).sum(axis=(1, 2))
    num = -(W * w * phi).sum(axis=(1, 2))
    return np.asarray(np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0))


def _median_where(z: NDArray[np.float64], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Per channel (first axis), the median of ``z`` where ``mask``."""
    flat = np.where(mask, z, np.nan).reshape(z.shape[0], -1)
    med = np.nanmedian(np.where(np.all(np.isnan(flat), axis=1, keepdims=True), 0.0, flat),
                       axis=1)
    return np.asarray(med)
