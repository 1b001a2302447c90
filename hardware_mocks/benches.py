"""Built-in simulated benches, shaped like the article's.

- ``block``: the 160.6 kg standard block on four curved-bar springs (article Tables
  1-2), 4 triaxial response points, 9 forces, 2048 Hz sampling, 512 points (4 Hz
  lines), a small first elastic mode at 177 Hz.
- ``block-rigid``: the same block with no elastic modes.
- ``block-flexible``: the block with its first elastic mode at 450 Hz, three times
  above the top of the article's mass line (90-150 Hz), and a stronger one at 610 Hz.
- ``engine``: a 110 kg engine on three inclined rubber mounts (article section 5.2),
  4 triaxial points (one sensor mounted skewed), 18 forces, 256 Hz sampling, 1024
  lines, rigid modes within 30 Hz, first elastic mode at 118.5 Hz.
- ``engine-rigid``: the engine with no elastic modes.

The article's own engine tables are not physically realisable (they break the
triangle inequality of principal moments), so the engine's inertia here is a
consistent one of the same size.

Noise model (``frfset``): complex Gaussian noise of standard deviation
``noise * |H|`` added to every FRF value (``noise=0.02`` is "2 % FRF noise");
location errors: every node's reported coordinates are moved by independent
uniform errors in ``[-location_error, +location_error]`` per axis (m), while the
FRFs keep the true geometry, as when points are measured imprecisely.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from hardware_mocks.model import BodyOnMounts, ElasticMode, Mount
from processing.data import FRFSet, Geometry

__all__ = ["BENCHES", "Bench", "get_bench"]


@dataclass(frozen=True)
class Bench:
    """A body on mounts with its measurement geometry and frequency lines."""

    name: str
    description: str
    model: BodyOnMounts
    node_ids: NDArray[np.int64]
    node_xyz: NDArray[np.float64]
    resp_nodes: NDArray[np.int64]
    resp_dirs: NDArray[np.float64]
    exc_nodes: NDArray[np.int64]
    exc_dirs: NDArray[np.float64]
    freq: NDArray[np.float64]
    #: mass-line and stiffness bands the article would use on this bench, Hz
    article_bands: tuple[tuple[float, float], tuple[float, float]]

    @property
    def geometry(self) -> Geometry:
        return Geometry(self.node_ids, self.node_xyz)

    def exact_frf(self, freq: NDArray[np.float64] | None = None) -> NDArray[np.complex128]:
        g = self.geometry
        return self.model.frf(
            self.freq if freq is None else freq,
            g.coordinates(self.resp_nodes),
            self.resp_dirs,
            g.coordinates(self.exc_nodes),
            self.exc_dirs,
        )

    def frfset(
        self,
        noise: float = 0.0,
        location_error: float = 0.0,
        seed: int | None = 0,
    ) -> FRFSet:
        """FRFs of this bench with optional noise and point-location errors."""
        rng = np.random.default_rng(seed)
        H = self.exact_frf()
        if noise > 0:
            z = rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)
            H = H + noise * np.abs(H) * z / np.sqrt(2)
        xyz = self.node_xyz
        if location_error > 0:
            xyz = xyz + rng.uniform(-location_error, location_error, xyz.shape)
        return FRFSet(
            freq=self.freq,
            H=H,
            resp_nodes=self.resp_nodes,
            resp_dirs=self.resp_dirs,
            exc_nodes=self.exc_nodes,
            exc_dirs=self.exc_dirs,
            geometry=Geometry(self.node_ids, xyz),
        )


def _rot(axis: str, deg: float) -> NDArray[np.float64]:
    return Rotation.from_euler(axis, deg, degrees=True).as_matrix()


def _triaxial(points: list[tuple[int, tuple[float, float, float], NDArray[np.float64]]]) -> tuple[
    NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]
]:
    ids, xyz, rn, rd = [], [], [], []
    for nid, p, R in points:
        ids.append(nid)
        xyz.append(p)
        for k in range(3):
            rn.append(nid)
            rd.append(R[:, k])
    return np.array(ids), np.array(xyz, float), np.array(rn), np.array(rd, float)


_Force = tuple[int, tuple[float, float, float], tuple[float, float, float]]


def _forces(forces: Sequence[_Force]) -> tuple[
    dict[int, tuple[float, float, float]], NDArray[np.int64], NDArray[np.float64]
]:
    pts: dict[int, tuple[float, float, float]] = {}
    en, ed = [], []
    for nid, p, d in forces:
        pts[nid] = p
        en.append(nid)
        ed.append(d)
    ed_a = np.array(ed, float)
    return pts, np.array(en), ed_a / np.linalg.norm(ed_a, axis=1, keepdims=True)


def _assemble(
    name: str,
    description: str,
    model: BodyOnMounts,
    sensors: list[tuple[int, tuple[float, float, float], NDArray[np.float64]]],
    forces: Sequence[tuple[int, tuple[float, float, float], tuple[float, float, float]]],
    freq: NDArray[np.float64],
    bands: tuple[tuple[float, float], tuple[float, float]],
) -> Bench:
    ids, xyz, rn, rd = _triaxial(sensors)
    pts, en, ed = _forces(forces)
    all_ids = np.concatenate([ids, np.array(sorted(pts))])
    all_xyz = np.concatenate([xyz, np.array([pts[k] for k in sorted(pts)], float)])
    return Bench(name, description, model, all_ids, all_xyz, rn, rd, en, ed, freq, bands)


# --- the standard block (article section 3) ---------------------------------------------------
_BLOCK_DIMS = np.array([0.294, 0.3046, 0.2258])
_BLOCK_MASS = 160.6


def _block_model(elastic: tuple[ElasticMode, ...]) -> BodyOnMounts:
    a, b, c = _BLOCK_DIMS
    JG = _BLOCK_MASS / 12 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    zeta, f_ref = 0.02, 15.0
    mounts = []
    for x, y, tilt in ((0.03, 0.03, 20.0), (0.264, 0.03, -20.0), (0.03, 0.274, 15.0),
                       (0.264, 0.274, -15.0)):
        k = np.array([6.7e5, 6.9e4, 3.5e5])
        mounts.append(Mount(np.array([x, y, 0.0]), k, k * 2 * zeta / (2 * np.pi * f_ref),
                            _rot("y", tilt)))
    return BodyOnMounts(_BLOCK_MASS, _BLOCK_DIMS / 2, JG, tuple(mounts), elastic)


def _block_mode(freq: float, amplitude: float, pattern: int) -> ElasticMode:
    coef = np.zeros((3, 6))
    if pattern == 0:  # bending about y: z displacement quadratic in x
        coef[2, 0], coef[0, 3] = 1.0, -0.4
    else:  # twisting-like: x and y displacements in yz/xz products
        coef[0, 5], coef[1, 4], coef[2, 1] = 1.0, -0.8, 0.5
    return ElasticMode(freq, 0.01, amplitude * coef / np.sqrt(_BLOCK_MASS), _BLOCK_DIMS / 2,
                       float(np.max(_BLOCK_DIMS) / 2))


def _block(name: str, description: str, elastic: tuple[ElasticMode, ...]) -> Bench:
    a, b, c = _BLOCK_DIMS
    R_skew = Rotation.from_euler("zyx", (30.0, -20.0, 10.0), degrees=True).as_matrix()
    sensors = [
        (1, (a, 0.05, 0.20), np.eye(3)),
        (2, (0.0, 0.25, 0.18), np.eye(3)),
        (3, (0.15, b, 0.05), R_skew),
        (4, (0.20, 0.10, c), np.eye(3)),
    ]
    forces = [
        (101, (a, 0.20, 0.10), (1, 0, 0)),
        (102, (0.0, 0.08, 0.15), (-1, 0, 0)),
        (103, (0.10, 0.0, 0.17), (0, -1, 0)),
        (104, (0.22, b, 0.08), (0, 1, 0)),
        (105, (0.05, 0.05, c), (0, 0, 1)),
        (106, (0.25, 0.26, c), (0, 0, 1)),
        (107, (0.25, 0.04, c), (0, 0, 1)),
        (108, (0.04, 0.27, c), (0.6, 0, 0.8)),
        (109, (a, 0.28, 0.21), (0.5, 0.5, 0.70710678)),
    ]
    freq = np.arange(1, 257, dtype=np.float64) * 4.0  # 2048 Hz sampling, 512 points
    return _assemble(name, description, _block_model(elastic), sensors, forces, freq,
                     ((90.0, 150.0), (4.0, 32.0)))


# --- the engine (article section 5.2) ----------------------------------------------------------
_ENGINE_MASS = 110.0
_ENGINE_COG = (0.0195, 0.2081, 0.1342)


def _engine_model(elastic: tuple[ElasticMode, ...]) -> BodyOnMounts:
    R = Rotation.from_euler("zyx", (12.0, -25.0, 18.0), degrees=True).as_matrix()
    JG = R @ np.diag([2.6, 3.9, 4.6]) @ R.T
    zeta, f_ref = 0.06, 20.0
    mounts = []
    for p, k, R_m in (
        ((0.26, 0.02, 0.02), (2.7e5, 2.1e5, 7.8e5), _rot("y", 25.0)),
        ((-0.24, 0.06, 0.04), (2.4e5, 2.3e5, 7.2e5), _rot("y", -25.0)),
        ((0.02, 0.46, 0.06), (1.8e5, 3.0e5, 6.0e5), _rot("x", 15.0)),
    ):
        k_a = np.array(k)
        mounts.append(Mount(np.array(p), k_a, k_a * 2 * zeta / (2 * np.pi * f_ref), R_m))
    return BodyOnMounts(_ENGINE_MASS, np.array(_ENGINE_COG), JG, tuple(mounts), elastic)


def _engine_modes() -> tuple[ElasticMode, ...]:
    coef = np.zeros((3, 6))
    coef[2, 1], coef[0, 3], coef[1, 0] = 1.0, 0.5, -0.3
    return (
        ElasticMode(118.5, 0.02, 0.5 * coef / np.sqrt(_ENGINE_MASS), np.array(_ENGINE_COG), 0.3),
    )


def _engine(name: str, description: str, elastic: tuple[ElasticMode, ...]) -> Bench:
    R_skew = Rotation.from_euler("zyx", (-35.0, 15.0, 25.0), degrees=True).as_matrix()
    sensors = [
        (1, (0.20, 0.00, 0.26), np.eye(3)),
        (2, (-0.21, 0.05, 0.30), np.eye(3)),
        (3, (0.16, 0.40, 0.28), R_skew),
        (4, (-0.18, 0.38, 0.05), np.eye(3)),
    ]
    pts = {
        11: (0.25, 0.10, 0.20), 12: (-0.25, 0.12, 0.22), 13: (0.05, -0.05, 0.18),
        14: (0.02, 0.48, 0.20), 15: (0.10, 0.20, 0.33), 16: (-0.12, 0.30, 0.32),
    }
    dirs = {
        11: ((1, 0, 0), (0, 1, 0), (0, 0, 1)), 12: ((-1, 0, 0), (0, 1, 0), (0, 0, 1)),
        13: ((0, -1, 0), (1, 0, 0), (0, 0, 1)), 14: ((0, 1, 0), (1, 0, 0), (0, 0, 1)),
        15: ((0, 0, 1), (1, 0, 0), (0, 1, 0)), 16: ((0, 0, 1), (-1, 0, 0), (0, -1, 0)),
    }
    # each point is excited along three directions; excitation node ids 101..118
    forces = []
    for i, (nid, p) in enumerate(pts.items()):
        for j, d in enumerate(dirs[nid]):
            forces.append((100 + 3 * i + j + 1, p, d))
    freq = np.arange(1, 1025, dtype=np.float64) * 0.125  # 256 Hz sampling, 1024 lines
    return _assemble(name, description, _engine_model(elastic), sensors, forces, freq,
                     ((60.0, 85.0), (3.0, 35.0)))


BENCHES: dict[str, Callable[[], Bench]] = {
    "block": lambda: _block(
        "block", "160.6 kg standard block on 4 springs, small elastic mode at 177 Hz",
        (_block_mode(177.0, 0.15, 0),),
    ),
    "block-rigid": lambda: _block("block-rigid", "160.6 kg standard block, rigid", ()),
    "block-flexible": lambda: _block(
        "block-flexible", "160.6 kg standard block, elastic modes at 450 and 610 Hz",
        (_block_mode(450.0, 1.0, 0), _block_mode(610.0, 1.0, 1)),
    ),
    "engine": lambda: _engine(
        "engine", "110 kg engine on 3 mounts, elastic mode at 118.5 Hz", _engine_modes()
    ),
    "engine-rigid": lambda: _engine("engine-rigid", "110 kg engine on 3 mounts, rigid", ()),
}


def get_bench(name: str) -> Bench:
    """The built-in bench called ``name`` (see :data:`BENCHES`)."""
    try:
        return BENCHES[name]()
    except KeyError:
        raise KeyError(
            f"unknown bench {name!r}: choose one of {', '.join(sorted(BENCHES))}"
        ) from None
