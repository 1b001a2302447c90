"""What a real test adds to the exact FRFs: sensor errors, point-location errors and noise.

A triaxial accelerometer's channel nominally reads the global axis ``d`` at its reported
point. Its true sensing vector is ``(1 + g) (R d + t c)``: ``R`` a small rotation
(misalignment, angle up to ``misalignment_deg`` about a random axis, one per sensor), ``g``
a gain error drawn uniformly in ``+-gain_error`` per channel, ``t = transverse`` the
transverse sensitivity along a random unit vector ``c`` perpendicular to ``R d``. The true
point is a body node; the reported point differs from it by a draw uniform in
``+-location_error`` per coordinate (forces likewise; their directions are exact).

Noise (errors in variables, :func:`h1_with_noise`): each excitation is a run of
``n_averages`` spectra of a random force (complex Gaussian, unit variance per line); the
force channel and every response channel get complex Gaussian noise whose standard
deviation is ``noise`` times that channel's clean RMS over the run (all lines and
averages); the FRF is the H1 estimate ``sum conj(F) X / sum |F|^2`` and the coherence
``|sum conj(F) X|^2 / (sum |F|^2 sum |X|^2)``. Force noise biases H1 low, response noise
scatters it; lines far below a record's RMS (anti-resonances, the mass line under strong
peaks) are the noisiest, as in a real test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.reference.kinematics import rotation

__all__ = ["Channels", "h1_with_noise", "sensor_channels"]


@dataclass(frozen=True)
class Channels:
    """Measured DOFs: the true ones (body nodes, vectors) and what the test reports.

    Attributes
    ----------
    nodes : (n,) body node index of each DOF (true point)
    vectors : (n, 3) true sensing (or force) vectors in the global frame
    ids : (n,) reported node id of each DOF (one id per sensor or force point)
    reported_xyz : (n, 3) reported coordinates of each DOF's point, m
    reported_dirs : (n, 3) reported unit directions (global axes, sign included)
    """

    nodes: NDArray[np.int64]
    vectors: NDArray[np.float64]
    ids: NDArray[np.int64]
    reported_xyz: NDArray[np.float64]
    reported_dirs: NDArray[np.float64]


def _unit_perpendicular(d: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
    c = np.cross(d, rng.normal(size=d.shape))
    return c / np.linalg.norm(c, axis=-1, keepdims=True)


def sensor_channels(node_xyz: NDArray[np.float64], nodes: NDArray[np.int64],
                    rng: np.random.Generator, *, first_id: int = 1,
                    location_error: float = 0.0, misalignment_deg: float = 0.0,
                    gain_error: float = 0.0, transverse: float = 0.0) -> Channels:
    """Three channels (global x, y, z) per triaxial sensor at ``nodes`` with their errors."""
    nodes = np.asarray(nodes, dtype=np.int64)
    s = nodes.size
    R = np.empty((s, 3, 3))
    for i in range(s):
        axis = rng.normal(size=3)
        angle = np.deg2rad(misalignment_deg) * rng.uniform(0.0, 1.0)
        R[i] = rotation(axis / np.linalg.norm(axis) * angle)
    d_true = np.transpose(R, (0, 2, 1)).reshape(3 * s, 3)  # rows: R @ e_x, R @ e_y, R @ e_z
    c = _unit_perpendicular(d_true, rng)
    g = rng.uniform(-gain_error, gain_error, 3 * s)
    vectors = (1 + g)[:, None] * (d_true + transverse * c)
    offsets = rng.uniform(-location_error, location_error, (s, 3))
    return Channels(nodes=np.repeat(nodes, 3), vectors=vectors,
                    ids=np.repeat(np.arange(first_id, first_id + s), 3),
                    reported_xyz=np.repeat(node_xyz[nodes] + offsets, 3, axis=0),
                    reported_dirs=np.tile(np.eye(3), (s, 1)))


def force_channels(node_xyz: NDArray[np.float64], nodes: NDArray[np.int64],
                   dirs: NDArray[np.float64], rng: np.random.Generator, *, first_id: int = 101,
                   location_error: float = 0.0) -> Channels:
    """Forces along ``dirs`` (global axes with sign) at ``nodes``; one reported id per node."""
    nodes = np.asarray(nodes, dtype=np.int64)
    uniq, inv = np.unique(nodes, return_inverse=True)
    offsets = rng.uniform(-location_error, location_error, (uniq.size, 3))
    return Channels(nodes=nodes, vectors=np.asarray(dirs, dtype=float),
                    ids=first_id + inv, reported_xyz=node_xyz[nodes] + offsets[inv],
                    reported_dirs=np.asarray(dirs, dtype=float))


def h1_with_noise(H: NDArray[np.complex128], noise: float, n_averages: int,
                  rng: np.random.Generator) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """H1 and coherence (n_r, n_e, n_f) of a random-excitation test of the exact ``H``.

    Each excitation column is one run of ``n_averages`` force spectra; see the module's
    notes for the noise model. ``noise = 0`` returns ``H`` and unit coherence.
    """
    if noise <= 0:
        return H.copy(), np.ones(H.shape)
    n_r, n_e, n_f = H.shape

    def cn(*size: int) -> NDArray[np.complex128]:
        return (rng.normal(size=size) + 1j * rng.normal(size=size)) / np.sqrt(2)

    H1 = np.empty(H.shape, dtype=complex)
    coh = np.empty(H.shape)
    for e in range(n_e):  # one run per excitation: keeps the (n_r, n_avg, n_f) spectra small
        F = cn(n_averages, n_f)
        X = H[:, e, None, :] * F[None]  # (n_r, n_avg, n_f)
        rms_f = np.sqrt(np.mean(np.abs(F) ** 2))
        rms_x = np.sqrt(np.mean(np.abs(X) ** 2, axis=(1, 2)))  # (n_r,)
        Fm = F + noise * rms_f * cn(n_averages, n_f)
        Xm = X + noise * rms_x[:, None, None] * cn(n_r, n_averages, n_f)
        Sff = np.sum(np.abs(Fm) ** 2, axis=0)  # (n_f,)
        Sfx = np.sum(np.conj(Fm)[None] * Xm, axis=1)  # (n_r, n_f)
        Sxx = np.sum(np.abs(Xm) ** 2, axis=1)
        H1[:, e] = Sfx / Sff
        coh[:, e] = np.abs(Sfx) ** 2 / (Sff * Sxx)
    return H1, coh
