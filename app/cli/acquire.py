"""``insitu acquire``: run a test plan headless, with progress bars, into one HDF5 run file.

``--mock`` (or no ``--station``) acquires on the built-in in-process mock bench with a
simulated operator arm. ``--resume`` continues an interrupted run from its file.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from app.acquire import HammerProcedure, InProcessBench, Listener, load_plan, plan_for_bench
from app.acquire.events import HitRecord, RunState
from app.acquire.events import Progress as RunProgress
from app.cli.common import UserError
from drivers.station import load_station


class _Bars(Listener):
    def __init__(self, progress: Progress, n_points: int, console: Console) -> None:
        self.progress = progress
        self.console = console
        self.points = progress.add_task("points", total=n_points)
        self.hits = progress.add_task("hits at point", total=1)

    def on_next_point(self, point: Any) -> None:
        self.progress.update(self.hits, description=f"hits at {point.label}", completed=0)

    def on_hit(self, hit: HitRecord) -> None:
        if not hit.accepted:
            self.console.print(f"hit {hit.hit_id + 1} at point {hit.point + 1} rejected: "
                               f"{hit.reason}")

    def on_progress(self, p: RunProgress) -> None:
        self.progress.update(self.hits, total=p.point_needed, completed=p.point_accepted)
        self.progress.update(self.points, completed=p.points_done)

    def on_paused(self, reason: str) -> None:
        self.console.print(f"[yellow]paused: {reason}[/yellow]")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("acquire", help="acquire a test plan into an HDF5 run file",
                       description=__doc__)
    p.add_argument("--station", type=Path, help="station.toml (default: built-in mock bench)")
    p.add_argument("--plan", type=Path, help="test plan TOML (default with --mock: the bench's)")
    p.add_argument("--out", type=Path, required=True, help="run file to write (RUN.h5)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument("--mock", action="store_true", help="use the in-process mock bench")
    p.add_argument("--bench", default="engine", help="mock bench (default engine)")
    p.add_argument("--hits", type=int, default=1, help="mock plan: accepted hits per point")
    p.add_argument("--length", type=float, default=2.0, help="mock plan: record length, s")
    p.add_argument("--points", help="mock plan: excitation indices, comma separated")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.resume and not args.out.is_file():
        raise UserError(f"{args.out}: no run file to resume")
    if not args.resume and args.out.exists():
        raise UserError(f"{args.out} exists: choose another --out or use --resume")
    plan = load_plan(args.plan) if args.plan else None
    console = Console()
    with contextlib.ExitStack() as stack:
        if args.mock or args.station is None:
            bench = stack.enter_context(InProcessBench(args.bench))
            station, listeners = bench.station, [bench.operator]
            if plan is None and not args.resume:
                pts = [int(x) for x in args.points.split(",")] if args.points else None
                plan = plan_for_bench(args.bench, points=pts, hits=args.hits,
                                      length=args.length)
        else:
            station, listeners = load_station(args.station), []
            if plan is None and not args.resume:
                raise UserError("give --plan FILE (or --mock for the built-in bench's plan)")
        proc = HammerProcedure(plan, station, args.out, listeners=listeners, resume=args.resume)
        n = len(proc.plan.excitations)
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=console) as progress:
            proc.add_listener(_Bars(progress, n, console))
            proc.start()
            try:
                while proc.wait(0.2) is RunState.RUNNING or proc.running:
                    pass
            except KeyboardInterrupt:
                proc.stop()
                proc.wait()
    if proc.state is not RunState.FINISHED:
        raise UserError(f"run {proc.state.value}: {proc.message}; acquired hits are in "
                        f"{args.out} (continue with --resume)")
    console.print(f"{len(proc.hits)} hits, run written to {args.out}")
    if proc.result is not None:
        from app.cli.summary import print_result

        print_result(proc.result, console)
    return 0
