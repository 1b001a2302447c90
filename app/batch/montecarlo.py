"""Monte Carlo on a Dask cluster: a pure draw function mapped over seeds, in chunks.

A draw function takes an integer seed and returns one vector (the identified numbers of one
perturbed input); it must be picklable (a module-level function, or an instance of a
module-level class such as :class:`MassLineDraw`) and depend on nothing but its seed.
:func:`monte_carlo` opens a cluster and returns the ``(n, m)`` draws in seed order, the same
array as ``np.stack([draw(s) for s in seeds])`` whatever the number of workers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from distributed import Client, as_completed
from numpy.typing import NDArray

from app.batch.cluster import open_client, total_threads
from processing.geometry import excitation_matrix, response_matrix
from processing.massline import fit_inertia

__all__ = ["Draw", "MassLineDraw", "chunk_draws", "map_draws", "monte_carlo"]

#: a draw function: seed -> one vector of identified numbers
Draw = Callable[[int], NDArray[np.float64]]

#: chunks per worker thread when no chunk size is given (load balance against task overhead)
CHUNKS_PER_THREAD = 4


def chunk_draws(draw: Draw, seeds: NDArray[np.int64]) -> NDArray[np.float64]:
    """``draw`` for each seed of a chunk, stacked ``(len(seeds), m)`` (one task's work)."""
    return np.stack([np.asarray(draw(int(s)), dtype=float).ravel() for s in seeds])


def map_draws(client: Client, draw: Draw, n: int, *, first_seed: int = 0,
              chunk: int | None = None,
              progress: Callable[[int], None] | None = None) -> NDArray[np.float64]:
    """``draw`` over the seeds ``first_seed .. first_seed + n - 1`` on ``client``'s workers.

    Parameters
    ----------
    client : a Dask client (:func:`app.batch.cluster.open_client`)
    draw : picklable seed -> vector function (the same length for every seed)
    n : number of draws
    first_seed : seed of the first draw
    chunk : draws per task (default: ``n`` over 4 tasks per worker thread)
    progress : called with the number of draws done after each finished chunk

    Returns
    -------
    (n, m) array
        Row ``k`` is ``draw(first_seed + k)``.

    Raises
    ------
    ValueError
        ``n`` or ``chunk`` below 1; the first exception a draw raised, as it was raised.
    """
    if n < 1:
        raise ValueError(f"the number of draws must be at least 1, got {n}")
    if chunk is None:
        chunk = max(1, math.ceil(n / (CHUNKS_PER_THREAD * total_threads(client))))
    if chunk < 1:
        raise ValueError(f"the chunk size must be at least 1, got {chunk}")
    seeds = np.arange(first_seed, first_seed + n, dtype=np.int64)
    parts = [seeds[k:k + chunk] for k in range(0, n, chunk)]
    [remote] = client.scatter([draw], broadcast=True)  # sent once, not with every task
    futures = [client.submit(chunk_draws, remote, part, pure=False) for part in parts]
    index = {f.key: k for k, f in enumerate(futures)}
    out: list[NDArray[np.float64] | None] = [None] * len(parts)
    done = 0
    try:
        for fut in as_completed(futures):
            out[index[fut.key]] = fut.result()
            done += len(parts[index[fut.key]])
            if progress is not None:
                progress(done)
    finally:
        client.cancel(futures)
    return np.concatenate([o for o in out if o is not None], axis=0)


def monte_carlo(draw: Draw, n: int, *, scheduler: str | None = None,
                workers: int | None = None, first_seed: int = 0, chunk: int | None = None,
                progress: Callable[[int], None] | None = None) -> NDArray[np.float64]:
    """:func:`map_draws` on a cluster opened for it: a local cluster of ``workers`` processes
    (default one per core), or the running scheduler at ``scheduler``. Returns ``(n, m)``."""
    with open_client(scheduler, workers) as client:
        return map_draws(client, draw, n, first_seed=first_seed, chunk=chunk,
                         progress=progress)


@dataclass(frozen=True)
class MassLineDraw:
    """The article's plain mass-line estimate of the ten parameters with the response points
    moved by a random offset: a draw function of the location uncertainty.

    Each draw moves every response point (the rows sharing a location move together) by an
    offset with independent normal components of standard deviation ``sigma`` and solves
    ``M(theta) X_j = T`` over the lines, ``X_j = E^+ H_j`` (eqs. 6-11 without the stiffness
    term, which the mass line makes small).

    Attributes
    ----------
    freq : (n_lines,) the mass-line lines, Hz
    H : (n_resp, n_exc, n_lines) accelerances on those lines, (m/s^2)/N
    resp_xyz, resp_dirs : (n_resp, 3) stated response locations (m) and directions
    exc_xyz, exc_dirs : (n_exc, 3) excitation locations (m) and directions
    sigma : standard deviation of each coordinate of a point's location error, m
    """

    freq: NDArray[np.float64]
    H: NDArray[np.complex128]
    resp_xyz: NDArray[np.float64]
    resp_dirs: NDArray[np.float64]
    exc_xyz: NDArray[np.float64]
    exc_dirs: NDArray[np.float64]
    sigma: float

    def __call__(self, seed: int) -> NDArray[np.float64]:
        """theta ``[m, m x_c, m y_c, m z_c, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz]`` (about O, the
        convention of :mod:`processing.inertia`) of the draw ``seed``."""
        points, which = np.unique(self.resp_xyz, axis=0, return_inverse=True)
        offsets = np.random.default_rng(seed).normal(0.0, self.sigma, points.shape)
        E = response_matrix(self.resp_xyz + offsets[which.ravel()], self.resp_dirs)
        X = np.einsum("dr,rel->del", np.linalg.pinv(E), self.H)
        T = excitation_matrix(self.exc_xyz, self.exc_dirs)
        return fit_inertia(X, T[:, :, None].astype(complex)).theta
