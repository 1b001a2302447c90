"""Time and peak memory of a time UFF's way to an identification, against a plain reference.

Two generated tests of one reference scenario (``hardware_mocks/reference/timedata.py``: 12
excitation points, 4 triaxial sensors, 2048 Hz), written as binary UFF time records: a shaker
test (continuous random, 32 s a point) and a hammer test (2 hits a point). Each child process
is timed from its start to its exit, its peak resident memory read from ``os.wait4``:

- ``identify``: ``insitu identify FILE.uff`` with no option, end to end (start-up, imports,
  reading, FRFs, the fit with its bootstrap, the printed report);
- ``load``: the imports and ``app.pipeline.load(FILE)`` alone; the child also reports its
  resident memory after the imports (``base``), so ``load - base`` is what the reading and
  the FRFs cost;
- ``read``: the reading alone, as ``load`` reads a shaker file: the file indexed
  (``app.io.uff_time.read_time_file``), every run's force, then every run whole, one run at
  a time (the code before this change read every run at once in ``read_time_file``);
- ``reference``: pyuff reading the whole file (``pyuff.UFF(FILE).read_sets()``, every
  dataset in one list) and, per run, H1 from ``scipy.signal.welch`` and ``scipy.signal.csd``
  (2048-sample Hann segments, 50 % overlap), the way a short script would do it; for the
  hammer test this is a reference for reading and spectra, not for its per-hit processing;
- ``identify (compared)``, ``load (compared)``, ``read (compared)``: the same with another
  checkout's code (``--compare DIR``, e.g. the code before a change).

The kinds take turns (one of each per repeat) so that the machine's load falls on them alike;
the table gives medians over the repeats and the load average before and after.

    .venv/bin/python benchmarks/timeuff_read.py [--repeats 3] [--dir DIR] [--write]
        [--compare CHECKOUT --compare-label TEXT]

``--dir`` keeps the generated files (made once); ``--write`` writes
``benchmarks/results/timeuff-read.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results" / "timeuff-read.md"
KINDS = ("identify", "load", "read", "reference")

LOAD_CHILD = """
import json, sys, time
t0 = time.perf_counter()
from app.pipeline import Settings, load
def rss():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
base = rss()
m = load(sys.argv[1], Settings())
print(json.dumps({"base_mb": base, "lines": int(m.frf.freq.size)}))
"""

READ_CHILD = """
import json, sys
from app.io.uff_time import read_time_file
f = read_time_file(sys.argv[1])
if hasattr(f, "read_run"):  # one run at a time: the forces, then every run whole
    for lc in f.load_cases:
        f.read_run(lc, force_only=True)
    for lc in f.load_cases:
        f.read_run(lc)
    n = len(f.load_cases)
else:  # every run at once
    n = len(f.runs)
print(json.dumps({"runs": n}))
"""

REFERENCE_CHILD = """
import json, sys
import numpy as np, pyuff
from scipy.signal import csd, welch
sets = pyuff.UFF(sys.argv[1]).read_sets()
runs = {}
for ds in sets:
    if ds.get("type") == 58 and ds.get("func_type") == 1:
        runs.setdefault(ds["load_case_id"], []).append(ds)
H = []
for recs in runs.values():
    force = next(d["data"] for d in recs if d["ordinate_spec_data_type"] == 13)
    resp = np.array([d["data"] for d in recs if d["ordinate_spec_data_type"] == 12])
    fs = round(1.0 / recs[0]["abscissa_inc"])
    _, pff = welch(force, fs, nperseg=2048)
    _, pfx = csd(force[None], resp, fs, nperseg=2048)
    H.append(pfx / pff)
print(json.dumps({"runs": len(H)}))
"""


def make_files(folder: Path) -> dict[str, Path]:
    """The shaker and hammer test files (generated once into ``folder``)."""
    from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
    from hardware_mocks.reference.timedata import (
        HammerSpec,
        ShakerSpec,
        hammer_test,
        shaker_test,
        write_uff,
    )

    files = {"shaker": folder / "shaker_12x32s.uff", "hammer": folder / "hammer_12x2hits.uff"}
    if all(p.exists() for p in files.values()):
        return files
    sc = build_scenario(ScenarioSpec(seed=7001, shape="engine", n_sensors=4, n_forces=12,
                                     elastic_ratio=8.0, band_ratio=0.5))
    write_uff(shaker_test(sc, ShakerSpec(seed=1, kind="random", duration=32.0, fs=2048.0)),
              files["shaker"])
    write_uff(hammer_test(sc, HammerSpec(seed=1, hits=2, fs=2048.0, n_double=1,
                                         n_clipped=1)), files["hammer"])
    return files


def child(kind: str, path: Path, root: Path = ROOT) -> dict[str, float]:
    """Run one child process with the code of ``root``: wall time (s), peak RSS (MiB), and
    what it printed."""
    kind = kind.split()[0]
    if kind == "identify":
        cmd = [sys.executable, "-m", "app.cli.main", "identify", str(path)]
    else:
        code = {"load": LOAD_CHILD, "read": READ_CHILD, "reference": REFERENCE_CHILD}[kind]
        cmd = [sys.executable, "-c", code, str(path)]
    env = {**os.environ, "PYTHONPATH": str(root)}
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
                            cwd=root)
    assert proc.stdout is not None
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    row: dict[str, float] = {"seconds": seconds, "peak_mb": usage.ru_maxrss / 1024,  # MiB
                             "status": float(proc.returncode)}
    if kind != "identify" and proc.returncode == 0:
        row.update(json.loads(out.decode().strip().splitlines()[-1]))
    return row


def measure(files: dict[str, Path], repeats: int, kinds: list[str], compare: Path | None,
            ) -> dict[tuple[str, str], list[dict[str, float]]]:
    rows: dict[tuple[str, str], list[dict[str, float]]] = {}
    for rep in range(repeats):
        for test, path in files.items():
            order = kinds if rep % 2 == 0 else kinds[::-1]
            for kind in order:
                root = compare if kind.endswith("(compared)") and compare else ROOT
                row = child(kind, path, root)
                rows.setdefault((test, kind), []).append(row)
                print(f"{test} {kind}: {row['seconds']:.2f} s, peak {row['peak_mb']:.0f} MiB"
                      + (f", base {row['base_mb']:.0f} MiB" if "base_mb" in row else "")
                      + (f" (exit {row['status']:.0f})" if row["status"] else ""), flush=True)
    return rows


def table(files: dict[str, Path], rows: dict[tuple[str, str], list[dict[str, float]]],
          kinds: list[str]) -> list[str]:
    lines = ["| test | file | what | time (s) | peak RSS (MiB) | peak / file | "
             "load - base (MiB) | time / reference |",
             "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    for test, path in files.items():
        size = path.stat().st_size / 2**20
        ref = float(np.median([r["seconds"] for r in rows[(test, "reference")]]))
        for kind in kinds:
            rs = rows[(test, kind)]
            sec = float(np.median([r["seconds"] for r in rs]))
            peak = float(np.median([r["peak_mb"] for r in rs]))
            extra = (f"{np.median([r['peak_mb'] - r['base_mb'] for r in rs]):.0f}"
                     if kind.startswith("load") else "")
            lines.append(f"| {test} | {size:.1f} MiB | {kind} | {sec:.2f} | {peak:.0f} | "
                         f"{peak / size:.2f} | {extra} | {sec / ref:.2f} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--dir", type=Path, help="keep the generated files here")
    p.add_argument("--write", action="store_true", help=f"write {RESULTS.relative_to(ROOT)}")
    p.add_argument("--compare", type=Path,
                   help="another checkout of the project: its identify and load measured too")
    p.add_argument("--compare-label", default="another checkout",
                   help="what the compared checkout is, for the results file")
    a = p.parse_args(argv)
    kinds = list(KINDS) + (["identify (compared)", "load (compared)", "read (compared)"]
                           if a.compare else [])
    with tempfile.TemporaryDirectory() as tmp:
        folder = a.dir or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        files = make_files(folder)
        before = os.getloadavg()
        t0 = time.perf_counter()
        rows = measure(files, a.repeats, kinds, a.compare)
        after = os.getloadavg()
        lines = table(files, rows, kinds)
    print("\n".join(lines))
    if a.write:
        head = [
            "# Time UFF: reading to identification, time and peak memory",
            "",
            "Produced by `benchmarks/timeuff_read.py` (do not edit by hand); what each row "
            "measures is in its docstring. Medians over the repeats; the kinds took turns.",
            "",
            f"- date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}",
            f"- machine: {platform.machine()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}",
            f"- load average (1, 5, 15 min): before {before[0]:.1f}, {before[1]:.1f}, "
            f"{before[2]:.1f}; after {after[0]:.1f}, {after[1]:.1f}, {after[2]:.1f}",
            f"- command: `python benchmarks/timeuff_read.py --repeats {a.repeats}"
            + (" --compare CHECKOUT" if a.compare else "") + f"` ({time.perf_counter() - t0:.0f}"
            " s)" + (f"; \"(compared)\" rows: {a.compare_label}" if a.compare else ""),
            "",
        ]
        RESULTS.write_text("\n".join(head + lines) + "\n")
        print(f"written to {RESULTS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
