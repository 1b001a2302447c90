"""Mounts that stiffen with frequency: what they cost the identification.

Each scenario of the reference suite (``hardware_mocks/reference/scenarios.py``, ``suite``)
is measured twice: on its mounts as drawn (constant rates) and on the same mounts stiffening
by a rise per decade drawn from 10-40 % (``ScenarioSpec.stiffening``; the truth's K is the
stiffness at the geometric mean of the rigid-body modes, see docs/reference_model.md). Both
are identified by ``insitu identify FILE.uff`` with no option (in-process, as
``benchmarks/accuracy.py``) and by the article's method written independently
(``hardware_mocks/reference/article.py``). Errors as in docs/accuracy.md; each cell the
median / 95th percentile over the scenarios answered. Where the identification states K(f)
(``stiffening`` in its result), K is compared at the truth's frequency on stiffening mounts
(at its own stated frequency on constant ones, whose K holds at every frequency).

Two suites with fixed seeds: ``development`` (:data:`DEVELOPMENT_SEED`), the one to look at
while changing the method, and ``held-out`` (:data:`HELD_OUT_SEED`), published and never
used while tuning; the tests use seeds of their own.

Run: ``.venv/bin/python benchmarks/stiffening.py [--scenarios 40] [--suite held-out]
[--jobs 2] [--write-docs]``; ``--write-docs`` writes its section of docs/accuracy.md.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from dataclasses import replace  # noqa: E402
from datetime import UTC, datetime  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from accuracy import frfset_of, run_cli  # noqa: E402
from docs_page import write_section  # noqa: E402

from app.io.uff import write_frf_uff  # noqa: E402
from hardware_mocks.reference.article import ArticleRefusalError, identify_scenario  # noqa: E402
from hardware_mocks.reference.metrics import METRICS, errors  # noqa: E402
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario, suite  # noqa: E402

#: the suite to develop a stiffening model on
DEVELOPMENT_SEED = 4242
#: the published suite, never used while tuning
HELD_OUT_SEED = 5151
SUITES = {"development": DEVELOPMENT_SEED, "held-out": HELD_OUT_SEED}
#: rise of the mounts' stiffness per decade, drawn uniformly
RISE = (0.10, 0.40)
DOCS = Path(__file__).resolve().parent.parent / "docs" / "accuracy.md"
TITLE = "## Mounts that stiffen with frequency"


def specs(n: int, seed: int) -> list[ScenarioSpec]:
    """The suite's ``n`` scenarios with their stiffening mounts (the constant ones: the same
    with ``stiffening=0``)."""
    out = []
    for k, spec in enumerate(suite(n, seed)):
        rng = np.random.default_rng([seed, k, 28])
        out.append(replace(spec, stiffening=float(rng.uniform(*RISE))))
    return out


def _errors_default(spec: ScenarioSpec) -> dict[str, Any]:
    sc = build_scenario(spec)
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "frf.uff"
        write_frf_uff(path, frfset_of(sc), binary=True)
        code, res, msg = run_cli(["identify", str(path)])
    if res is None:
        out["default"] = {"refused": msg or f"exit status {code}"}
    else:
        K, st = np.asarray(res["stiffness"]), res.get("stiffening")
        if st is not None and sc.truth.stiffening:  # K(f) stated: at the truth's frequency
            K = K * (sc.truth.stiffness_hz / st["stiffness_at_hz"]) ** st["exponent"]
        out["default"] = {"errors": errors(sc.truth, res["mass"], res["cog"],
                                           res["inertia_origin"], res["inertia_cog"], K),
                          "rise": None if st is None else st["per_decade"]}
    try:
        a = identify_scenario(sc)
        out["article"] = {"errors": errors(sc.truth, a.mass, a.cog, a.inertia_origin,
                                           a.inertia_cog, a.K)}
    except ArticleRefusalError as err:
        out["article"] = {"refused": str(err)}
    return out


def evaluate(spec: ScenarioSpec) -> dict[str, Any]:
    """Both methods on the scenario with constant and with stiffening mounts."""
    return {"name": spec.name, "rise": spec.stiffening,
            "constant": _errors_default(replace(spec, stiffening=0.0)),
            "stiffening": _errors_default(spec)}


def _cell(values: list[float]) -> str:
    if not values:
        return "-"
    return f"{np.median(values):.2f} / {np.percentile(values, 95):.2f}"


def summary(rows: list[dict[str, Any]]) -> list[list[str]]:
    """Per method and mounts: answered, then median / p95 of each metric."""
    body = []
    for method in ("default", "article"):
        for mounts in ("constant", "stiffening"):
            got = [r[mounts][method]["errors"] for r in rows if "errors" in r[mounts][method]]
            body.append([method, mounts, f"{len(got)}/{len(rows)}",
                         *(_cell([g[m] for g in got]) for m, _ in METRICS)])
        both = [(r["constant"][method]["errors"], r["stiffening"][method]["errors"])
                for r in rows
                if "errors" in r["constant"][method] and "errors" in r["stiffening"][method]]
        ratio = []
        for m, _ in METRICS:  # median of the per-scenario ratios
            q = [b[m] / a[m] for a, b in both if a[m] > 0]
            ratio.append(f"{np.median(q):.2f}" if q else "-")
        body.append([method, "ratio (median)", f"{len(both)}", *ratio])
    return body


HEADER = ("method", "mounts", "answered", *(f"{m} {u}" for m, u in METRICS))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", type=int, default=40, help="scenarios per suite (40)")
    p.add_argument("--suite", choices=(*SUITES, "both"), default="both")
    p.add_argument("--jobs", type=int, default=2, help="parallel processes (2)")
    p.add_argument("--write-docs", action="store_true", help=f"write its section of {DOCS}")
    args = p.parse_args(argv)
    console = Console()
    names = list(SUITES) if args.suite == "both" else [args.suite]
    sections = []
    for name in names:
        t0 = time.perf_counter()
        with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            rows = list(pool.map(evaluate, specs(args.scenarios, SUITES[name]), chunksize=1))
        elapsed = time.perf_counter() - t0
        body = summary(rows)
        table = Table(title=f"{name} suite (seed {SUITES[name]}), {len(rows)} scenarios, "
                      f"{elapsed:.0f} s")
        for h in HEADER:
            table.add_column(h)
        for cells in body:
            table.add_row(*cells)
        console.print(table)
        sections += [f"### {name.capitalize()} suite (seed {SUITES[name]}, {len(rows)} "
                     f"scenarios, {elapsed:.0f} s)", "",
                     "| " + " | ".join(HEADER) + " |", "|" + " --- |" * len(HEADER),
                     *("| " + " | ".join(c) + " |" for c in body), ""]
    if args.write_docs:
        text = [
            TITLE, "",
            "Produced by `benchmarks/stiffening.py` (do not edit by hand). Each scenario of "
            "the reference suite is identified twice: on its mounts as drawn (constant "
            "rates) and on the same mounts stiffening by 10-40 % a decade "
            "(`docs/reference_model.md`: the truth's K holds at the geometric mean of the "
            "rigid-body modes). `default` is `insitu identify FILE.uff` with no option, "
            "`article` the article's method written independently. Each cell: median / 95th "
            "percentile over the scenarios answered; `ratio`: median over the scenarios of "
            "stiffening error / constant error. The identification fits a constant K: these "
            "numbers are what the stiffening costs it. The development suite is the one to "
            "look at while changing the method; the held-out suite is published and never "
            "tuned on.", "",
            f"- date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}",
            f"- machine: {platform.machine()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}",
            f"- command: `python benchmarks/stiffening.py {' '.join(sys.argv[1:])}`", "",
            *sections]
        write_section("benchmarks/stiffening.py", "\n".join(text), DOCS)
        console.print(f"written to {DOCS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
