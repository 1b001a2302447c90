"""Identification speed at the engine's size: 4 triaxial points, 18 forces, 500 lines.

Measured in one run:
- reference: a plain per-line loop of the article's equations (eq. 6 per line, the
  stacked eqs. 8-10 matrix A and B, least squares eq. 11), as a straightforward
  implementation would do it;
- core: the same mass-line solve vectorised (pinv(E) once, all lines at once,
  10x10 normal equations from 6x6 moments of X);
- the full plain method (iteration of section 2.2, fixed bands) and the full
  default pipeline (band selection, elastic-mode detection, leakage terms,
  iteration, checks, synthesis);
- a 100-run Monte Carlo of +-3 mm point-location errors with the plain method
  and with the default pipeline.

Run: ``.venv/bin/python benchmarks/identify.py``
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from rich.console import Console
from rich.table import Table

from hardware_mocks.benches import get_bench
from processing.data import FRFSet
from processing.geometry import excitation_matrix, response_matrix
from processing.identify import IdentifyOptions, identify
from processing.inertia import mass_matrix
from processing.massline import fit_inertia

N_LINES = 500
MASS_BAND = (40.0, 60.0)
STIFF_BAND = (1.0, 35.0)


def best_time(fn: Callable[[], object], repeat: int = 7, number: int = 3) -> float:
    """Best of ``repeat`` means over ``number`` calls, seconds."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return float(best)


def reference_loop(frf: FRFSet, band: tuple[float, float]) -> np.ndarray:
    """The article's mass-line step as a per-line loop (eqs. 6, 8-11), K* = 0."""
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    rows_A, rows_B = [], []
    for j in np.flatnonzero((frf.freq >= band[0]) & (frf.freq <= band[1])):
        X = np.linalg.inv(E.T @ E) @ E.T @ frf.H[:, :, j]  # eq. 6, per line
        for k in range(X.shape[1]):  # eq. 8: M x_k = t_k, linear in theta
            for part in (np.real, np.imag):
                x = part(X[:, k])
                A = np.zeros((6, 10))
                for p in range(10):
                    e = np.zeros(10)
                    e[p] = 1.0
                    A[:, p] = mass_matrix(e) @ x
                rows_A.append(A)
                rows_B.append(T[:, k] if part is np.real else np.zeros(6))
    A = np.vstack(rows_A)
    B = np.concatenate(rows_B)
    return np.linalg.lstsq(A, B, rcond=None)[0]  # eq. 11


def core(frf: FRFSet, band: tuple[float, float]) -> np.ndarray:
    """The same solve, vectorised."""
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    sel = (frf.freq >= band[0]) & (frf.freq <= band[1])
    n_r, n_e = frf.H.shape[:2]
    H = frf.H[..., sel]
    X = (np.linalg.pinv(E) @ H.reshape(n_r, -1)).reshape(6, n_e, -1)
    return fit_inertia(X, T[:, :, None]).theta


def main() -> None:
    console = Console()
    bench = get_bench("engine-rigid")
    full = bench.frfset(noise=0.02, location_error=0.0, seed=0)
    frf = FRFSet(full.freq[:N_LINES], full.H[..., :N_LINES], full.resp_nodes, full.resp_dirs,
                 full.exc_nodes, full.exc_dirs, full.geometry)
    ref_theta = reference_loop(frf, MASS_BAND)
    core_theta = core(frf, MASS_BAND)
    agree = float(np.max(np.abs(core_theta - ref_theta) / np.abs(ref_theta)))
    plain_opt = IdentifyOptions(method="plain", mass_band=MASS_BAND, stiffness_band=STIFF_BAND)
    t_ref = best_time(lambda: reference_loop(frf, MASS_BAND), repeat=3, number=1)
    t_core = best_time(lambda: core(frf, MASS_BAND))
    t_plain = best_time(lambda: identify(frf, plain_opt))
    t_full = best_time(lambda: identify(frf), repeat=5)
    n_sel = int(np.count_nonzero((frf.freq >= MASS_BAND[0]) & (frf.freq <= MASS_BAND[1])))

    table = Table(title=f"Identification, 12 response DOFs x 18 forces x {N_LINES} lines "
                  f"({n_sel} mass-line lines)")
    table.add_column("implementation")
    table.add_column("ms / identification", justify="right")
    table.add_column("speed-up vs reference loop", justify="right")
    for name, t in (
        ("reference: per-line loop, stacked A (eq. 8-11)", t_ref),
        ("core: vectorised, moments (same equations)", t_core),
        ("plain method, full (iteration, fixed bands)", t_plain),
        ("default pipeline (auto bands, leakage, checks)", t_full),
    ):
        table.add_row(name, f"{t * 1e3:.3f}", f"{t_ref / t:.1f}x")
    console.print(table)
    console.print(f"core vs reference: max relative difference of theta {agree:.2e}")

    # Monte Carlo: 100 runs of +-3 mm location errors (noise-free FRFs, as the article's section 4)
    runs = [bench.frfset(0.0, 0.003, seed=s) for s in range(100)]
    runs = [FRFSet(r.freq[:N_LINES], r.H[..., :N_LINES], r.resp_nodes, r.resp_dirs, r.exc_nodes,
                   r.exc_dirs, r.geometry) for r in runs]
    t0 = time.perf_counter()
    th_core = np.array([identify(r, plain_opt).theta for r in runs])
    t_mc_core = time.perf_counter() - t0
    t0 = time.perf_counter()
    th_full = np.array([identify(r).theta for r in runs])
    t_mc_full = time.perf_counter() - t0
    truth = bench.model.theta
    mc = Table(title="Monte Carlo, 100 runs of +-3 mm point-location errors")
    mc.add_column("implementation")
    mc.add_column("total s", justify="right")
    mc.add_column("mass error RMS %", justify="right")
    mc.add_column("CoG error RMS mm", justify="right")
    for name, th, t in (("plain method (fixed bands)", th_core, t_mc_core),
                        ("default pipeline", th_full, t_mc_full)):
        m_err = (th[:, 0] - truth[0]) / truth[0] * 100
        c_err = (th[:, 1:4] / th[:, :1] - truth[1:4] / truth[0]) * 1e3
        mc.add_row(name, f"{t:.2f}", f"{np.sqrt(np.mean(m_err**2)):.3f}",
                   f"{np.sqrt(np.mean(c_err**2)):.3f}")
    console.print(mc)


if __name__ == "__main__":
    main()
