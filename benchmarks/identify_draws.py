"""Identification errors over random draws on the built-in benches (median / 95th percentile).

Each noisy configuration is drawn ``N`` times (seeds 100..100+N-1; noise-free ones once) and
identified with the default options; errors against the bench model's truth: mass %, CoG mm,
worst inertia entry (about O and the CoG) as % of the largest principal moment, worst K entry
as % of sqrt(Kii Kjj); a refusal is an ``InputError``. ``refine`` runs ``--refine-points``
0, 1, 3, 5 and 30 on engine-rigid with 2 % noise and +-3 mm location errors and checks the
claims of response-point refinement over the draws (:data:`REFINE_CLAIMS`; the tests keep
one draw each): 3 rounds lower the mean CoG and inertia errors, 30 rounds settle (no worse
than 5, points closer to the truth, no correction beyond the errors' reach). It exits 1 when
a claim fails.

Run: ``.venv/bin/python benchmarks/identify_draws.py [N] [all|acc|refine]``
"""

from __future__ import annotations

import sys
from collections.abc import Callable

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


ROUNDS = (0, 1, 3, 5, 30)
#: the noisy row's tolerances (mass %, CoG mm, inertia %, K %): on the mean errors after 3
#: rounds, and tighter ones on the median errors after 30
ROW_LIMITS = {"mass": 0.7, "cog": 2.0, "inertia": 1.0, "stiffness": 5.0}
SETTLED_LIMITS = {"mass": 0.3, "cog": 1.5, "inertia": 1.2, "stiffness": 1.5}
REFINE_CLAIMS = (
    "3 rounds: mean CoG error under 0.85x and mean inertia error under 0.95x of those "
    "without, mean errors within the noisy row's tolerances",
    "30 rounds: median errors no worse than 1.2x those of 5 rounds (+0.001), within "
    "mass 0.3 %, CoG 1.5 mm, inertia 1.2 %, K 1.5 %",
    "30 rounds: median RMS point error under 0.8x the nominal locations', every correction "
    "under 6 mm (the +-3 mm errors' reach)",
)


def _refine_draw(bench: Bench, seed: int, true_xyz: np.ndarray
                 ) -> tuple[dict[int, dict[str, float]], float, float]:
    """One draw's errors after each of :data:`ROUNDS`; after 30 rounds its largest correction
    (mm) and its RMS point error relative to the nominal locations'."""
    f = bench.frfset(0.02, 0.003, seed=seed)
    errs: dict[int, dict[str, float]] = {}
    for rounds in ROUNDS:
        r = identify(f, IdentifyOptions(refine_points=rounds))
        errs[rounds] = errors(bench, r)
    c = r.point_corrections
    assert c is not None
    nominal = np.sqrt(np.mean((f.resp_xyz - true_xyz) ** 2))
    after = np.sqrt(np.mean((f.resp_xyz - c - true_xyz) ** 2))
    return errs, float(np.abs(c).max() * 1000), float(after / nominal)


def refine(n: int) -> bool:
    """Corrections and errors of response-point refinement against the number of rounds over
    ``n`` draws (seeds 100..), and whether :data:`REFINE_CLAIMS` hold; True when they do."""
    bench = get_bench("engine-rigid")
    true_xyz = bench.frfset().resp_xyz
    draws = [_refine_draw(bench, 100 + s, true_xyz) for s in range(n)]
    by_rounds = {k: [d[0][k] for d in draws] for k in ROUNDS}
    corr = [d[1] for d in draws]
    loc = [d[2] for d in draws]
    for rounds, errs in by_rounds.items():
        print(f"refine {rounds:2d}: {_summary(errs)}", flush=True)
    print(f"refine 30: largest correction mm {np.median(corr):.2f}/{np.percentile(corr, 95):.2f}"
          f" (max {max(corr):.2f}), RMS point error / nominal {np.median(loc):.2f}/"
          f"{np.percentile(loc, 95):.2f}", flush=True)

    def stat(rounds: int, how: Callable[[list[float]], float]) -> dict[str, float]:
        return {k: float(how([e[k] for e in by_rounds[rounds]])) for k in METRICS}

    mean0, mean3 = stat(0, np.mean), stat(3, np.mean)
    med5, med30 = stat(5, np.median), stat(30, np.median)
    held = [
        mean3["cog"] < 0.85 * mean0["cog"] and mean3["inertia"] < 0.95 * mean0["inertia"]
        and all(mean3[k] <= v for k, v in ROW_LIMITS.items()),
        all(med30[k] <= 1.2 * med5[k] + 1e-3 for k in METRICS)
        and all(med30[k] <= v for k, v in SETTLED_LIMITS.items()),
        float(np.median(loc)) < 0.8 and max(corr) < 6.0,
    ]
    for claim, ok in zip(REFINE_CLAIMS, held, strict=True):
        print(f"{'holds' if ok else 'FAILS'}: {claim}", flush=True)
    return all(held)


def main() -> int:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    which = sys.argv[2] if len(sys.argv) > 2 else "all"
    if which in ("all", "acc"):
        accuracy(n)
    if which in ("all", "refine"):
        return 0 if refine(n) else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
