"""Identification errors over random draws on the built-in benches (median / 95th percentile).

Each noisy configuration is drawn ``N`` times (seeds 100..100+N-1; noise-free ones once) and
identified with the default options; errors against the bench model's truth: mass %, CoG mm,
worst inertia entry (about O and the CoG) as % of the largest principal moment, worst K entry
as % of sqrt(Kii Kjj); a refusal is an ``InputError``. ``refine`` runs ``--refine-points``
0, 1, 5 and 30 on engine-rigid with 2 % noise and +-3 mm location errors.

Run: ``.venv/bin/python benchmarks/identify_draws.py [N] [all|acc|refine]``
"""

from __future__ import annotations

import sys

import numpy as np

from hardware_mocks.benches import Bench, get_bench
from processing.data import InputError
from processing.identify import IdentificationResult, IdentifyOptions, identify
from processing.inertia import inertia_properties

CONFIGS = [("block-rigid", 0, 0), ("engine-rigid", 0, 0), ("block", 0, 0), ("engine", 0, 0),
           ("block-flexible", 0, 0),
           ("block", 0.02, 0.003), ("block-flexible", 0.01, 0.0), ("engine", 0.01, 0.002),
           ("engine-rigid", 0.02, 0.003), ("engine", 0.05, 0.005), ("block", 0.05, 0.005),
           ("block-rigid", 0.02, 0.003)]
METRICS = ("mass", "cog", "inertia", "stiffness")


def errors(bench: Bench, r: IdentificationResult) -> dict[str, float]:
    """Errors against the bench model's truth (see the module docstring)."""
    m = bench.model
    truth = inertia_properties(m.theta)
    p = r.properties
    scale = np.sqrt(np.outer(np.diag(m.K), np.diag(m.K)))
    tensor = max(np.max(np.abs(p.inertia_origin - truth.inertia_origin)),
                 np.max(np.abs(p.inertia_cog - truth.inertia_cog)))
    return {"mass": abs(p.mass - m.mass) / m.mass * 100,
            "cog": float(np.max(np.abs(p.cog - m.cog)) * 1000),
            "inertia": float(tensor / truth.principal_moments.max() * 100),
            "stiffness": float(np.max(np.abs(r.K - m.K) / scale) * 100)}


def _summary(errs: list[dict[str, float]]) -> str:
    return " ".join(f"{k} {np.median([e[k] for e in errs]):.3g}/"
                    f"{np.percentile([e[k] for e in errs], 95):.3g}" for k in METRICS)


def accuracy(n: int) -> None:
    """Median/p95 errors and refusals per configuration."""
    for name, noise, loc in CONFIGS:
        bench = get_bench(name)
        seeds = range(1) if noise == 0 and loc == 0 else range(n)
        errs, refused = [], 0
        for s in seeds:
            try:
                errs.append(errors(bench, identify(bench.frfset(noise, loc, seed=100 + s))))
            except InputError:
                refused += 1
        row = _summary(errs) if errs else ""
        print(f"{name} noise={noise} loc={loc}: refused {refused}/{len(seeds)} {row}", flush=True)


def refine(n: int) -> None:
    """Corrections and errors of response-point refinement against the number of rounds."""
    bench = get_bench("engine-rigid")
    for rounds in (0, 1, 5, 30):
        errs, corr = [], []
        for s in range(n):
            r = identify(bench.frfset(0.02, 0.003, seed=100 + s),
                         IdentifyOptions(refine_points=rounds))
            errs.append(errors(bench, r))
            c = r.point_corrections
            corr.append(0.0 if c is None else float(np.abs(c).max() * 1000))
        print(f"refine {rounds:2d}: largest correction mm {np.median(corr):.2f}/"
              f"{np.percentile(corr, 95):.2f} | {_summary(errs)}", flush=True)


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    which = sys.argv[2] if len(sys.argv) > 2 else "all"
    if which in ("all", "acc"):
        accuracy(n)
    if which in ("all", "refine"):
        refine(n)


if __name__ == "__main__":
    main()
