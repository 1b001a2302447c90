"""Random test scenarios on the reference model, from fixed seeds.

A :class:`ScenarioSpec` fixes everything a scenario draws (shape, mounts, sensors, forces,
errors, band); :func:`build_scenario` turns it into a :class:`Scenario`: the system, its
truth, the exact FRFs at the true points and the measured ones (H1 with noise, at the
reported points and directions). :func:`suite` gives the benchmark's specs.

Example
-------
>>> from hardware_mocks.reference.scenarios import build_scenario, suite
>>> sc = build_scenario(suite(3)[1])
>>> sc.H.shape == (sc.sensors.nodes.size, sc.forces.nodes.size, sc.freq.size)
True
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hardware_mocks.reference.body import SHAPES, make_body
from hardware_mocks.reference.kinematics import rigid_map, rotation
from hardware_mocks.reference.measurement import (
    Channels,
    force_channels,
    h1_with_noise,
    sensor_channels,
)
from hardware_mocks.reference.mounts import Mount
from hardware_mocks.reference.system import ReferenceSystem, Truth

__all__ = ["Scenario", "ScenarioSpec", "build_scenario", "excitation_cond", "suite"]

#: analyser spans a test chooses from, Hz
SPANS = (50.0, 100.0, 200.0, 400.0, 800.0, 1600.0, 3200.0)


@dataclass(frozen=True)
class ScenarioSpec:
    """Everything that defines one scenario (SI; angles in degrees).

    ``elastic_ratio`` is the free body's first elastic mode over the highest rigid-body
    mode (``None``: an infinitely stiff body). ``band_ratio`` is the measured span over the
    first elastic mode (the span is then snapped to :data:`SPANS` and kept at least 3 times
    the highest rigid-body mode). ``noise`` is relative to each record's RMS
    (:mod:`.measurement`). ``damping`` is the mounts' model (:mod:`.system`).
    """

    seed: int
    shape: str = "block"
    n_sensors: int = 4
    n_forces: int = 12
    n_mounts: int = 4
    noise: float = 0.0
    n_averages: int = 20
    location_error: float = 0.0
    misalignment_deg: float = 0.0
    gain_error: float = 0.0
    transverse: float = 0.0
    elastic_ratio: float | None = 8.0
    band_ratio: float = 1.5
    n_lines: int = 1600
    damping: Literal["hysteretic", "viscous"] = "hysteretic"
    stiffening: float = 0.0

    @property
    def family(self) -> str:
        return self.shape

    @property
    def tags(self) -> tuple[str, ...]:
        """Extra groups: "rigid-clean" (stiff body, no error), "sensors" (gain/transverse)."""
        t = []
        if self.elastic_ratio is None and self.is_clean:
            t.append("rigid-clean")
        if self.gain_error > 0 or self.transverse > 0:
            t.append("sensors")
        return tuple(t)

    @property
    def is_clean(self) -> bool:
        return (self.noise == 0 and self.location_error == 0 and self.misalignment_deg == 0
                and self.gain_error == 0 and self.transverse == 0)

    @property
    def name(self) -> str:
        stiff = "rigid" if self.elastic_ratio is None else f"x{self.elastic_ratio:.1f}"
        return (f"{self.seed:04d}-{self.shape}-{stiff}-n{self.noise * 100:.1f}"
                f"-l{self.location_error * 1000:.1f}")


def excitation_cond(xyz: NDArray[np.float64], dirs: NDArray[np.float64]) -> float:
    """Condition number of the excitation matrix ``T = [e; p x e]`` with its moment rows
    divided by the RMS distance of the points from O (a unit-free figure; the article asks
    < 20)."""
    T = np.einsum("nji,nj->in", rigid_map(xyz), dirs)
    length = float(np.sqrt(np.mean(np.sum(xyz**2, axis=1))))
    T[3:] /= length
    s = np.linalg.svd(T, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def _spread(points: NDArray[np.float64], count: int, rng: np.random.Generator,
            ) -> NDArray[np.int64]:
    """``count`` indices of well-spread points (farthest-point sampling from a random one)."""
    chosen = [int(rng.integers(points.shape[0]))]
    d = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(count - 1):
        nxt = int(np.argmax(d * rng.uniform(0.8, 1.0, d.size)))
        chosen.append(nxt)
        d = np.minimum(d, np.linalg.norm(points - points[nxt], axis=1))
    return np.array(chosen)


def _mounts(xyz: NDArray[np.float64], mass: float, n: int, rng: np.random.Generator,
            ) -> tuple[Mount, ...]:
    """``n`` inclined mounts under the body's lowest nodes, near its corners."""
    bottom = np.flatnonzero(xyz[:, 2] <= xyz[:, 2].min() + 1e-9)
    p = xyz[bottom]
    lo, hi = p.min(axis=0), p.max(axis=0)
    if n == 3:
        targets = [(lo[0], lo[1]), (lo[0], hi[1]), (hi[0], 0.5 * (lo[1] + hi[1]))]
    else:
        targets = [(lo[0], lo[1]), (lo[0], hi[1]), (hi[0], lo[1]), (hi[0], hi[1])]
    f_bounce = rng.uniform(6.0, 14.0)
    k_total = mass * (2 * np.pi * f_bounce) ** 2
    out = []
    for tx, ty in targets:
        node = int(bottom[np.argmin((p[:, 0] - tx) ** 2 + (p[:, 1] - ty) ** 2)])
        tilt = np.deg2rad(rng.uniform(10.0, 45.0))
        yaw = rng.uniform(0, 2 * np.pi)
        horizontal = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        A = rotation(horizontal * tilt) @ rotation([0.0, 0.0, rng.uniform(0, 2 * np.pi)])
        kw = k_total / n * rng.uniform(0.7, 1.3)
        rates = np.array([kw * rng.uniform(0.15, 0.6), kw * rng.uniform(0.15, 0.6), kw])
        out.append(Mount(node, xyz[node], A.T, rates, rng.uniform(0.05, 0.25, 3)))
    return tuple(out)


@dataclass(frozen=True)
class Scenario:
    """One built scenario. Arrays are SI; H is accelerance (m/s^2)/N.

    Attributes
    ----------
    spec : what it was built from
    system : the reference system (body, mounts)
    freq : (n_f,) Hz, the measured lines (``df`` to the span)
    sensors, forces : measured DOFs, true and reported (:class:`.measurement.Channels`)
    H_exact : (n_ch, n_exc, n_f) exact FRFs between the true DOFs (sensor errors included)
    H, coherence : the measured H1 and its coherence
    """

    spec: ScenarioSpec
    system: ReferenceSystem
    freq: NDArray[np.float64]
    sensors: Channels
    forces: Channels
    H_exact: NDArray[np.complex128]
    H: NDArray[np.complex128]
    coherence: NDArray[np.float64]

    @property
    def truth(self) -> Truth:
        return self.system.truth

    @property
    def mounts(self) -> tuple[Mount, ...]:
        return self.system.mounts

    @cached_property
    def rigid_modes_hz(self) -> NDArray[np.float64]:
        """Undamped rigid-body modes of the truth, Hz."""
        return self.truth.rigid_modes()[0]

    @cached_property
    def natural_frequencies_hz(self) -> NDArray[np.float64]:
        """Modes of the assembled system (six mount modes, then elastic ones), Hz."""
        return self.system.natural_frequencies_hz()

    @property
    def first_elastic_hz(self) -> float:
        return self.system.first_elastic_hz()

    def geometry(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Reported node ids (unique) and their coordinates (n, 3), m."""
        ids = np.concatenate([self.sensors.ids, self.forces.ids])
        xyz = np.concatenate([self.sensors.reported_xyz, self.forces.reported_xyz])
        uniq, first = np.unique(ids, return_index=True)
        return uniq, xyz[first]


def build_scenario(spec: ScenarioSpec) -> Scenario:
    """Build the scenario ``spec`` describes (deterministic in ``spec.seed``)."""
    rng = np.random.default_rng([spec.seed, 12])
    body = make_body(spec.shape, rng)
    centre = 0.5 * (body.xyz.min(axis=0) + body.xyz.max(axis=0))
    body = body.moved(-centre + rng.uniform(-0.15, 0.15, 3))
    mounts = _mounts(body.xyz, body.mass, spec.n_mounts, rng)
    rigid_sys = ReferenceSystem(body, mounts, rigid=True, damping=spec.damping)
    if spec.stiffening:
        f_k = float(np.exp(np.mean(np.log(rigid_sys.truth.rigid_modes()[0]))))
        rigid_sys = ReferenceSystem(body, mounts, rigid=True, damping=spec.damping,
                                    stiffening=spec.stiffening, stiffness_hz=f_k)
    f_rigid = float(rigid_sys.truth.rigid_modes()[0][-1])
    if spec.elastic_ratio is None:
        system = rigid_sys
        f_elastic = float("inf")
        span = min((s for s in SPANS if s >= 5 * f_rigid), default=SPANS[-1])
    else:
        f_free = float(body.free_modes_hz(7)[6])
        f_elastic = spec.elastic_ratio * f_rigid
        system = ReferenceSystem(body.scaled((f_elastic / f_free) ** 2), mounts,
                                 damping=spec.damping, stiffening=rigid_sys.stiffening,
                                 stiffness_hz=rigid_sys.stiffness_hz)
        want = max(spec.band_ratio * f_elastic, 3 * f_rigid)
        span = min((s for s in SPANS if s >= want), default=SPANS[-1])
    df = span / spec.n_lines
    freq: NDArray[np.float64] = df * np.arange(1, spec.n_lines + 1, dtype=float)
    surface = np.flatnonzero(body.surface)
    s_nodes = surface[_spread(body.xyz[surface], spec.n_sensors, rng)]
    sensors = sensor_channels(body.xyz, s_nodes, rng, location_error=spec.location_error,
                              misalignment_deg=spec.misalignment_deg,
                              gain_error=spec.gain_error, transverse=spec.transverse)
    axes = np.vstack([np.eye(3), -np.eye(3)])
    for _ in range(500):
        nodes = rng.choice(surface, spec.n_forces)
        dirs = axes[rng.integers(0, 6, spec.n_forces)]
        key = np.unique(np.column_stack([nodes, np.abs(dirs) @ [1, 2, 3]]), axis=0)
        if key.shape[0] == spec.n_forces and excitation_cond(body.xyz[nodes], dirs) < 15.0:
            break
    else:
        raise ArithmeticError(f"scenario {spec.seed}: no excitation set with cond(T) < 15")
    forces = force_channels(body.xyz, nodes, dirs, rng, location_error=spec.location_error)
    H_exact = system.accelerance(freq, sensors.nodes, sensors.vectors, forces.nodes,
                                 forces.vectors)
    H, coh = h1_with_noise(H_exact, spec.noise, spec.n_averages, rng)
    return Scenario(spec, system, freq, sensors, forces, H_exact, H, coh)


def suite(n: int = 200, seed: int = 2026) -> list[ScenarioSpec]:
    """The benchmark's ``n`` scenario specs, the same for the same ``seed``.

    Shapes cycle block, engine, gearbox. Every tenth scenario is a stiff, error-free body
    ("rigid-clean"), every tenth (offset 5) a noise- and error-free flexible one with its
    first elastic mode at 20x the highest rigid mode; the others draw 3-6 triaxial sensors,
    6-24 forces, 3-4 mounts, noise 0-3 %, location errors 0-3 mm, misalignment 0-2 deg,
    elastic ratio 1.5-20 (log-uniform), span 0.3-3x the first elastic mode; one in three has
    sensor gain (+-2 %) and transverse sensitivity (3 %) errors; one in three flexible ones
    has viscous mounts (the rigid-clean ones all have: the methods' own damping model).
    """
    out = []
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        spec = ScenarioSpec(
            seed=seed * 1000 + i, shape=SHAPES[i % 3], n_sensors=int(rng.integers(3, 7)),
            n_forces=int(rng.integers(6, 25)), n_mounts=int(rng.integers(3, 5)),
            noise=float(rng.uniform(0, 0.03)), n_averages=int(rng.choice([10, 20])),
            location_error=float(rng.uniform(0, 0.003)),
            misalignment_deg=float(rng.uniform(0, 2.0)),
            elastic_ratio=float(np.exp(rng.uniform(np.log(1.5), np.log(20.0)))),
            band_ratio=float(np.exp(rng.uniform(np.log(0.3), np.log(3.0)))),
            n_lines=int(rng.choice([800, 1600])),
            damping="viscous" if rng.uniform() < 1 / 3 else "hysteretic")
        if rng.uniform() < 1 / 3:
            spec = replace(spec, gain_error=0.02, transverse=0.03)
        if i % 10 == 0:
            spec = replace(spec, noise=0.0, location_error=0.0, misalignment_deg=0.0,
                           gain_error=0.0, transverse=0.0, elastic_ratio=None,
                           damping="viscous")
        elif i % 10 == 5:
            spec = replace(spec, noise=0.0, location_error=0.0, misalignment_deg=0.0,
                           gain_error=0.0, transverse=0.0, elastic_ratio=20.0)
        out.append(spec)
    return out
