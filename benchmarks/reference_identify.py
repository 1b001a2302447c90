"""The plain reference: the article's method as a straightforward script, for speed ratios.

Reads a UFF file of accelerance FRFs (dataset 15 nodes, dataset 58 function type 4, SI, global
directions) with pyuff and runs the article's method as written, in Python loops over the
frequency lines and excitations, with numpy for the small matrices:

- eq. 6/12: the rigid-body accelerances at O, ``X_j = (E^T E)^-1 E^T H_j``, line by line;
- eqs. 7-11: the mass line, ``(M - K*/w^2) X = T`` stacked in real and imaginary parts over
  the lines and excitations of the mass-line band, M linear in the ten parameters, solved by
  least squares;
- eq. 14: ``K*_j = w^2 (M X_j - T) X_j^H (X_j X_j^H)^-1`` on the stiffness band's lines,
  K = mean Re K*, C = mean Im K* / w;
- section 2.2: the two steps repeated until the parameters converge.

It imports nothing from the project (its own E, T and M), so its numbers are also a check of
our conventions. The bands are given, as the article chooses them by hand.

    python benchmarks/reference_identify.py FILE.uff --mass-band 40 60 --stiffness-band 1 35
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pyuff

AXES = np.eye(3)


def skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def read(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                             np.ndarray]:
    """freq, H (n_resp, n_exc, n_f), response points and directions, force points and
    directions, from a UFF file's dataset 15 and dataset 58 records (function type 4)."""
    sets = pyuff.UFF(path).read_sets()
    nodes: dict[int, np.ndarray] = {}
    for s in sets:
        if s["type"] == 15:
            for n, x, y, z in zip(s["node_nums"], s["x"], s["y"], s["z"], strict=True):
                nodes[int(n)] = np.array([x, y, z])
        elif s["type"] == 2411:
            for n, x, y, z in zip(s["node_nums"], s["x"], s["y"], s["z"], strict=True):
                nodes[int(n)] = np.array([x, y, z])
    resp: list[tuple[int, int]] = []
    exc: list[tuple[int, int]] = []
    records = []
    for s in sets:
        if s["type"] != 58 or s["func_type"] != 4:
            continue
        r = (int(s["rsp_node"]), int(s["rsp_dir"]))
        e = (int(s["ref_node"]), int(s["ref_dir"]))
        if r not in resp:
            resp.append(r)
        if e not in exc:
            exc.append(e)
        records.append((resp.index(r), exc.index(e), s))
    freq = np.asarray(records[0][2]["x"], dtype=float)
    H = np.zeros((len(resp), len(exc), freq.size), complex)
    for i, k, s in records:
        H[i, k] = s["data"]

    def dirs(dofs: list[tuple[int, int]]) -> np.ndarray:
        return np.array([np.sign(c) * AXES[abs(c) - 1] for _, c in dofs])

    return (freq, H, np.array([nodes[n] for n, _ in resp]), dirs(resp),
            np.array([nodes[n] for n, _ in exc]), dirs(exc))


def mass_matrix(theta: np.ndarray) -> np.ndarray:
    """M at O from theta = [m, m xc, m yc, m zc, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz] (eq. 2)."""
    m, sx, sy, sz, jxx, jyy, jzz, jxy, jxz, jyz = theta
    S = skew(np.array([sx, sy, sz]))
    J = np.array([[jxx, -jxy, -jxz], [-jxy, jyy, -jyz], [-jxz, -jyz, jzz]])
    M = np.zeros((6, 6))
    M[:3, :3] = m * np.eye(3)
    M[:3, 3:] = -S
    M[3:, :3] = S
    M[3:, 3:] = J
    return M


def identify(freq: np.ndarray, H: np.ndarray, rxyz: np.ndarray, rdir: np.ndarray,
             exyz: np.ndarray, edir: np.ndarray, mass_band: tuple[float, float],
             stiffness_band: tuple[float, float], max_iter: int = 50,
             tol: float = 1e-8) -> dict[str, object]:
    """The article's method on H, looped as written; the result in SI units."""
    E = np.array([np.concatenate([d, np.cross(r, d)]) for r, d in zip(rxyz, rdir, strict=True)])
    T = np.array([np.concatenate([d, np.cross(p, d)]) for p, d in zip(exyz, edir, strict=True)]).T
    P = np.linalg.inv(E.T @ E) @ E.T  # eq. 6
    w = 2 * np.pi * freq
    mass_lines = [j for j in range(freq.size) if mass_band[0] <= freq[j] <= mass_band[1]]
    stiff_lines = [j for j in range(freq.size)
                   if stiffness_band[0] <= freq[j] <= stiffness_band[1] and freq[j] > 0]
    X = {j: P @ H[:, :, j] for j in set(mass_lines) | set(stiff_lines)}
    basis = [mass_matrix(np.eye(10)[p]) for p in range(10)]
    K = C = np.zeros((6, 6))
    theta = np.zeros(10)
    iterations = 0
    while iterations < max_iter:
        iterations += 1
        rows, rhs = [], []
        for j in mass_lines:  # eqs. 5, 7-11: M X = T + (K + j w C) X / w^2
            B = T + (K + 1j * w[j] * C) @ X[j] / w[j] ** 2
            for k in range(T.shape[1]):
                A = np.column_stack([Mp @ X[j][:, k] for Mp in basis])
                rows += [A.real, A.imag]
                rhs += [B[:, k].real, B[:, k].imag]
        new = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
        M = mass_matrix(new)
        Ks = []
        for j in stiff_lines:  # eq. 14
            Xj = X[j]
            Ks.append(w[j] ** 2 * (M @ Xj - T) @ Xj.conj().T @ np.linalg.inv(Xj @ Xj.conj().T))
        K = np.mean([k.real for k in Ks], axis=0)
        C = np.mean([k.imag / w[j] for k, j in zip(Ks, stiff_lines, strict=True)], axis=0)
        done = np.max(np.abs(new - theta) / np.maximum(np.abs(new), 1e-12)) < tol
        theta = new
        if done:
            break
    m = theta[0]
    return {"mass": float(m), "cog": (theta[1:4] / m).tolist(), "theta": theta.tolist(),
            "stiffness": K.tolist(), "damping": C.tolist(), "iterations": iterations}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("uff")
    ap.add_argument("--mass-band", type=float, nargs=2, required=True, metavar=("LO", "HI"))
    ap.add_argument("--stiffness-band", type=float, nargs=2, required=True, metavar=("LO", "HI"))
    a = ap.parse_args()
    result = identify(*read(a.uff), tuple(a.mass_band), tuple(a.stiffness_band))
    print(json.dumps(result))


if __name__ == "__main__":
    main()
