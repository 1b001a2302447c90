"""Clipped hits found as a digitiser would flag them, on the independent reference model.

For each scenario (``hardware_mocks/reference/``, no code from ``processing/``): a hammer
test of 9 points x 5 hits, whose third run has its two most vertical accelerometer channels
clipped at one level each, 1.5 % under the weakest hit's peak on that channel (every hit
clipped for a few samples, often one or two: no flat top of three samples to see in one
hit), written as a time UFF and read by ``app.pipeline.load`` with no option. Counted: the
clipped run's hits rejected, with the channel named, and the good hits (the other runs)
rejected. ``--against CHECKOUT`` runs the same with another checkout's
``processing/impact.py`` (the code before a change) in a child process.

    .venv/bin/python benchmarks/clipping.py [--scenarios 20] [--seed 8100] [--write]

``--write`` writes ``benchmarks/results/clipping.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
if "--child" not in sys.argv:  # a child of --against imports the other checkout's code
    sys.path.insert(0, str(ROOT))

CLIPPED_RUN = 2  # the third run
LEVEL = 0.985  # of the weakest hit's peak on the channel


def _clipped_test(seed: int):  # a reference-model TimeTest
    from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
    from hardware_mocks.reference.timedata import HammerSpec, hammer_test

    sc = build_scenario(ScenarioSpec(seed=seed, n_forces=9))
    test = hammer_test(sc, HammerSpec(seed, hits=5, jitter=0.05))
    run = test.runs[CLIPPED_RUN]
    resp = run.responses.copy()
    spacing = float(np.min(np.diff([h.time for h in run.hits])))
    spans = [(int(h.time * test.fs), int((h.time + spacing) * test.fs)) for h in run.hits]
    for c in np.argsort(-np.abs(sc.sensors.vectors[:, 2]))[:2]:
        level = LEVEL * min(float(np.abs(resp[c, a:b]).max()) for a, b in spans)
        resp[c] = np.clip(resp[c], -level, level)
    runs = list(test.runs)
    runs[CLIPPED_RUN] = dataclasses.replace(run, responses=resp)
    return dataclasses.replace(test, runs=tuple(runs))


def count(seeds: list[int]) -> dict[str, int]:
    """Hits of the clipped runs rejected for an overload, and good hits rejected."""
    from app.pipeline import load
    from hardware_mocks.reference.timedata import write_uff

    out = {"clipped": 0, "clipped_rejected": 0, "good": 0, "good_rejected": 0}
    for seed in seeds:
        test = _clipped_test(seed)
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "test.uff"
            write_uff(test, path)
            reports = [r.message for r in load(path).provenance.reports]
        for k, run in enumerate(test.runs):
            line = next(r for r in reports if r.startswith(f"load case {k + 1}"))
            n = len(run.hits)
            bad = line.count("overload on")
            if k == CLIPPED_RUN:
                out["clipped"] += n
                out["clipped_rejected"] += bad
            else:
                accepted = re.search(r"(\d+) hits? accepted", line)
                out["good"] += n
                out["good_rejected"] += n - (int(accepted.group(1)) if accepted else 0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", type=int, default=20)
    ap.add_argument("--seed", type=int, default=8100)
    ap.add_argument("--against", type=Path, help="another checkout: its processing/impact.py")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    seeds = list(range(args.seed, args.seed + args.scenarios))
    if args.child:
        print(json.dumps(count(seeds)))
        return
    rows = [("this checkout", count(seeds))]
    if args.against is not None:
        env = {**os.environ, "PYTHONPATH": f"{args.against}{os.pathsep}{ROOT}"}
        child = subprocess.run([sys.executable, __file__, "--child", "--scenarios",
                                str(args.scenarios), "--seed", str(args.seed)],
                               capture_output=True, text=True, env=env, check=True,
                               cwd=args.against)
        rows.append((f"against {args.against}", json.loads(child.stdout.splitlines()[-1])))
    table = Table(title=f"clipped hits, {args.scenarios} scenarios from seed {args.seed}")
    for col in ("code", "clipped hits rejected", "good hits rejected"):
        table.add_column(col)
    for name, c in rows:
        table.add_row(name, f"{c['clipped_rejected']} of {c['clipped']}",
                      f"{c['good_rejected']} of {c['good']}")
    Console().print(table)
    if args.write:
        stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
        lines = ["# Clipped hits (`benchmarks/clipping.py`)", "",
                 f"- date: {stamp}", f"- command: `benchmarks/clipping.py --scenarios "
                 f"{args.scenarios} --seed {args.seed}"
                 + (" --against CHECKOUT`" if args.against else "`"), "",
                 "| code | clipped hits rejected | good hits rejected |", "| --- | --- | --- |"]
        lines += [f"| {name.replace(str(args.against), 'the code before')} | "
                  f"{c['clipped_rejected']} of {c['clipped']} | "
                  f"{c['good_rejected']} of {c['good']} |" for name, c in rows]
        (ROOT / "benchmarks" / "results" / "clipping.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
