"""Soak test: a long acquisition on the mock bench process, with faults injected at random.

    .venv/bin/python benchmarks/soak.py [--minutes 60] [--seed 1] [--json out.json]
                                        [--hits N] [--fault-every LOW HIGH]
                                        [--first-fault FAULT] [--write-docs]

The mock bench (``insitu mock-bench``) runs in its own process; ``insitu acquire
--mock-operator`` acquires one long hammer run from it (the mock-bench plan with short
records and many hits per point: an accelerated test). ``--hits N`` gives each point N
hits instead: the soak then ends when the run is complete, or after ``--minutes`` at the
latest (``tests/app/test_soak.py``: one hit at each of the 9 points, a fault every 2 to 5 s,
the first one the bench killed).
At random moments (every ``--fault-every`` 5 to 25 s by default) this script:

- sets a fault of the bench's devices for a while through its control channel: front-end
  frames dropped or truncated, hammer frames corrupted or dropped, line noise;
- unplugs a device (it goes silent for a few seconds, then answers again);
- kills the bench process (``SIGKILL``) and starts a new one;
- stalls the acquiring process (``SIGSTOP`` for up to 2 s, then ``SIGCONT``).

A run that pauses (a device stopped answering) is stopped by ``acquire --mock-operator``
with its records kept; the script then resumes it (``--resume``, the bench restarted if it
was killed), as an operator would. It reports the records and accepted hits before and
after every resume (an accepted hit lost is a failure), frames lost, every pause and
resume, and the resident memory of the acquiring processes: its growth within a segment
from 10 s after the first record the segment stores (start-up and warm-up over), its
peak, and the growth over the run (the highest peak above the first segment's first
minute).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "docs" / "mock_bench_plan.toml"
BENCH = "engine-rigid"
INSITU = [sys.executable, "-m", "app.cli.main"]
#: seconds after a segment's first stored record from which its memory growth is counted
WARM = 10.0


@dataclass
class Report:
    minutes: float
    seed: int
    segments: int = 0
    records: int = 0
    accepted: int = 0
    accepted_lost: int = 0
    samples_lost: int = 0
    bad_frames: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    pauses: list[str] = field(default_factory=list)
    bench_restarts: int = 0
    rss_mb_first_minute: list[float] = field(default_factory=list)
    rss_mb_peak: list[float] = field(default_factory=list)
    rss_mb_acquiring: list[float] = field(default_factory=list)
    rss_growth_mb: float = 0.0
    #: the segment of the largest growth: (s from its start, MB) samples, its first record's s
    rss_growth_trace: list[tuple[float, float]] = field(default_factory=list)
    rss_growth_first_record_s: float = -1.0
    rss_mb_max: float = 0.0
    rss_growth_hour_mb: float = 0.0
    stop_s: list[float] = field(default_factory=list)
    crashes: list[str] = field(default_factory=list)
    finished: bool = False  # the run is complete (all its points' hits)


def _rss_mb(pid: int) -> float:
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return float("nan")
    m = re.search(r"VmRSS:\s+(\d+) kB", text)
    return int(m.group(1)) / 1024 if m else float("nan")


class Bench:
    """The mock bench process and its control channel; restartable."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.proc: subprocess.Popen[str] | None = None
        self.station = folder / "bench.toml"
        self.count = 0

    def start(self) -> None:
        self.count += 1
        self.station = self.folder / f"bench-{self.count}.toml"
        self.proc = subprocess.Popen([*INSITU, "mock-bench", "--bench", BENCH, "--station",
                                      str(self.station)], cwd=ROOT, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, text=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.station.exists() and "[devices.frontend]" in self.station.read_text():
                time.sleep(0.2)
                return
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        raise RuntimeError("the mock bench did not start")

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()

    def fault(self, device: str, name: str, value: int | bool | str) -> bool:
        from hardware_mocks.bench_control import BenchControl, BenchControlError

        try:
            with BenchControl.from_station(self.station, timeout=2.0) as control:
                control.fault(device, name, value)
            return True
        except (BenchControlError, OSError, ValueError):
            return False


#: fault name -> (device, field, value while on, value when off)
FAULTS: dict[str, tuple[str, str, int | bool | str, int | bool | str]] = {
    "frontend frames dropped": ("frontend", "drop_every", 97, 0),
    "frontend frames truncated": ("frontend", "bad_frame_every", 89, 0),
    "hammer frames corrupted": ("hammer", "corrupt_every", 53, 0),
    "hammer frames dropped": ("hammer", "drop_every", 61, 0),
    "front end unplugged": ("frontend", "silent", True, False),
    "hammer unplugged": ("hammer", "silent", True, False),
}


def _counts(path: Path) -> tuple[int, int, int, int]:
    """(records, accepted, samples lost, bad frames) stored in the run file."""
    from app.io.runfile import read_run

    if not path.exists():
        return 0, 0, 0, 0
    run = read_run(path, with_data=False)
    r = run.records
    return (len(r), int(np.count_nonzero(r.accepted)), int(np.sum(r.missing)),
            int(np.sum(r.bad_frames)))


def _finished(path: Path) -> bool:
    """True once the run file says the run is complete."""
    from app.io.runfile import read_run

    return path.exists() and read_run(path, with_data=False).state == "finished"


def soak(minutes: float, seed: int, folder: Path, console: Console, hits: int = 100000,
         fault_every: tuple[float, float] = (5.0, 25.0), first: str | None = None) -> Report:
    """Acquire for ``minutes`` (or until the run of ``hits`` per point is complete), a
    fault every ``fault_every`` s (uniform between the two); the first one ``first`` when
    given (a short run then surely holds it), the others drawn."""
    rng = random.Random(seed)
    report = Report(minutes, seed)
    plan = folder / "plan.toml"
    text, n = re.subn(r"^hits = \d+$", f"hits = {hits}", PLAN.read_text(), flags=re.M)
    if n != 1:
        raise RuntimeError(f"{PLAN}: no single 'hits = N' line to set")
    plan.write_text(text.replace("length = 1.5", "length = 0.5"))
    out = folder / "soak.h5"
    bench = Bench(folder)
    bench.start()
    end = time.monotonic() + 60 * minutes
    kept = (0, 0, 0, 0)
    try:
        while time.monotonic() < end and not _finished(out):
            args = [*INSITU, "acquire", "--station", str(bench.station), "--plan", str(plan),
                    "--out", str(out), "--mock-operator"]
            if out.exists():
                args = [*INSITU, "acquire", "--resume", str(out), "--station",
                        str(bench.station), "--mock-operator"]
            acq = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.PIPE, text=True,
                                   env={**os.environ, "COLUMNS": "200"})
            report.segments += 1
            t0 = time.monotonic()
            rss: list[tuple[float, float]] = []
            size0 = out.stat().st_size if out.exists() else 0
            t_first = -1.0  # when the segment stored its first record
            next_fault = t0 + rng.uniform(*fault_every)
            while acq.poll() is None and time.monotonic() < end:
                time.sleep(0.5)
                rss.append((time.monotonic() - t0, _rss_mb(acq.pid)))
                if t_first < 0 and out.exists() and out.stat().st_size != size0:
                    t_first = rss[-1][0]  # start-up over (imports, devices, read-back)
                if time.monotonic() < next_fault:
                    continue
                next_fault = time.monotonic() + rng.uniform(*fault_every)
                what = rng.choice([*FAULTS, "bench killed", "host stall"])
                if first is not None and not report.faults:
                    what = first
                report.faults[what] = report.faults.get(what, 0) + 1
                console.log(f"fault: {what}")
                if what == "bench killed":
                    bench.kill()
                    report.bench_restarts += 1
                    break
                if what == "host stall":
                    acq.send_signal(signal.SIGSTOP)
                    time.sleep(rng.uniform(0.2, 2.0))
                    acq.send_signal(signal.SIGCONT)
                    continue
                device, name, on, off = FAULTS[what]
                if bench.fault(device, name, on):
                    time.sleep(rng.uniform(1.0, 4.0))
                    bench.fault(device, name, off)
            t_int = None
            if acq.poll() is None and time.monotonic() >= end:
                acq.send_signal(signal.SIGINT)  # the operator stops the run: records kept
                t_int = time.monotonic()
            try:
                _, err = acq.communicate(timeout=120)
            except subprocess.TimeoutExpired:
                acq.kill()
                _, err = acq.communicate()
                report.crashes.append("acquire did not stop within 120 s")
            if t_int is not None:
                report.stop_s.append(time.monotonic() - t_int)
            lines = [ln for ln in err.splitlines() if ln.strip()]
            if any("Traceback" in ln or "internal error" in ln for ln in lines):
                report.crashes.append(lines[-1])
            if lines:
                report.pauses.append(lines[-1][:200])
            first = [m for t, m in rss if 5 <= t <= 60 and np.isfinite(m)]
            if first:
                report.rss_mb_first_minute.append(float(np.median(first)))
                report.rss_mb_peak.append(float(np.nanmax([m for _, m in rss])))
            # from WARM s after the first record (its processing loads and compiles code)
            after = [m for t, m in rss if t_first >= 0 and t >= t_first + WARM
                     and np.isfinite(m)]
            if after:
                report.rss_mb_acquiring.append(after[0])
                growth = max(after) - after[0]
                if growth >= report.rss_growth_mb:
                    report.rss_growth_mb = growth
                    report.rss_growth_trace = [(round(t, 2), round(m, 1)) for t, m in rss]
                    report.rss_growth_first_record_s = t_first
            now = _counts(out)
            if now[1] < kept[1] or now[0] < kept[0]:
                report.accepted_lost += kept[1] - now[1]
            kept = now
            if bench.proc is None or bench.proc.poll() is not None:
                bench.start()
            else:  # faults off again before the resume
                for device, name, _, off in FAULTS.values():
                    bench.fault(device, name, off)
    finally:
        bench.stop()
    report.records, report.accepted, report.samples_lost, report.bad_frames = kept
    report.finished = _finished(out)
    if report.rss_mb_peak:
        report.rss_mb_max = float(max(report.rss_mb_peak))
        # over the hour: the highest peak of any segment above the first segment's first minute
        report.rss_growth_hour_mb = report.rss_mb_max - report.rss_mb_first_minute[0]
    return report


def table(report: Report) -> Table:
    t = Table(title=f"soak: {report.minutes:g} min, seed {report.seed}")
    t.add_column("what")
    t.add_column("value", justify="right")
    for k, v in (("acquire segments (runs and resumes)", report.segments),
                 ("records stored", report.records), ("accepted hits", report.accepted),
                 ("accepted hits lost", report.accepted_lost),
                 ("samples lost (in stored records)", report.samples_lost),
                 ("corrupted frames seen", report.bad_frames),
                 ("bench restarts", report.bench_restarts),
                 (f"memory growth in a segment from {WARM:g} s after its first record, MB "
                  "(worst)",
                  f"{report.rss_growth_mb:.1f}"),
                 ("memory growth over the run, MB (highest peak - first segment's first "
                  "minute)", f"{report.rss_growth_hour_mb:.1f}"),
                 ("resident memory, MB: first minute (first, last segment) / peak",
                  f"{report.rss_mb_first_minute[0]:.0f}, {report.rss_mb_first_minute[-1]:.0f}"
                  f" / {report.rss_mb_max:.0f}" if report.rss_mb_first_minute else "-"),
                 ("seconds from Ctrl-C to exit", ", ".join(f"{s:.1f}" for s in report.stop_s)
                  or "-"),
                 ("crashes (traceback, internal error, hang)", len(report.crashes))):
        t.add_row(k, str(v))
    for k, v in sorted(report.faults.items()):
        t.add_row(f"fault injected: {k}", str(v))
    return t


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--hits", type=int, default=100000,
                    help="hits per point: the soak ends when the run is complete")
    ap.add_argument("--fault-every", type=float, nargs=2, default=(5.0, 25.0),
                    metavar=("LOW", "HIGH"), help="seconds between faults (uniform)")
    ap.add_argument("--first-fault", choices=(*FAULTS, "bench killed", "host stall"),
                    help="the first fault injected (the others drawn)")
    ap.add_argument("--json", type=Path, help="write the report as JSON here")
    ap.add_argument("--write-docs", action="store_true",
                    help="append the table to docs/reliability.md")
    args = ap.parse_args()
    console = Console()
    with tempfile.TemporaryDirectory() as d:
        report = soak(args.minutes, args.seed, Path(d), console, args.hits,
                      tuple(args.fault_every), args.first_fault)
    console.print(table(report))
    for p in report.pauses:
        console.print(f"segment ended: {p}")
    if args.json:
        args.json.write_text(json.dumps(asdict(report), indent=2))
    if args.write_docs:
        rec = Console(record=True, width=100, file=open(os.devnull, "w"))
        rec.print(table(report))
        with (ROOT / "docs" / "reliability.md").open("a") as f:
            f.write(f"\n### {time.strftime('%Y-%m-%d')}: `benchmarks/soak.py --minutes "
                    f"{args.minutes:g} --seed {args.seed}`\n\n```\n{rec.export_text()}```\n")
    return 0 if report.accepted_lost == 0 and not report.crashes else 1


if __name__ == "__main__":
    sys.exit(main())
