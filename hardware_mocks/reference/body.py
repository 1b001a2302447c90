"""A flexible body as a 3-D lattice: point masses at nodes joined by axial springs.

The body is a union of cubic cells of side ``h`` (voxels). Its nodes are the cells'
corners, each carrying a point mass and three translational degrees of freedom. Every
pair of corners of an occupied cell (12 edges, 12 face diagonals, 4 body diagonals) is
joined by an axial spring of stiffness ``k0 * h / L`` (``L`` its length) times a per-spring
factor; a union of face-sharing cells braced this way is rigid as a truss, so the free
body has exactly six zero-frequency (rigid-body) modes and every other mode is elastic.
Structural damping is a loss factor ``eta``: the stiffness is ``K (1 + j eta)``.

Shapes (``make_body``):

``block``
    compact block 0.4 x 0.3 x 0.3 m (4 x 3 x 3 cells), node masses uneven by +-30 %.
``engine``
    0.48 x 0.36 x 0.36 m block with an overhanging housing on one end's upper half, a
    heavy lump (flywheel) on the other end and a light accessory bracket: uneven mass,
    CoG off the geometric centre.
``gearbox``
    long slender 0.8 x 0.2 x 0.2 m box (8 x 2 x 2 cells) with mass tapering along it: its
    first elastic modes are bending modes.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

__all__ = ["SHAPES", "LatticeBody", "make_body"]

SHAPES = ("block", "engine", "gearbox")

_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
_PAIRS = np.array(list(combinations(range(8), 2)))  # 28 pairs of a cell's corners


@dataclass(frozen=True)
class LatticeBody:
    """Point masses on a lattice joined by axial springs (global frame, SI).

    Attributes
    ----------
    xyz : (n, 3) node positions, m
    masses : (n,) node masses, kg
    springs : (s, 2) node indices of each spring
    rates : (s,) spring stiffnesses, N/m (before ``stiffness_scale``)
    eta : structural loss factor of the body (stiffness ``K (1 + j eta)``)
    surface : (n,) True for nodes on the body's outer surface
    """

    xyz: NDArray[np.float64]
    masses: NDArray[np.float64]
    springs: NDArray[np.int64]
    rates: NDArray[np.float64]
    eta: float
    surface: NDArray[np.bool_]
    shape: str = "block"

    @property
    def n_nodes(self) -> int:
        return int(self.xyz.shape[0])

    @property
    def mass(self) -> float:
        return float(self.masses.sum())

    def stiffness(self) -> NDArray[np.float64]:
        """Real stiffness matrix (3n x 3n), N/m: ``sum k n n^T`` per spring of unit axis n."""
        a, b = self.springs[:, 0], self.springs[:, 1]
        d = self.xyz[b] - self.xyz[a]
        nrm = d / np.linalg.norm(d, axis=1, keepdims=True)
        blocks = self.rates[:, None, None] * nrm[:, :, None] * nrm[:, None, :]  # (s, 3, 3)
        n3 = 3 * self.n_nodes
        K = np.zeros((n3, n3))
        ia = 3 * a[:, None] + np.arange(3)  # (s, 3)
        ib = 3 * b[:, None] + np.arange(3)
        for ri, ci, sign in ((ia, ia, 1.0), (ib, ib, 1.0), (ia, ib, -1.0), (ib, ia, -1.0)):
            np.add.at(K, (ri[:, :, None], ci[:, None, :]), sign * blocks)
        return K

    def free_modes_hz(self, count: int = 12) -> NDArray[np.float64]:
        """Lowest ``count`` undamped free-free natural frequencies, Hz (six are ~0)."""
        m3 = np.repeat(self.masses, 3)
        w2 = scipy.linalg.eigh(self.stiffness(), np.diag(m3), eigvals_only=True,
                               subset_by_index=[0, min(count, m3.size) - 1])
        return np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi)

    def scaled(self, factor: float) -> LatticeBody:
        """The same body with every spring stiffness multiplied by ``factor``."""
        return LatticeBody(self.xyz, self.masses, self.springs, self.rates * factor, self.eta,
                           self.surface, self.shape)

    def moved(self, offset: NDArray[np.float64]) -> LatticeBody:
        """The same body translated by ``offset`` (3,), m."""
        return LatticeBody(self.xyz + offset, self.masses, self.springs, self.rates, self.eta,
                           self.surface, self.shape)


def _lattice(cells: NDArray[np.int64], h: float) -> tuple[
        NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_], NDArray[np.int64]]:
    """Nodes (positions), springs (index pairs), surface flags, node grid indices of cells."""
    corners = (cells[:, None, :] + _CORNERS[None]).reshape(-1, 3)
    grid, inverse = np.unique(corners, axis=0, return_inverse=True)
    cell_nodes = inverse.reshape(-1, 8)
    pairs = np.sort(cell_nodes[:, _PAIRS].reshape(-1, 2), axis=1)
    springs = np.unique(pairs, axis=0)
    # a node is inside when all 8 cells around it are occupied
    occupied = {tuple(c) for c in cells.tolist()}
    inside = np.array([all((g[0] - i, g[1] - j, g[2] - k) in occupied for i, j, k in _CORNERS)
                       for g in grid.tolist()])
    return grid * h, springs, ~inside, grid


def _box(nx: int, ny: int, nz: int, start: tuple[int, int, int] = (0, 0, 0),
         ) -> NDArray[np.int64]:
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    return np.stack([i.ravel(), j.ravel(), k.ravel()], 1) + np.asarray(start)


def make_body(shape: str, rng: np.random.Generator, *, mass: float | None = None,
              eta: float | None = None) -> LatticeBody:
    """A lattice body of one of :data:`SHAPES`, uneven by draws from ``rng``.

    Parameters
    ----------
    shape : "block", "engine" or "gearbox"
    rng : source of the mass and stiffness unevenness
    mass : total mass, kg (default: 160 kg block, 110 kg engine, 60 kg gearbox, +-15 %)
    eta : body loss factor (default: drawn in [0.005, 0.03])

    Returns
    -------
    LatticeBody with unit spring rate scale ``k0 = 1e8 N/m`` (rescale with ``scaled``); the
    node positions have the lattice's corner at the origin.
    """
    if shape == "block":
        h, cells = 0.1, _box(4, 3, 3)
        nominal = 160.0
    elif shape == "engine":
        h = 0.12
        cells = np.concatenate([_box(4, 3, 3), _box(1, 3, 1, start=(4, 0, 2)),
                                _box(1, 1, 1, start=(-1, 2, 1))])
        nominal = 110.0
    elif shape == "gearbox":
        h, cells = 0.1, _box(8, 2, 2)
        nominal = 60.0
    else:
        raise ValueError(f"unknown body shape {shape!r}: use one of {', '.join(SHAPES)}")
    xyz, springs, surface, grid = _lattice(cells, h)
    w = np.asarray(rng.uniform(0.7, 1.3, xyz.shape[0]), dtype=np.float64)
    if shape == "engine":
        w[grid[:, 0] == 0] *= 2.5  # flywheel end
        w[grid[:, 0] == grid[:, 0].max()] *= 0.6  # light overhanging housing
    elif shape == "gearbox":
        w *= np.interp(grid[:, 0], [0, grid[:, 0].max()], [1.6, 0.6])
    total = (nominal if mass is None else mass) * (rng.uniform(0.85, 1.15) if mass is None else 1)
    masses = total * w / w.sum()
    lengths = np.linalg.norm(xyz[springs[:, 1]] - xyz[springs[:, 0]], axis=1)
    rates = 1e8 * h / lengths * rng.uniform(0.8, 1.2, springs.shape[0])
    loss = float(rng.uniform(0.005, 0.03)) if eta is None else float(eta)
    return LatticeBody(xyz, masses, springs, rates, loss, surface, shape)
