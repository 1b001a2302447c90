"""Accuracy on the independent reference model's scenario suite (``hardware_mocks.reference``).

Each scenario (a lattice body on inclined mounts with its exact truth, FRFs measured with
noise and sensor/location errors, see ``hardware_mocks/reference/scenarios.py``) is written
to a binary UFF file with its reported geometry, and identified three ways:

- ``default``: ``insitu identify FILE.uff`` as a user runs it (``app.cli.main.main``
  in-process; a non-zero exit status is a refusal, its stderr line the reason);
- ``plain``: ``insitu identify FILE.uff --method plain``;
- ``article``: the article's method written independently
  (``hardware_mocks/reference/article.py``) with its own band rule, on the same FRFs and
  reported geometry.

Errors (``hardware_mocks/reference/metrics.py``): mass %, CoG distance mm, worst inertia
entry (about O and about the CoG) as % of the largest principal moment, worst K entry as %
of sqrt(Kii Kjj). The table gives, per family (body shape), per tag and overall, the median
and 95th percentile over the scenarios a method answered, and its refusals.

Coverage (``--coverage``): the default method with its uncertainty (the fit's covariance
plus the Monte Carlo of the test uncertainties a user would state for the scenario: its
location, misalignment/transverse and gain error levels as standard deviations), and per
parameter group (mass, CoG, inertia about the CoG, K, C of viscous mounts) the fraction of
scenario x entry cases with ``|error| <= 1.96 std`` and the median ``|error| / std``;
also over the results that pass their own checks (synthesis error, physical consistency).
With ``--write-docs`` it writes its own section of docs/accuracy.md.

Run: ``.venv/bin/python benchmarks/accuracy.py [--scenarios 200] [--family engine]
[--jobs 2] [--write-docs] [--json FILE] [--coverage]``. BLAS runs single-threaded in every
process (set before numpy is imported); ``--jobs`` runs scenarios in parallel processes.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import UTC, datetime  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from app.cli.main import main as insitu_main  # noqa: E402
from app.io.uff import write_frf_uff  # noqa: E402
from hardware_mocks.reference.article import ArticleRefusalError, identify_scenario  # noqa: E402
from hardware_mocks.reference.metrics import METRICS, errors  # noqa: E402
from hardware_mocks.reference.scenarios import (  # noqa: E402
    Scenario,
    ScenarioSpec,
    build_scenario,
    suite,
)
from processing.data import FRFSet, Geometry, InputError  # noqa: E402
from processing.geometry import GeometryError  # noqa: E402
from processing.identify import IdentifyOptions, identify  # noqa: E402
from processing.montecarlo import StatedUncertainty  # noqa: E402

METHODS = ("default", "plain", "article")
DOCS = Path(__file__).resolve().parent.parent / "docs" / "accuracy.md"


def frfset_of(sc: Scenario) -> FRFSet:
    """The scenario's measured FRFs as the project's FRFSet (reported geometry)."""
    ids, xyz = sc.geometry()
    return FRFSet(freq=sc.freq, H=sc.H, resp_nodes=sc.sensors.ids,
                  resp_dirs=sc.sensors.reported_dirs, exc_nodes=sc.forces.ids,
                  exc_dirs=sc.forces.reported_dirs, geometry=Geometry(ids, xyz),
                  coherence=sc.coherence)


def run_cli(args: list[str]) -> tuple[int, dict[str, Any] | None, str]:
    """``insitu ARGS --out JSON`` in-process: exit status, result JSON, last stderr line."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "result.json"
        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = insitu_main([*args, "--out", str(out)])
        result = json.loads(out.read_text()) if code == 0 and out.exists() else None
    lines = err.getvalue().strip().splitlines()
    return code, result, lines[-1] if lines else ""


def evaluate(spec: ScenarioSpec) -> dict[str, Any]:
    """Errors (or the refusal) of each method on one scenario."""
    sc = build_scenario(spec)
    row: dict[str, Any] = {"name": spec.name, "family": spec.family, "tags": list(spec.tags)}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{spec.name}.uff"
        write_frf_uff(path, frfset_of(sc), binary=True)
        for method, extra in (("default", []), ("plain", ["--method", "plain"])):
            t0 = time.perf_counter()
            code, res, msg = run_cli(["identify", str(path), *extra])
            if res is None:
                row[method] = {"refused": msg or f"exit status {code}"}
            else:
                row[method] = {"errors": errors(sc.truth, res["mass"], res["cog"],
                                                res["inertia_origin"], res["inertia_cog"],
                                                res["stiffness"]),
                               "bands": res["bands"], "seconds": time.perf_counter() - t0}
    try:
        a = identify_scenario(sc)
        row["article"] = {"errors": errors(sc.truth, a.mass, a.cog, a.inertia_origin,
                                           a.inertia_cog, a.K),
                          "bands": {"mass_line": a.mass_band, "stiffness": a.stiffness_band}}
    except ArticleRefusalError as err:
        row["article"] = {"refused": str(err)}
    return row


#: parameter groups of the coverage table
COVERAGE_GROUPS = ("mass", "cog", "inertia", "K", "C")
#: draws of the Monte Carlo in the coverage benchmark
COVERAGE_DRAWS = 300


def stated_for(spec: ScenarioSpec) -> StatedUncertainty:
    """The standard uncertainties a user would state for a scenario: its error levels as
    standard deviations (uniform +-a -> a / sqrt 3; a rotation of angle uniform in 0-a about a
    random axis -> a / 3 about each axis; transverse sensitivity t along a random
    perpendicular -> t / sqrt 2 about each perpendicular axis)."""
    angle = float(np.hypot(np.deg2rad(spec.misalignment_deg) / 3, spec.transverse / np.sqrt(2)))
    return StatedUncertainty(location=spec.location_error / np.sqrt(3), angle=angle,
                             gain=spec.gain_error / np.sqrt(3), draws=COVERAGE_DRAWS)


def evaluate_coverage(spec: ScenarioSpec) -> dict[str, Any]:
    """|error| / std of every entry of each group for one scenario (default method with its
    uncertainty), whether its checks pass, and the identification times with and without
    the covariance part."""
    sc = build_scenario(spec)
    frf = frfset_of(sc)
    row: dict[str, Any] = {"name": spec.name, "family": spec.family, "tags": list(spec.tags)}
    try:
        t0 = time.perf_counter()
        identify(frf, IdentifyOptions(uncertainty=False))
        t1 = time.perf_counter()
        r = identify(frf, IdentifyOptions(stated=stated_for(spec)))
        t2 = time.perf_counter()
        identify(frf)
        t3 = time.perf_counter()
    except (InputError, GeometryError) as err:
        row["refused"] = str(err)
        return row
    except (np.linalg.LinAlgError, ValueError) as err:  # the CLI reports these as refusals
        row["refused"] = f"{type(err).__name__}: {err}"
        return row
    u = r.uncertainty
    assert u is not None
    tr, p = sc.truth, r.properties
    iu3, iu6 = np.triu_indices(3), np.triu_indices(6)
    pairs: dict[str, tuple[Any, Any, Any]] = {
        "mass": (p.mass, tr.mass, u.std["mass"]), "cog": (p.cog, tr.cog, u.std["cog"]),
        "inertia": (p.inertia_cog[iu3], tr.inertia_cog[iu3], u.std["inertia_cog"][iu3]),
        "K": (r.K[iu6], tr.K[iu6], u.std["stiffness"][iu6])}
    if spec.damping == "viscous":
        pairs["C"] = (r.C[iu6], tr.C[iu6], u.std["damping"][iu6])
    row["ratio"] = {g: (np.abs(np.ravel(e) - np.ravel(t)) / np.maximum(np.ravel(s), 1e-300)
                        ).tolist() for g, (e, t, s) in pairs.items()}
    checks = r.checks()
    row["checks_pass"] = bool(checks["reconstruction_error"]["pass"]
                              and checks["physical_consistency"]["pass"])
    row["seconds"] = {"plain": t1 - t0, "with_mc": t2 - t1, "covariance": t3 - t2}
    return row


def coverage_table(rows: list[dict[str, Any]]) -> list[list[str]]:
    """Rows: group, cases, coverage, median |error|/std, then the same over passing checks."""
    out = []
    for g in COVERAGE_GROUPS:
        cells = [g]
        for subset in (rows, [r for r in rows if r.get("checks_pass")]):
            v = np.concatenate([np.asarray(r["ratio"][g]) for r in subset
                                if "ratio" in r and g in r["ratio"]] or [np.zeros(0)])
            cells += ([f"{v.size}", f"{np.mean(v <= 1.96) * 100:.1f} %", f"{np.median(v):.3g}"]
                      if v.size else ["0", "-", "-"])
        out.append(cells)
    return out


COVERAGE_HEADER = ["group", "cases", "within 1.96 std", "median abs(error)/std",
                   "cases (checks pass)", "within 1.96 std (checks pass)",
                   "median abs(error)/std (checks pass)"]


def main_coverage(specs: list[ScenarioSpec], args: argparse.Namespace) -> int:
    console = Console()
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(evaluate_coverage, specs, chunksize=1))
    elapsed = time.perf_counter() - t0
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))
    body = coverage_table(rows)
    table = Table(title=f"Coverage of the 95 % intervals on {len(rows)} scenarios "
                        f"({elapsed:.0f} s)")
    for h in COVERAGE_HEADER:
        table.add_column(h)
    for cells in body:
        table.add_row(*cells)
    console.print(table)
    times = [r["seconds"] for r in rows if "seconds" in r]
    ratio = np.array([t["covariance"] / t["plain"] for t in times])
    mc = np.array([t["with_mc"] - t["covariance"] for t in times])
    refused = sum(1 for r in rows if "refused" in r)
    passing = sum(1 for r in rows if r.get("checks_pass"))
    timing = (f"identification with / without the covariance part: median "
              f"{np.median(ratio):.2f}x, max {np.max(ratio):.2f}x; Monte Carlo of "
              f"{COVERAGE_DRAWS} draws: median {np.median(mc):.2f} s")
    console.print(f"{refused} refused, {passing} pass their checks; {timing}")
    if args.write_docs:
        write_coverage_docs(body, len(rows), refused, passing, timing, elapsed, args)
        console.print(f"written to {DOCS}")
    return 0


COVERAGE_TITLE = "## Coverage of the stated uncertainty"


def write_coverage_docs(body: list[list[str]], n: int, refused: int, passing: int,
                        timing: str, elapsed: float, args: argparse.Namespace) -> None:
    """Replace (or append) the coverage section of docs/accuracy.md."""
    text = DOCS.read_text() if DOCS.exists() else ""
    head = text.split(COVERAGE_TITLE)[0].rstrip("\n")
    after = text.split(COVERAGE_TITLE, 1)[1] if COVERAGE_TITLE in text else ""
    later = after[after.index("\n## ") + 1:] if "\n## " in after else ""  # other sections
    shown = [a for i, a in enumerate(sys.argv[1:])
             if a != "--json" and (i == 0 or sys.argv[i] != "--json")]
    lines = [
        "", "", COVERAGE_TITLE, "",
        "Produced by `benchmarks/accuracy.py --coverage` (do not edit by hand). The default "
        "method with its uncertainty (docs/uncertainty.md): the fit's covariance plus the "
        f"Monte Carlo ({COVERAGE_DRAWS} draws) of the test uncertainties a user would state "
        "for the scenario, i.e. its own location, misalignment/transverse and gain error "
        "levels as standard deviations (`stated_for`). A case is one entry of one group in "
        "one scenario (mass; CoG x, y, z; the six entries of the tensor about the CoG; the 21 "
        "of K; the 21 of C for viscous mounts only, hysteretic ones have no viscous truth); "
        "it is covered when |error| <= 1.96 std. 'checks pass': the result's synthesis "
        "error and physical-consistency checks pass (what a test engineer would sign off).",
        "",
        f"- date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}",
        f"- command: `python benchmarks/accuracy.py {' '.join(shown)}` ({elapsed:.0f} s)",
        f"- {n} scenarios, {refused} refused, {passing} pass their checks",
        f"- {timing}",
        "",
        "| " + " | ".join(COVERAGE_HEADER) + " |",
        "| " + " | ".join("---" if i == 0 else "---:" for i in range(len(COVERAGE_HEADER)))
        + " |",
        *("| " + " | ".join(c) + " |" for c in body),
        "",
    ]
    DOCS.write_text(head + "\n".join(lines) + ("\n\n" + later if later else ""))


def worse_than_article(row: dict[str, Any]) -> bool:
    """Default refused where the article answered, or is worse in any metric."""
    art, dft = row["article"], row["default"]
    if "errors" not in art:
        return False
    if "errors" not in dft:
        return True
    return any(dft["errors"][k] > art["errors"][k] for k, _ in METRICS)


def groups(rows: list[dict[str, Any]]) -> list[tuple[str, list[dict[str, Any]]]]:
    """(name, rows) per family, per tag, then all."""
    out = []
    for fam in sorted({r["family"] for r in rows}):
        out.append((fam, [r for r in rows if r["family"] == fam]))
    for tag in sorted({t for r in rows for t in r["tags"]}):
        out.append((f"[{tag}]", [r for r in rows if tag in r["tags"]]))
    out.append(("all", rows))
    out.append(("all, article answered", [r for r in rows if "errors" in r["article"]]))
    return out


def ratios(rows: list[dict[str, Any]]) -> list[tuple[str, float, float]]:
    """(metric, default / article median, default / article p95) on the scenarios both
    answered."""
    both = [r for r in rows if "errors" in r["article"] and "errors" in r["default"]]
    out = []
    for key, _ in METRICS:
        d = np.array([r["default"]["errors"][key] for r in both])
        a = np.array([r["article"]["errors"][key] for r in both])
        if d.size:
            out.append((key, float(np.median(d) / np.median(a)),
                        float(np.percentile(d, 95) / np.percentile(a, 95))))
    return out


def refusal_kinds(rows: list[dict[str, Any]], method: str) -> list[tuple[int, str, str]]:
    """(count, message with numbers as #, one example) per kind of refusal of ``method``."""
    kinds: dict[str, list[str]] = {}
    for r in rows:
        if "refused" in r[method]:
            msg = r[method]["refused"]
            kinds.setdefault(re.sub(r"\d+(\.\d+)?", "#", msg), []).append(msg)
    return sorted(((len(v), k, v[0]) for k, v in kinds.items()), reverse=True)


def summary(rows: list[dict[str, Any]]) -> list[list[str]]:
    """Table rows: group, method, scenarios, refusals, then median / p95 of each metric."""
    table = []
    for name, rs in groups(rows):
        for method in METHODS:
            ok = [r[method]["errors"] for r in rs if "errors" in r[method]]
            cells = [name, method, str(len(rs)), str(len(rs) - len(ok))]
            for key, _ in METRICS:
                v = np.array([e[key] for e in ok])
                cells.append(f"{np.median(v):.3g} / {np.percentile(v, 95):.3g}" if v.size
                             else "-")
            table.append(cells)
    return table


HEADER = ["group", "method", "scenarios", "refused",
          *(f"{k} {u} (median / p95)" for k, u in METRICS)]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", type=int, default=200, help="number of scenarios (200)")
    p.add_argument("--family", choices=("block", "engine", "gearbox"),
                   help="only this body shape")
    p.add_argument("--jobs", type=int, default=2, help="parallel processes (2)")
    p.add_argument("--seed", type=int, default=2026, help="suite seed (2026)")
    p.add_argument("--write-docs", action="store_true", help=f"write the table to {DOCS}")
    p.add_argument("--verbose", action="store_true", help="print each scenario's errors")
    p.add_argument("--json", type=Path, metavar="FILE",
                   help="also write every scenario's errors, bands and refusals here")
    p.add_argument("--coverage", action="store_true",
                   help="coverage of the 95 %% intervals instead of the accuracy table")
    args = p.parse_args(argv)
    specs = [s for s in suite(args.scenarios, args.seed)
             if args.family is None or s.family == args.family]
    if args.coverage:
        return main_coverage(specs, args)
    console = Console()
    t0 = time.perf_counter()
    rows: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for row in pool.map(evaluate, specs, chunksize=1):
            rows.append(row)
            if args.verbose:
                console.print(row["name"], {m: row[m].get("errors", row[m].get("refused"))
                                            for m in METHODS})
    elapsed = time.perf_counter() - t0
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))
    table = Table(title=f"Accuracy on {len(rows)} reference scenarios ({elapsed:.0f} s)")
    for h in HEADER:
        table.add_column(h, justify="left" if h in ("group", "method") else "right")
    body = summary(rows)
    for cells in body:
        table.add_row(*cells)
    console.print(table)
    worse = [r["name"] for r in rows if worse_than_article(r)]
    both = sum(1 for r in rows if "errors" in r["article"])
    console.print(f"default worse than the article's method in some metric (or refused where "
                  f"it answered): {len(worse)} of {both} scenarios the article answered")
    for key, med, p95 in ratios(rows):
        console.print(f"  {key}: default / article on the scenarios both answered: median "
                      f"{med:.2f}, p95 {p95:.2f}")
    for method in METHODS:
        for count, kind, _ in refusal_kinds(rows, method):
            console.print(f"  {method} refused {count}x: {kind}")
    if args.write_docs:
        write_docs(body, rows, worse, both, elapsed, args)
        console.print(f"written to {DOCS}")
    return 0


def write_docs(body: list[list[str]], rows: list[dict[str, Any]], worse: list[str], both: int,
               elapsed: float, args: argparse.Namespace) -> None:
    shown = [a for i, a in enumerate(sys.argv[1:])  # the --json file is a local path
             if a != "--json" and (i == 0 or sys.argv[i] != "--json")]
    cmd = "python benchmarks/accuracy.py " + " ".join(shown)
    lines = [
        "# Accuracy on the independent reference model",
        "",
        "Produced by `benchmarks/accuracy.py` (do not edit by hand). Scenarios: "
        "`hardware_mocks/reference/scenarios.py` (`suite`, seed "
        f"{args.seed}); truth, FRFs and errors are computed without any code from "
        "`processing/` (see `hardware_mocks/reference/`). Each scenario is written to a "
        "binary UFF file; `default` and `plain` are `insitu identify FILE.uff` "
        "(`--method plain`), `article` the article's method with its own band rule "
        "(`hardware_mocks/reference/article.py`, given the system's true highest rigid-body "
        "and first elastic frequencies).",
        "",
        "Scenarios: three body shapes (compact block, engine-like with overhangs and uneven "
        "mass, long gearbox-like), each a lattice of point masses and braced springs whose "
        "elastic modes lie inside and above the measured band, on 3-4 inclined mounts with "
        "their own loss factors; 3-6 triaxial sensors, 6-24 forces, noise 0-3 % of each "
        "record's RMS on force and responses (H1 over 10-20 averages), point-location errors "
        "0-3 mm, sensor misalignment 0-2 deg, first elastic mode 1.5-20x the highest "
        "rigid-body mode; one in three with sensor gain (+-2 %) and transverse sensitivity "
        "(3 %) errors (tag `sensors`); one in ten stiff and error-free (tag `rigid-clean`). "
        "The lattice's elastic modes move the measured points strongly: their residual "
        "below a mode at f_e is of order (f / f_e)^2 of the mass line, so a mass line close "
        "to the first elastic mode carries errors of several % without a leakage model.",
        "",
        "Errors: mass %; CoG distance, mm; worst inertia-tensor entry about O and about the "
        "CoG, % of the largest principal moment; worst K entry, % of sqrt(Kii Kjj). Each "
        "cell: median / 95th percentile over the scenarios the method answered.",
        "",
        f"- date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}",
        f"- machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, {platform.system()} {platform.release()}",
        f"- command: `{cmd}` ({elapsed:.0f} s)",
        "",
        "| " + " | ".join(HEADER) + " |",
        "| " + " | ".join("---" if i < 2 else "---:" for i in range(len(HEADER))) + " |",
        *("| " + " | ".join(c) + " |" for c in body),
        "",
        f"Scenarios where `default` is worse than the article's method in at least one "
        f"metric, or refuses where it answers: **{len(worse)}** of the {both} it answered.",
        "",
        "Ratios default / article on the scenarios both answered (group `all, article "
        "answered`):",
        "",
        "| metric | median ratio | p95 ratio |",
        "| --- | ---: | ---: |",
        *(f"| {k} | {m:.2f} | {q:.2f} |" for k, m, q in ratios(rows)),
        "",
    ]
    for method in METHODS:
        kinds = refusal_kinds(rows, method)
        if kinds:
            lines += [f"Refusals of `{method}` (count, message with its numbers as #, one "
                      "example):", "",
                      *(f"- {n}: `{k}` (e.g. `{ex}`)" for n, k, ex in kinds), ""]
    old = DOCS.read_text() if DOCS.exists() else ""
    # the sections after this one (coverage, time data: written by their own benchmarks)
    kept = old[old.index("\n## ") + 1:] if "\n## " in old else ""
    DOCS.write_text("\n".join(lines) + ("\n\n" + kept if kept else ""))


if __name__ == "__main__":
    sys.exit(main())
