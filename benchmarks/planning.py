"""Test planning (``insitu plan``, ``processing/planning.py``) on the independent reference model.

For each scenario of ``hardware_mocks/reference/scenarios.py`` (``suite`` with this
benchmark's own seed, 3107, held out from the tests'; the error-free scenarios left out:
nothing to spread):

- candidates: 40 sensor positions and 40 excitation points on the body's surface (nodes
  spread by farthest-point sampling), each point with the directions a hammer reaches there
  (an axis along which no body node lies between the point and the outside);
- an approximate model, the truth perturbed as an operator's guess: mass +-10 %, CoG +-20 mm
  per axis, principal moments about the CoG +-20 % each, every mount rate +-30 %, the
  first elastic mode +-20 % (mount positions, axes and loss factors as built);
- :func:`processing.planning.plan_test` chooses 4 sensors and 9 excitations (D-optimal)
  for the scenario's noise, averages and lines, the stated uncertainties being its own
  error levels as standard deviations (as ``benchmarks/accuracy.py``'s ``stated_for``), and
  predicts the standard deviations; its time is measured;
- the achieved errors: Monte Carlo draws of the scenario's test errors (sensor location,
  misalignment, gain, transverse; force location) and noise (H1 over its averages) with
  ``hardware_mocks/reference/measurement.py`` on the chosen layout, each identified by
  :func:`processing.identify.fit` with default options; the same on random layouts of the
  same size (random sensors and excitations among the candidates, redrawn until E and T
  have rank 6).

Reported: per parameter group (mass, CoG x/y/z, the six entries of the tensor about the
CoG), predicted std / std of the achieved estimates over the draws (median over the group's
entries, then median, 5th and 95th percentile over the scenarios, and the share of the
scenario x entry cases within 0.5-2x); the same against the RMS error about the truth (the
scenario's elastic-mode bias included); the achieved CoG and inertia errors
(``hardware_mocks/reference/metrics.py``, median over the draws) of random over chosen
layouts (median over the scenarios), for the whole error and for its two parts on the same
layouts: the rigid-body part (the scenario's rigid-body truth with its test errors and
noise: what the search's criterion models) and the elastic modes' bias alone (the elastic
body without test errors or noise); the same ratio predicted by the search's own
first-order model (``linearised_std``); the planning time.

Run: ``.venv/bin/python benchmarks/planning.py [--scenarios 50] [--draws 12] [--jobs 2]
[--write-docs] [--json FILE] [--seed N]`` (default: a quick 6 scenarios). The published
table is seed 3107's; try changes on other seeds (``--seed 3108``), never on it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from docs_page import provenance  # noqa: E402

from hardware_mocks.reference.measurement import (  # noqa: E402
    force_channels,
    h1_with_noise,
    sensor_channels,
)
from hardware_mocks.reference.metrics import errors  # noqa: E402
from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario, suite  # noqa: E402
from processing.data import FRFSet, Geometry, InputError  # noqa: E402
from processing.geometry import GeometryError, check_geometry  # noqa: E402
from processing.identify import IdentifyOptions, fit  # noqa: E402
from processing.measurement import Measurement  # noqa: E402
from processing.montecarlo import StatedUncertainty  # noqa: E402
from processing.planning import (  # noqa: E402
    ApproximateModel,
    Candidates,
    Information,
    Layout,
    PlanningError,
    TestConditions,
    fisher_blocks,
    linearised_std,
    mount_stiffness,
    plan_test,
)

SEED = 3107
DOCS = Path(__file__).resolve().parent.parent / "docs" / "planning.md"
MARK = "<!-- written by benchmarks/planning.py -->"
N_CANDIDATES = 40
N_SENSORS, N_POINTS = 4, 9
GROUPS = {"mass": [0], "cog": [1, 2, 3], "inertia": [4, 5, 6, 7, 8, 9]}
GAIN_METRICS = ("cog", "inertia")
#: the error's parts the random / chosen table compares (:func:`measure`)
PARTS = {"whole": "whole error", "rigid": "rigid-body part (test errors, noise)",
         "elastic": "elastic modes' bias alone",
         "first_order": "predicted by the search's first-order model (std)"}
IU3 = np.triu_indices(3)


def stated_for(spec: ScenarioSpec) -> StatedUncertainty:
    """The scenario's error levels as standard deviations (as ``benchmarks/accuracy.py``)."""
    angle = float(np.hypot(np.deg2rad(spec.misalignment_deg) / 3, spec.transverse / np.sqrt(2)))
    return StatedUncertainty(location=spec.location_error / np.sqrt(3), angle=angle,
                             gain=spec.gain_error / np.sqrt(3), draws=300)


def _spread(points: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    chosen = [int(rng.integers(points.shape[0]))]
    d = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(count - 1):
        nxt = int(np.argmax(d * rng.uniform(0.7, 1.0, d.size)))
        chosen.append(nxt)
        d = np.minimum(d, np.linalg.norm(points - points[nxt], axis=1))
    return np.array(chosen)


def reachable(xyz: np.ndarray, node: int, h: float) -> list[np.ndarray]:
    """Force directions a hammer reaches at ``node``: along +-axis k when no body node lies
    on that line beyond the point on the side the hammer comes from."""
    p = xyz[node]
    out = []
    for k in range(3):
        others = [i for i in range(3) if i != k]
        line = np.all(np.abs(xyz[:, others] - p[others]) < 0.25 * h, axis=1)
        coord = xyz[line, k]
        d = np.zeros(3)
        if p[k] <= coord.min() + 1e-9:  # hammer from below: pushes +k
            d[k] = 1.0
            out.append(d.copy())
        if p[k] >= coord.max() - 1e-9:
            d[k] = -1.0
            out.append(d.copy())
    return out


def candidates_for(sc: Scenario, rng: np.random.Generator) -> tuple[Candidates, np.ndarray,
                                                                    np.ndarray]:
    """Candidates, and the body node of each candidate sensor and point."""
    body = sc.system.body
    xyz = body.xyz
    surface = np.flatnonzero(body.surface)
    h = float(np.min(np.linalg.norm(xyz[1:] - xyz[0], axis=1)))
    h = float(np.min([np.min(np.linalg.norm(np.delete(xyz, i, 0) - xyz[i], axis=1))
                      for i in surface[:20]]))
    s_nodes = surface[_spread(xyz[surface], N_CANDIDATES, rng)]
    p_nodes = surface[_spread(xyz[surface], N_CANDIDATES, rng)]
    ep, ed = [], []
    for i, n in enumerate(p_nodes):
        for d in reachable(xyz, int(n), h):
            ep.append(i)
            ed.append(d)
    cand = Candidates(np.arange(1, N_CANDIDATES + 1), xyz[s_nodes],
                      np.arange(101, 101 + N_CANDIDATES), xyz[p_nodes], np.array(ep),
                      np.array(ed))
    return cand, s_nodes, p_nodes


def approximate(sc: Scenario, rng: np.random.Generator) -> ApproximateModel:
    t = sc.truth
    ev, V = np.linalg.eigh(t.inertia_cog)
    J = (V * (ev * rng.uniform(0.8, 1.2, 3))) @ V.T
    K = np.zeros((6, 6))
    D = np.zeros((6, 6))
    for m in sc.mounts:
        k, d = mount_stiffness(m.position, m.axes, m.rates * rng.uniform(0.7, 1.3, 3),
                               m.loss_factors)
        K += k
        D += d
    fe = sc.first_elastic_hz
    return ApproximateModel(t.mass * rng.uniform(0.9, 1.1), t.cog + rng.uniform(-0.02, 0.02, 3),
                            J, K, D, first_elastic_hz=(None if not np.isfinite(fe)
                                                       else fe * rng.uniform(0.8, 1.2)))


def measure(sc: Scenario, s_nodes: np.ndarray, f_nodes: np.ndarray, f_dirs: np.ndarray,
            rng: np.random.Generator, part: str = "whole") -> dict[str, Any]:
    """One test of a layout on the reference model, identified with default options.

    ``part``: ``whole`` (the scenario's elastic body, test errors and noise), ``rigid`` (its
    rigid-body truth's FRFs, test errors and noise: what the search's criterion sees) or
    ``elastic`` (the elastic body without test errors or noise: its elastic modes' bias
    alone)."""
    spec = sc.spec
    xyz = sc.system.body.xyz
    k = 0.0 if part == "elastic" else 1.0
    sens = sensor_channels(xyz, s_nodes, rng, location_error=k * spec.location_error,
                           misalignment_deg=k * spec.misalignment_deg,
                           gain_error=k * spec.gain_error, transverse=k * spec.transverse)
    forces = force_channels(xyz, f_nodes, f_dirs, rng, location_error=k * spec.location_error)
    if part == "rigid":
        H = sc.truth.accelerance(sc.freq, xyz[sens.nodes], sens.vectors, xyz[forces.nodes],
                                 forces.vectors)
    else:
        H = sc.system.accelerance(sc.freq, sens.nodes, sens.vectors, forces.nodes,
                                  forces.vectors)
    H1, coh = h1_with_noise(H, k * spec.noise, spec.n_averages, rng)
    ids = np.concatenate([sens.ids, forces.ids])
    pts = np.concatenate([sens.reported_xyz, forces.reported_xyz])
    uniq, first = np.unique(ids, return_index=True)
    frf = FRFSet(sc.freq, H1, sens.ids, sens.reported_dirs, forces.ids, forces.reported_dirs,
                 Geometry(uniq, pts[first]), coherence=coh)
    try:
        r = fit(Measurement(frf), IdentifyOptions(uncertainty=False))
    except (InputError, GeometryError, ValueError, np.linalg.LinAlgError) as err:
        return {"refused": str(err)}
    p = r.properties
    e = errors(sc.truth, p.mass, p.cog, p.inertia_origin, p.inertia_cog, r.K)
    est = np.concatenate([[p.mass], p.cog, p.inertia_cog[IU3]])
    return {"errors": e, "estimate": est.tolist()}


def random_layout(cand: Candidates, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    for _ in range(1000):
        S = rng.choice(cand.sensor_xyz.shape[0], N_SENSORS, replace=False)
        P = rng.choice(cand.exc_dirs.shape[0], N_POINTS, replace=False)
        g = check_geometry(np.repeat(cand.sensor_xyz[S], 3, 0), np.tile(np.eye(3), (N_SENSORS, 1)),
                           cand.exc_xyz[P], cand.exc_dirs[P])
        if g.ok:
            return S, P
    raise ArithmeticError("no rank-6 random layout")


def first_order(info: Information, S: Any, P: Any, mass: float) -> list[float]:
    """The search's own first-order std (``linearised_std``) of a layout: the CoG's (the
    first moments' over the mass, m) and the largest of the tensor about O (kg m^2)."""
    s = linearised_std(info, Layout(tuple(int(i) for i in S), tuple(int(i) for i in P), 0.0,
                                    0))
    return [float(np.linalg.norm(s[1:4]) / mass), float(np.max(s[4:10]))]


def evaluate(spec: ScenarioSpec, draws: int, randoms: int, criterion: str = "D"
             ) -> dict[str, Any]:
    sc = build_scenario(spec)
    rng = np.random.default_rng([spec.seed, SEED])
    cand, s_nodes, p_nodes = candidates_for(sc, rng)
    model = approximate(sc, rng)
    cond = TestConditions(sc.freq, noise=spec.noise, averages=spec.n_averages,
                          stated=stated_for(spec), seed=spec.seed)
    row: dict[str, Any] = {"name": spec.name}
    t0 = time.perf_counter()
    try:
        design = plan_test(model, cand, N_SENSORS, N_POINTS, cond,
                           criterion="A" if criterion == "A" else "D")
    except PlanningError as err:  # counted and named in the table
        row["seconds"] = time.perf_counter() - t0
        row["plan_refused"] = str(err)
        return row
    row["seconds"] = time.perf_counter() - t0
    pred = design.prediction
    assert pred is not None
    row["predicted"] = np.concatenate([[pred.std["mass"]], pred.std["cog"],
                                       pred.std["inertia_cog"][IU3]]).tolist()
    row["cond_T"] = pred.geometry.cond_T
    S, P = list(design.layout.sensors), list(design.layout.excitations)
    f_nodes = p_nodes[cand.exc_point[P]]
    chosen = [measure(sc, s_nodes[S], f_nodes, cand.exc_dirs[P], rng) for _ in range(draws)]
    # the error's two parts on the same layouts: the rigid body with the test errors and
    # noise (what the criterion sees) and the elastic modes' bias alone
    parts: dict[str, dict[str, list[dict[str, Any]]]] = {
        "rigid": {"chosen": [measure(sc, s_nodes[S], f_nodes, cand.exc_dirs[P], rng, "rigid")
                             for _ in range(max(1, draws // 2))], "random": []},
        "elastic": {"chosen": [measure(sc, s_nodes[S], f_nodes, cand.exc_dirs[P], rng,
                                       "elastic")], "random": []}}
    # what the search's own first-order model says of the chosen and the random layouts
    info = fisher_blocks(model, cand, cond)
    row["first_order"] = {"chosen": first_order(info, S, P, model.mass), "random": []}
    rand = []
    per = max(1, draws // randoms)
    for _ in range(randoms):
        RS, RP = random_layout(cand, rng)
        row["first_order"]["random"].append(first_order(info, RS, RP, model.mass))
        layout = (s_nodes[RS], p_nodes[cand.exc_point[RP]], cand.exc_dirs[RP])
        rand += [measure(sc, *layout, rng) for _ in range(per)]
        for part in parts:
            parts[part]["random"].append(measure(sc, *layout, rng, part))
    truth = sc.truth
    row["truth"] = np.concatenate([[truth.mass], truth.cog, truth.inertia_cog[IU3]]).tolist()
    row["chosen"], row["random"], row["parts"] = chosen, rand, parts
    return row


def _ok(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in runs if "errors" in r]


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per group and scenario the median over the group's entries of predicted std over the
    achieved spread (std over the draws; robust: 1.4826 x median absolute deviation) and
    over the RMS error about the truth; random over chosen median errors."""
    kinds = ("std", "robust", "rms")
    ratio: dict[str, dict[str, list[float]]] = {k: {g: [] for g in GROUPS} for k in kinds}
    cases: dict[str, list[float]] = {g: [] for g in GROUPS}
    gain: dict[str, dict[str, list[float]]] = {}
    share: dict[str, list[float]] = {}
    refused = {"chosen": 0, "random": 0, "draws": 0}
    planned = [r for r in rows if "plan_refused" not in r]
    for row in planned:
        ok = _ok(row["chosen"])
        refused["draws"] += len(row["chosen"])
        refused["chosen"] += len(row["chosen"]) - len(ok)
        refused["random"] += len(row["random"]) - len(_ok(row["random"]))
        if len(ok) >= 3:
            est = np.array([r["estimate"] for r in ok])
            med = np.median(est, axis=0)
            spread = {"std": est.std(axis=0, ddof=1),
                      "robust": 1.4826 * np.median(np.abs(est - med), axis=0),
                      "rms": np.sqrt(np.mean((est - np.array(row["truth"])) ** 2, axis=0))}
            pred = np.array(row["predicted"])
            for g, idx in GROUPS.items():
                for k in kinds:
                    r = pred[idx] / np.maximum(spread[k][idx], 1e-300)
                    ratio[k][g].append(float(np.median(r)))
                cases[g] += (pred[idx] / np.maximum(spread["std"][idx], 1e-300)).tolist()
        if "first_order" in row:  # predicted random / chosen (median over the random ones)
            fo = row["first_order"]
            ratio_fo = np.median(np.array(fo["random"]), axis=0) / np.array(fo["chosen"])
            for m, v in zip(GAIN_METRICS, ratio_fo, strict=True):
                gain.setdefault("first_order", {}).setdefault(m, []).append(float(v))
        runs = {"whole": (ok, _ok(row["random"]))}
        runs |= {part: (_ok(v["chosen"]), _ok(v["random"]))
                 for part, v in row.get("parts", {}).items()}
        # each part's median errors (chosen, random) per metric, where both were measured
        med = {part: {m: [float(np.median([r["errors"][m] for r in runs_k])) for runs_k in ab]
                      for m in GAIN_METRICS}
               for part, ab in runs.items() if all(ab)}
        for part, by_metric in med.items():
            for m, (a, b) in by_metric.items():
                gain.setdefault(part, {}).setdefault(m, []).append(b / max(a, 1e-300))
        if "whole" in med and "elastic" in med:  # the elastic bias over the whole error
            for m in GAIN_METRICS:
                share.setdefault(m, []).append(med["elastic"][m][0]
                                               / max(med["whole"][m][0], 1e-300))
    secs = np.array([r["seconds"] for r in rows])
    return {"ratio": ratio, "cases": cases, "gain": gain, "share": share, "refused": refused,
            "seconds": secs, "cond_T": np.array([r["cond_T"] for r in planned]),
            "plan_refused": [r["plan_refused"] for r in rows if "plan_refused" in r]}


def tables(s: dict[str, Any]) -> list[str]:
    def q(v: list[float]) -> str:
        return (f"{np.percentile(v, 50):.2f} ({np.percentile(v, 5):.2f}-"
                f"{np.percentile(v, 95):.2f})") if v else "-"

    out = ["| group | scenarios | predicted / std of the estimates | predicted / robust "
           "spread | cases within 0.5-2x the std | predicted / RMS error |",
           "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for g in GROUPS:
        c = np.array(s["cases"][g])
        within = f"{np.mean((c >= 0.5) & (c <= 2.0)) * 100:.0f} %" if c.size else "-"
        r = s["ratio"]
        out.append(f"| {g} | {len(r['std'][g])} | {q(r['std'][g])} | {q(r['robust'][g])} | "
                   f"{within} | {q(r['rms'][g])} |")
    out += ["", "Each ratio cell: median (5th-95th percentile) over the scenarios.", "",
            "| achieved error, random / chosen layouts | error | scenarios | median (5th-95th "
            "percentile) | scenarios where the chosen layout is better |",
            "| --- | --- | ---: | ---: | ---: |"]
    for m in GAIN_METRICS:
        for part, what in PARTS.items():
            v = s["gain"].get(part, {}).get(m, [])
            better = f"{np.mean(np.array(v) > 1) * 100:.0f} %" if v else "-"
            out.append(f"| {m} | {what} | {len(v)} | {q(v)} | {better} |")
    out += ["", "The rigid-body part: the same layouts measured on the scenario's rigid-body "
            "truth (no elastic modes) with its test errors and noise; the elastic bias: on its "
            "elastic body without test errors or noise (one test a layout); the first-order "
            "prediction: the std of the CoG and of the largest entry of the tensor about O "
            "that the search minimises (noise information and test errors through E^+ and "
            "T^+), no identification run. The elastic bias "
            "on the chosen layout over its whole error, median (5th-95th percentile): "
            + ", ".join(f"{m} {q(s['share'][m])}" for m in GAIN_METRICS if s["share"].get(m))
            + "."]
    secs = s["seconds"]
    rf = s["refused"]
    out += ["", f"Planning {N_SENSORS} sensors and {N_POINTS} excitations from {N_CANDIDATES} "
            f"candidate sensors and {N_CANDIDATES} candidate points (search and prediction): "
            f"median {np.median(secs):.2f} s, max {np.max(secs):.2f} s. cond(T) of the chosen "
            f"layouts: median {np.median(s['cond_T']):.1f}, max {np.max(s['cond_T']):.1f}; "
            f"every chosen layout has rank-6 E and T (the search takes no other). "
            f"Identifications refused (no usable mass): chosen layouts {rf['chosen']} of "
            f"{rf['draws']} draws, random layouts {rf['random']}."]
    if s["plan_refused"]:
        out += ["", f"Scenarios the planner refused ({len(s['plan_refused'])}): "
                + "; ".join(f"`{m}`" for m in s["plan_refused"])]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", type=int, default=6)
    ap.add_argument("--draws", type=int, default=12, help="draws per layout kind")
    ap.add_argument("--randoms", type=int, default=4, help="random layouts per scenario")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--criterion", choices=("D", "A"), default="D")
    ap.add_argument("--seed", type=int, default=SEED,
                    help=f"scenario suite seed (default {SEED}, the published one: tune on "
                    "others)")
    ap.add_argument("--write-docs", action="store_true")
    ap.add_argument("--json", type=Path, help="write the per-scenario rows to this file")
    args = ap.parse_args(argv)
    specs = [s for s in suite(4 * args.scenarios, seed=args.seed)
             if not s.is_clean][:args.scenarios]
    t0 = time.perf_counter()
    console = Console()
    rows: list[dict[str, Any]] = []
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as ex:
            for row in ex.map(evaluate, specs, [args.draws] * len(specs),
                              [args.randoms] * len(specs), [args.criterion] * len(specs)):
                rows.append(row)
                console.print(f"{row['name']}: {row['seconds']:.2f} s "
                              f"{row.get('plan_refused', '')}")
    else:
        for spec in specs:
            row = evaluate(spec, args.draws, args.randoms, args.criterion)
            rows.append(row)
            console.print(f"{row['name']}: {row['seconds']:.2f} s")
    elapsed = time.perf_counter() - t0
    if args.json:
        args.json.write_text(json.dumps(rows))
    s = summarise(rows)
    text = tables(s)
    for line in text:
        console.print(line, soft_wrap=True)
    if args.write_docs:
        body = [MARK, "", f"Produced by `benchmarks/planning.py` (do not edit by hand): "
                f"{len(rows)} scenarios of `hardware_mocks/reference/scenarios.py` (`suite`, "
                f"seed {args.seed}, error-free ones left out), {args.draws} draws of the achieved "
                f"errors on the chosen layout, {args.randoms} random layouts x "
                f"{max(1, args.draws // args.randoms)} draws ({elapsed:.0f} s).", "",
                *provenance("benchmarks/planning.py"), "", *text, ""]
        old = DOCS.read_text() if DOCS.exists() else ""
        if MARK in old:
            head, rest = old.split(MARK, 1)
            tail = rest[rest.index("\n## "):] if "\n## " in rest else ""
            DOCS.write_text(head + "\n".join(body) + tail)
        else:
            DOCS.write_text(old + "\n" + "\n".join(body))
        console.print(f"written to {DOCS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())


