"""Mounts that stiffen with frequency: what they cost the identification.

Each scenario of the reference suite (``hardware_mocks/reference/scenarios.py``, ``suite``)
is measured twice: on its mounts as drawn (constant rates) and on the same mounts stiffening
by a rise per decade drawn from 10-40 % (``ScenarioSpec.stiffening``; the truth's K is the
stiffness at the geometric mean of the rigid-body modes, see docs/reference_model.md). Each
is identified by ``insitu identify FILE.uff`` with no option (``auto``: the stiffening read
from the data), by ``insitu identify FILE.uff --stiffening constant`` (K constant, as
before the stiffening was read) (in-process, as ``benchmarks/accuracy.py``) and by the
article's method written independently (``hardware_mocks/reference/article.py``). Errors as
in docs/accuracy.md; each cell the median / 95th percentile over the scenarios answered;
then, paired on the same data, how often ``auto`` took a stiffening and, where it did, the
median ratio of its errors to the constant K's and how often they were smaller. Where the
identification states K(f) (``stiffening`` in its result), K is compared at the truth's
frequency on stiffening mounts (at its own stated frequency on constant ones, whose K holds
at every frequency).

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


#: the identifications compared: name, extra options of insitu identify
RUNS = (("auto", ()), ("constant", ("--stiffening", "constant")))


def _errors_default(spec: ScenarioSpec) -> dict[str, Any]:
    sc = build_scenario(spec)
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "frf.uff"
        write_frf_uff(path, frfset_of(sc), binary=True)
        for name, extra in RUNS:
            code, res, msg = run_cli(["identify", str(path), *extra])
            if res is None:
                out[name] = {"refused": msg or f"exit status {code}"}
                continue
            K, st = np.asarray(res["stiffness"]), res.get("stiffening")
            if st is not None and sc.truth.stiffening:  # K(f) stated: at the truth's frequency
                K = K * (sc.truth.stiffness_hz / st["stiffness_at_hz"]) ** st["exponent"]
            out[name] = {"errors": errors(sc.truth, res["mass"], res["cog"],
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
    """Per mounts and identification: answered, then median / p95 of each metric; then the
    paired comparison of auto with the constant K where auto took a stiffening."""
    body = []
    for mounts in ("constant", "stiffening"):
        for method in ("auto", "constant", "article"):
            got = [r[mounts][method]["errors"] for r in rows if "errors" in r[mounts][method]]
            body.append([mounts, method, f"{len(got)}/{len(rows)}",
                         *(_cell([g[m] for g in got]) for m, _ in METRICS)])
        taken = [(r[mounts]["constant"]["errors"], r[mounts]["auto"]["errors"]) for r in rows
                 if "errors" in r[mounts]["auto"] and "errors" in r[mounts]["constant"]
                 and r[mounts]["auto"]["rise"] is not None]
        cells = []
        for m, _ in METRICS:
            q = np.array([b[m] / a[m] for a, b in taken if a[m] > 0])
            cells.append(f"{np.median(q):.2f}, {np.mean(q < 1):.0%} smaller" if q.size else "-")
        body.append([mounts, "auto / constant where taken", f"{len(taken)} taken", *cells])
    return body


HEADER = ("mounts", "identification", "answered", *(f"{m} {u}" for m, u in METRICS))


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
            "the reference suite is measured twice: on its mounts as drawn (constant "
            "rates) and on the same mounts stiffening by 10-40 % a decade "
            "(`docs/reference_model.md`: the truth's K holds at the geometric mean of the "
            "rigid-body modes; a K stated with its stiffening is compared there). `auto` is "
            "`insitu identify FILE.uff` with no option (the stiffening read from the data, "
            "docs/mounts.md), `constant` the same with `--stiffening constant` (a constant K, "
            "as before), `article` the article's method written independently. Each cell: "
            "median / 95th percentile over the scenarios answered; the last row of each "
            "mounts, paired on the same data: how many scenarios `auto` took a stiffening on "
            "and, there, the median ratio of its error to the constant K's and how often it "
            "was smaller. The development suite is the one looked at while the rule was "
            "made; the held-out suite is published and was not tuned on.", "",
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
