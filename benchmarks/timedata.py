"""Time data to identification with default options, on generated hammer and shaker tests.

Each case is a reference-model scenario (``hardware_mocks/reference/scenarios.py``: lattice
body on inclined mounts, 9 excitation points, 4 triaxial sensors) measured as time records by
the generator (``hardware_mocks/reference/timedata.py``): hammer tests (5 hits a point,
2.5-5 s apart +-20 %, one double hit and one clipped hit per test, mount damping x0.2-x3,
noise, offsets, drift, IEPE settling) and shaker tests (continuous random, burst random or
periodic chirp, 40 s a point, armature 1-4 kg: force drop-outs at resonances). Each is
written as a binary UFF file and identified as a user would: ``insitu identify FILE.uff``
with no option (``app.cli.main.main`` in-process; a non-zero exit status is a refusal, its
last stderr line the reason). The same scenario's exact FRFs, on the same lines, identified
the same way, give the errors the time-data processing is compared with; "bands" is the time
data identified in the bands chosen on the exact FRFs with ``--coherence 0`` (what the FRFs
from time data are worth when the band choice and the coherence gate are set aside).

Figures: refusals (with their messages), hits rejected (true: double or clipped; false: good
hits), excitation type detected, and the errors of ``hardware_mocks/reference/metrics.py``
(mass %, CoG mm, inertia % of the largest principal moment), median and 95th percentile.

With ``--write-docs`` the table goes into its own section of docs/accuracy.md (the sections
``benchmarks/accuracy.py`` writes are kept as they are).

``--budget development`` or ``--budget held-out``: the cases carry a real test's whole error
budget instead (:func:`budget_case`: noise 0.2-3 % of each channel's RMS on force and
responses, sensor gain +-2 %, misalignment up to 2 deg, transverse sensitivity 3 %, location
errors 2-3 mm, 1-5 hits a point, mount damping x0.2-x3, half the cases on mounts stiffening
10-40 % a decade, channel skew within a sample, mains hum, a 24-bit converter over fixed
ranges with 2-100x headroom, one or two channels of up to two runs clipped for 1-5 samples),
from the suite's fixed seed (:data:`BUDGET_SEEDS`): the development suite is the one to
look at while changing the method, the held-out one is published and never tuned on; the
tests use seeds of their own. Each suite writes its own section.

Run: ``.venv/bin/python benchmarks/timedata.py [--hammer 50] [--shaker 50] [--jobs 2]
[--budget SUITE] [--json FILE] [--write-docs]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import dataclasses  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import UTC, datetime  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # imported as benchmarks.timedata too
from accuracy import stated_for  # noqa: E402  (benchmarks/, the script's folder)

from app.cli.main import main as insitu_main  # noqa: E402
from app.io.uff import write_frf_uff  # noqa: E402
from app.pipeline import Settings, load  # noqa: E402
from hardware_mocks.reference.article import ArticleRefusalError  # noqa: E402
from hardware_mocks.reference.metrics import errors  # noqa: E402
from hardware_mocks.reference.plain import plain_identify  # noqa: E402
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario  # noqa: E402
from hardware_mocks.reference.timedata import (  # noqa: E402
    Budget,
    HammerSpec,
    ShakerSpec,
    TimeTest,
    hammer_test,
    shaker_test,
    write_uff,
)

FIGURES = ("mass", "cog", "inertia")
#: the table's figures: key, heading
TABLE = (("mass", "mass %"), ("cog", "CoG mm"), ("inertia", "inertia %"), ("stiffness", "K %"))
#: what each identification is, in the table
SOURCES = (("time", "time data, default options"), ("exact", "exact FRFs, same lines"),
           ("bands", "time data in the exact FRFs' bands"),
           ("nodelay", "time data, --channel-delays off (budget suites)"),
           ("plain", "plain baseline: H1 as a script does it, the article's method and band "
                     "rule (budget suites)"))
DOCS = Path(__file__).resolve().parent.parent / "docs" / "accuracy.md"
TITLE = "## Time data: hammer and shaker tests"


def case(i: int, kind: str, tip: float = 1.0) -> TimeTest:
    """Generated test ``i`` of ``kind`` ("hammer" or "shaker"), deterministic in ``i``; a
    hammer test's pulses ``tip`` times as wide as the band calls for."""
    rng = np.random.default_rng([2026, i, kind == "hammer"])
    spec = ScenarioSpec(seed=7000 + i + (500 if kind == "shaker" else 0),
                        shape=("block", "engine", "gearbox")[i % 3], n_sensors=4, n_forces=9,
                        elastic_ratio=float(rng.uniform(4.0, 12.0)),
                        band_ratio=float(rng.uniform(0.3, 0.8)),
                        damping="viscous" if rng.uniform() < 1 / 3 else "hysteretic")
    sc = build_scenario(spec)
    damping = float(np.exp(rng.uniform(np.log(0.2), np.log(3.0))))
    if kind == "hammer":
        return hammer_test(sc, HammerSpec(seed=i, spacing=float(rng.uniform(2.5, 5.0)),
                                          n_double=1, n_clipped=1, damping=damping, tip=tip,
                                          noise_force=float(rng.uniform(2e-4, 2e-3)),
                                          noise_response=float(rng.uniform(1e-4, 1e-3))))
    drive = ("random", "burst", "chirp")[i % 3]
    return shaker_test(sc, ShakerSpec(seed=i, kind=drive, damping=damping,  # type: ignore[arg-type]
                                      armature=float(rng.uniform(1.0, 4.0)),
                                      noise_force=float(rng.uniform(2e-4, 2e-3)),
                                      noise_response=float(rng.uniform(1e-4, 1e-3))))


#: the budget suites' seeds: development (look at it while changing the method) and held-out
#: (published, never tuned on)
BUDGET_SEEDS = {"development": 6060, "held-out": 6161}
BUDGET_TITLE = "## Time data with a real test's error budget"


def budget_case(i: int, kind: str, suite: str) -> TimeTest:
    """Test ``i`` of ``kind`` of the budget suite ``suite`` (module notes), deterministic."""
    seed = BUDGET_SEEDS[suite]
    rng = np.random.default_rng([seed, i, kind == "hammer"])
    spec = ScenarioSpec(seed=seed * 1000 + i + (500 if kind == "shaker" else 0),
                        shape=("block", "engine", "gearbox")[i % 3], n_sensors=4, n_forces=9,
                        elastic_ratio=float(rng.uniform(4.0, 12.0)),
                        band_ratio=float(rng.uniform(0.3, 0.8)),
                        damping="viscous" if rng.uniform() < 1 / 3 else "hysteretic",
                        location_error=float(rng.uniform(0.002, 0.003)),
                        misalignment_deg=float(rng.uniform(0.0, 2.0)), gain_error=0.02,
                        transverse=0.03,
                        stiffening=float(rng.uniform(0.1, 0.4)) if i % 2 else 0.0)
    sc = build_scenario(spec)
    damping = float(np.exp(rng.uniform(np.log(0.2), np.log(3.0))))
    budget = Budget(rms_noise=float(np.exp(rng.uniform(np.log(0.002), np.log(0.03)))),
                    skew=1.0, hum=float(rng.uniform(0.002, 0.02)),
                    mains_hz=float(rng.choice([50.0, 60.0])), bits=24, headroom=(2.0, 100.0),
                    clip_channels=int(rng.integers(0, 3)), clip_samples=(1, 5))
    if kind == "hammer":
        return hammer_test(sc, HammerSpec(seed=seed + i, hits=int(rng.integers(1, 6)),
                                          spacing=float(rng.uniform(2.5, 5.0)),
                                          n_double=int(rng.integers(0, 2)), damping=damping,
                                          noise_force=1e-4, noise_response=1e-4,
                                          budget=budget))
    drive = ("random", "burst", "chirp")[i % 3]
    return shaker_test(sc, ShakerSpec(seed=seed + i, kind=drive, damping=damping,  # type: ignore[arg-type]
                                      armature=float(rng.uniform(1.0, 4.0)),
                                      noise_force=1e-4, noise_response=1e-4, budget=budget))


def identify_cli(path: Path, *extra: str) -> tuple[dict[str, Any] | None, str, str]:
    """``insitu identify PATH EXTRA --out JSON`` in-process: result (None if refused; a
    result written with exit status 2, runs left out, counts), the refusal's last stderr
    line, stdout."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r.json"
        o, e = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
            code = insitu_main(["identify", str(path), *extra, "--out", str(out)])
        # exit status 2 with a result: runs were left out (the result holds the others)
        res = json.loads(out.read_text()) if code in (0, 2) and out.exists() else None
    lines = e.getvalue().strip().splitlines()
    return res, (lines[-1] if lines else f"exit status {code}") if res is None else "", o.getvalue()


def _errs(t: TimeTest, res: dict[str, Any]) -> dict[str, float]:
    """The errors of a result; K at the truth's frequency when both stiffen with frequency
    (on constant mounts K holds at every frequency: compared as stated)."""
    K, st = np.asarray(res["stiffness"]), res.get("stiffening")
    if st is not None and t.truth.stiffening:
        K = K * (t.truth.stiffness_hz / st["stiffness_at_hz"]) ** st["exponent"]
    return errors(t.truth, res["mass"], res["cog"], res["inertia_origin"], res["inertia_cog"], K)


#: the stated uncertainty's groups: result key, the truth's value, entries compared
_GROUPS = (("mass", "mass", lambda a: np.atleast_1d(a)), ("cog", "cog", np.ravel),
           ("inertia", "inertia_cog", lambda a: np.asarray(a)[np.triu_indices(3)]))


def _z(t: TimeTest, res: dict[str, Any]) -> dict[str, list[float]] | None:
    """|error| / stated std of each entry of each group (mass, CoG, inertia about the CoG),
    or None when the result states no std."""
    std = res.get("std")
    if not std:
        return None
    out = {}
    for name, key, pick in _GROUPS:
        err = np.abs(pick(np.asarray(res[key], float)) - pick(np.asarray(getattr(t.truth, key),
                                                                          float)))
        s = pick(np.asarray(std[key], float))
        out[name] = [float(e / v) if v > 0 else float("inf") for e, v in zip(err, s, strict=True)]
    return out


def stated_flags(spec: ScenarioSpec) -> list[str]:
    """``insitu identify``'s options stating a scenario's test uncertainties as a user who
    knows their error levels would (``benchmarks/accuracy.py``'s ``stated_for``: location,
    misalignment with transverse sensitivity, gain, as standard deviations)."""
    st = stated_for(spec)
    return ["--location-uncertainty", f"{st.location * 1e3:.6g}mm",
            "--angle-uncertainty", f"{np.rad2deg(st.angle):.6g}deg",
            "--gain-uncertainty", f"{st.gain * 100:.6g}%"]


def coverage_line(rows: list[dict[str, Any]], key: str = "time") -> str:
    """Coverage of the stated 95 % intervals (|error| <= 1.96 std) over the answered cases'
    entries, and the median |error| / std, per group, of the result ``key``: the default
    (``time``) or the default with the scenario's test uncertainties stated (``stated``)."""
    parts = []
    for name, _, _ in _GROUPS:
        z = np.concatenate([r[key]["z"][name] for r in rows
                            if key in r and r[key].get("z") is not None] or [np.zeros(0)])
        if z.size:
            parts.append(f"{name} {np.mean(z <= 1.96):.0%} covered, median |error|/std "
                         f"{np.median(z):.2f} ({z.size} entries)")
    what = ("the time data's default result" if key == "time" else
            "the same with the test uncertainties stated (--location-uncertainty, "
            "--angle-uncertainty, --gain-uncertainty: the scenario's error levels as standard "
            "deviations; the estimates are the default's)")
    return (f"stated 95 % intervals of {what}: " + "; ".join(parts)
            if parts else f"no stated uncertainty ({key})")


def _hit_counts(t: TimeTest, out: str) -> dict[str, int]:
    """Rejected hits from the pipeline's lines ``load case N (node ..): k hits accepted,
    rejected: hit i: ...``, matched to the generator's labels by order."""
    rejected: dict[int, set[int]] = {}
    without: set[int] = set()  # runs kept without the responses every hit overloads
    for m in re.finditer(r"load case (\d+) \(node \d+\): \d+ hits accepted(.*)", out):
        rejected[int(m.group(1))] = {int(h) - 1 for h in re.findall(r"hit (\d+):", m.group(2))}
        if m.group(2).startswith(" without "):
            without.add(int(m.group(1)))
    c = Counter[str]()
    for r in t.runs:
        rej = rejected.get(r.load_case)
        if rej is None:  # the whole run left out
            c["run left out"] += 1
            continue
        for k, h in enumerate(r.hits):
            what = "double" if h.double else "clipped" if h.clipped else "good"
            verdict = ("rejected" if k in rej else "kept without its clipped channel"
                       if r.load_case in without else "accepted")
            c[f"{what} {verdict}"] += 1
    return dict(c)


def evaluate(i: int, kind: str, budget: str | None = None) -> dict[str, Any]:
    """Case ``i`` of ``kind`` (of the budget suite ``budget`` when given), identified from
    its time data, from its exact FRFs and from its time data in the exact FRFs' bands."""
    t0 = time.perf_counter()
    t = case(i, kind) if budget is None else budget_case(i, kind, budget)
    row: dict[str, Any] = {"case": i, "kind": kind, "drive": t.kind,
                           "damping": t.settings["damping"]}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "time.uff"
        write_uff(t, path)
        res, why, out = identify_cli(path)
        m = re.search(r"^excitation (\w+) ", out, re.M)
        row["detected"] = m.group(1) if m else "?"
        row["defaults"] = [ln for ln in out.splitlines()
                           if ln.startswith(("excitation ", "record ", "trigger level",
                                             "shaker force", "earlier ", "record tails"))]
        row["time"] = ({"refused": why} if res is None else
                       {"errors": _errs(t, res), "z": _z(t, res)})
        if kind == "hammer":
            row["hits"] = _hit_counts(t, out)
        if budget is not None and res is not None:  # the test uncertainties stated
            res5, why5, _ = identify_cli(path, *stated_flags(t.scenario.spec))
            row["stated"] = ({"refused": why5} if res5 is None else
                             {"errors": _errs(t, res5), "z": _z(t, res5),
                              "same estimates": res5["theta"] == res["theta"]})
        if budget is not None:  # the channels' skew left in: what taking it out buys
            res4, why4, _ = identify_cli(path, "--channel-delays", "off")
            row["nodelay"] = ({"refused": why4} if res4 is None
                              else {"errors": _errs(t, res4), "z": _z(t, res4)})
            try:  # the plain baseline on the same samples (hardware_mocks/reference/plain.py)
                a = plain_identify(t)
                row["plain"] = {"errors": errors(t.truth, a.mass, a.cog, a.inertia_origin,
                                                 a.inertia_cog, a.K)}
            except ArticleRefusalError as err:
                row["plain"] = {"refused": str(err)}
        # the exact FRFs on the lines the time data gave, identified the same way
        try:
            frf = load(path, Settings()).frf
            fc = t.scenario.forces  # the columns the time data kept (a run may be left out)
            cols = [int(np.flatnonzero((fc.ids == n) & np.all(np.isclose(fc.reported_dirs, d),
                                                               axis=1))[0])
                    for n, d in zip(frf.exc_nodes, frf.exc_dirs, strict=True)]
            # no window's tau: it lives in the measurement's provenance, not written
            exact = dataclasses.replace(frf, H=t.exact_frf(frf.freq)[:, cols],
                                        coherence=np.ones(frf.H.shape))
            epath = Path(tmp) / "exact.uff"
            write_frf_uff(epath, exact, binary=True, coherence=True)
            res2, why2, _ = identify_cli(epath)
            row["exact"] = {"refused": why2} if res2 is None else {"errors": _errs(t, res2)}
            if res2 is not None:  # the time data's FRFs in the bands chosen on the exact ones
                mb, sb = res2["bands"]["mass_line"], res2["bands"]["stiffness"]
                res3, why3, _ = identify_cli(path, "--mass-band", *map(str, mb),
                                             "--stiffness-band", *map(str, sb),
                                             "--coherence", "0")
                row["bands"] = ({"refused": why3} if res3 is None
                                else {"errors": _errs(t, res3)})
        except Exception as err:  # reported, not hidden
            row["exact"] = {"refused": f"{type(err).__name__}: {err}"}
    row["seconds"] = time.perf_counter() - t0
    return row


def _stats(rows: list[dict[str, Any]], key: str) -> str:
    ok = [r[key]["errors"] for r in rows if "errors" in r[key]]
    if not ok:
        return "no answer"
    out = []
    for f in FIGURES:
        v = [e[f] for e in ok]
        out.append(f"{f} {np.median(v):.3g}/{np.percentile(v, 95):.3g}"
                   f"{' mm' if f == 'cog' else ' %'}")
    return ", ".join(out)


def report(rows: list[dict[str, Any]]) -> str:
    lines = []
    for kind in ("hammer", "shaker"):
        rs = [r for r in rows if r["kind"] == kind]
        if not rs:
            continue
        det = Counter(r["detected"] for r in rs)
        lines.append(f"{kind}: {len(rs)} tests; excitation detected {dict(det)}")
        if kind == "hammer":
            hits = Counter[str]()
            for r in rs:
                hits.update(r["hits"])
            lines.append(f"  hits: {dict(hits)}")
        for key, _ in SOURCES:
            have = [r for r in rs if key in r]
            if not have:
                continue
            refused = [r[key]["refused"] for r in have if "refused" in r[key]]
            lines.append(f"  {key:5s}: answered {len(have) - len(refused)}/{len(have)}; "
                         f"median/p95 {_stats(have, key)}")
            for msg, n in Counter(re.sub(r"[-\d.]+", "#", m)[:160] for m in refused).items():
                lines.append(f"    refused x{n}: {msg}")
    return "\n".join(lines)


def _cell(rows: list[dict[str, Any]], key: str, fig: str) -> tuple[float, float] | None:
    v = [r[key]["errors"][fig] for r in rows if key in r and "errors" in r[key]]
    return (float(np.median(v)), float(np.percentile(v, 95))) if v else None


def _fmt(x: tuple[float, float] | None) -> str:
    return "-" if x is None else f"{x[0]:.3g} / {x[1]:.3g}"


def table(rows: list[dict[str, Any]]) -> list[list[str]]:
    """Per kind: one row per source (cases, refusals, median / p95 of each figure) and the
    ratio time data / exact FRFs of the medians and of the 95th percentiles."""
    body = []
    for kind in ("hammer", "shaker"):
        rs = [r for r in rows if r["kind"] == kind]
        if not rs:
            continue
        for key, name in SOURCES:
            have = [r for r in rs if key in r]
            if not have:
                continue
            refused = sum("refused" in r[key] for r in have)
            body.append([kind, name, str(len(have)), str(refused),
                         *(_fmt(_cell(rs, key, f)) for f, _ in TABLE)])
        body.append([kind, "ratio time data / exact FRFs", "", "", *_ratios(rs, "exact")])
        if any("plain" in r for r in rs):
            body.append([kind, "ratio time data / plain baseline", "", "",
                         *_ratios(rs, "plain")])
    return body


def _ratios(rows: list[dict[str, Any]], key: str) -> list[str]:
    """Per figure: the time data's median and 95th percentile over those of ``key``."""
    out = []
    for f, _ in TABLE:
        t, b = _cell(rows, "time", f), _cell(rows, key, f)
        out.append("-" if t is None or b is None else
                   f"{t[0] / max(b[0], 1e-300):.2f} / {t[1] / max(b[1], 1e-300):.2f}")
    return out


HEADER = ["test", "FRFs", "cases", "refused", *(f"{h} (median / p95)" for _, h in TABLE)]


def hits_line(rows: list[dict[str, Any]]) -> str:
    """The hammer hits' verdicts against the generator's labels."""
    c = Counter[str]()
    for r in rows:
        c.update(r.get("hits", {}))
    keep = "kept without its clipped channel"

    def of(what: str) -> str:
        n = c[f"{what} rejected"] + c[f"{what} accepted"] + c[f"{what} {keep}"]
        return f"{c[f'{what} rejected']} of {n}"
    return (f"hammer hits rejected: double hits {of('double')}, clipped hits {of('clipped')} "
            f"({c[f'clipped {keep}']} more kept without the clipped channel, the point's only "
            f"hits), good hits {of('good')} ({c[f'good {keep}']} kept without a channel); runs "
            f"left out: {c['run left out']}")


def write_docs(rows: list[dict[str, Any]], elapsed: float, argv: list[str],
               budget: str | None = None) -> None:
    """Replace (or append) this benchmark's section of docs/accuracy.md (the budget suite's
    own section with ``budget``)."""
    shown = [a for i, a in enumerate(argv) if a != "--json" and (i == 0 or argv[i - 1] != "--json")]
    detected = {kind: dict(Counter(r["detected"] for r in rows if r["kind"] == kind))
                for kind in ("hammer", "shaker")}
    drives = Counter((r["drive"], next((ln.split(" (")[0] for ln in r["defaults"]
                                        if ln.startswith("shaker force")), "?"))
                     for r in rows if r["kind"] == "shaker")
    title = TITLE if budget is None else f"{BUDGET_TITLE}: {budget} suite"
    intro = ("" if budget is None else
             f"The {budget} suite (seed {BUDGET_SEEDS[budget]}): every case carries a real "
             "test's whole error budget, on top of the defects below: noise 0.2-3 % of each "
             "channel's RMS on force and responses, sensor gain +-2 %, misalignment up to 2 "
             "deg, transverse sensitivity 3 %, location errors 2-3 mm, 1-5 hits a point (0 or "
             "1 double hit a test, no clipped hit drawn as such), half the cases on mounts "
             "stiffening 10-40 % a decade (K compared at the truth's frequency), channel skew "
             "within a sample, mains hum 0.2-2 % of the RMS, a 24-bit converter over fixed "
             "ranges with 2-100x headroom, one or two channels of up to two runs clipped for "
             "1-5 samples (the hits reaching a range count as clipped). "
             + ("Published and never tuned on." if budget == "held-out" else
                "The suite to look at while changing the method.") + " ")
    lines = [
        title, "",
        intro + "Produced by `benchmarks/timedata.py` (do not edit by hand). Each case is a "
        "reference-model scenario measured as time records by "
        "`hardware_mocks/reference/timedata.py` (no code from `processing/`): hammer tests "
        "(5 hits a point, 2.5-5 s apart +-20 %, one double hit and one clipped hit per test, "
        "mount damping x0.2-x3, noise on force and responses, DC offset and drift, IEPE "
        "settling) and shaker tests (continuous random, burst random, periodic chirp; 40 s a "
        "point; armature 1-4 kg: force drop-outs at resonances). `time data` is `insitu "
        "identify FILE.uff` with no option (every time-data setting read from the data); "
        "`exact FRFs` the same scenario's exact accelerances on the same lines, identified "
        "the same way; `time data in the exact FRFs' bands` the time data with the bands "
        "the exact FRFs chose and `--coherence 0`. Errors as in the table above; each cell "
        "median / 95th percentile over the cases answered; the ratio row divides the time "
        "data's median and 95th percentile by the exact FRFs'.",
        "",
        f"- date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}",
        f"- machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}",
        f"- command: `python benchmarks/timedata.py {' '.join(shown)}` ({elapsed:.0f} s)",
        f"- excitation read from the data: hammer tests {detected['hammer']}, shaker tests "
        f"{detected['shaker']}",
        "- shaker records read from the force: " + "; ".join(
            f"{d}: '{how}' x{n}" for (d, how), n in sorted(drives.items())),
        f"- {hits_line(rows)}",
        f"- {coverage_line(rows)}",
        *([f"- {coverage_line(rows, 'stated')}"] if budget is not None else []),
        "",
        "| " + " | ".join(HEADER) + " |",
        "| " + " | ".join("---" if i < 2 else "---:" for i in range(len(HEADER))) + " |",
        *("| " + " | ".join(c) + " |" for c in table(rows)),
        "",
    ]
    refusals = Counter(f"{r['kind']} ({key}): " + re.sub(r"[-\d.]+", "#", r[key]["refused"])[:160]
                       for r in rows for key, _ in SOURCES if key in r and "refused" in r[key])
    if refusals:
        lines += ["Refusals (count, message with its numbers as #):", "",
                  *(f"- {n}: `{m}`" for m, n in refusals.most_common()), ""]
    old = DOCS.read_text() if DOCS.exists() else ""
    if title in old:
        head, rest = old.split(title, 1)
        tail = rest[rest.index("\n## ") + 1:] if "\n## " in rest else ""
    else:
        head, tail = old.rstrip("\n") + "\n\n\n", ""
    DOCS.write_text(head + "\n".join(lines) + ("\n\n" + tail if tail else ""))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hammer", type=int, default=50)
    p.add_argument("--shaker", type=int, default=50)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--json", type=Path)
    p.add_argument("--budget", choices=tuple(BUDGET_SEEDS),
                   help="the cases of this error-budget suite")
    p.add_argument("--write-docs", action="store_true",
                   help=f"write the table into its section of {DOCS.name}")
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    todo = ([(i, "hammer", a.budget) for i in range(a.hammer)]
            + [(i, "shaker", a.budget) for i in range(a.shaker)])
    rows: list[dict[str, Any]] = []
    with ProcessPoolExecutor(a.jobs) as pool:
        for row in pool.map(evaluate, *zip(*todo, strict=True)):
            rows.append(row)
            print(f"{row['kind']} {row['case']}: {row['drive']}, detected {row['detected']}, "
                  f"time {row['time']}, exact {row['exact']}, {row.get('hits', '')} "
                  f"({row['seconds']:.0f} s)", flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1, default=float))
    print(report(rows))
    print(hits_line(rows))
    print(coverage_line(rows))
    print(coverage_line(rows, "stated"))
    print("| " + " | ".join(HEADER) + " |")
    for cells in table(rows):
        print("| " + " | ".join(cells) + " |")
    if a.write_docs:
        write_docs(rows, time.perf_counter() - t0, sys.argv[1:] if argv is None else argv,
                   a.budget)
        print(f"written to {DOCS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
