"""``insitu acquire``: run a test plan headless, with progress bars, into one HDF5 run file.

The plan's ``method`` picks the procedure: hammer (triggered hits) or shaker (a
level ramp, then blocks averaged per point). ``--mock`` (or no ``--station``)
acquires on the built-in in-process mock bench with a simulated operator (who
hits, or moves the shaker). ``--resume`` continues an interrupted run from its
file, with the plan stored there (a ``--plan`` that differs is refused, naming the keys)
on the station the run was acquired with (the built-in mock bench it used, or the
``--station`` it needs, said in one line before any device opens). Ctrl-C, SIGTERM and
SIGHUP stop the run, its records kept, and the last line gives the command that
continues it. ``--resume --override HIT=accept|reject|clear`` (repeatable; HIT the record
number printed by the run, from 1) changes the operator's verdict of stored hits
or blocks: the FRFs and the identification are recomputed from the raw records
and stored when every point is complete (no device is opened then), otherwise
the acquisition resumes to complete the points that now lack hits. With a real
station and a shaker plan, the run waits at each point until the shaker is
attached there (press Enter).

A station file with a ``[simulation]`` table (``docs/ni_station.toml``) runs its real
drivers on simulated vendor APIs (NI-DAQmx) driven by that built-in bench, with a simulated
operator (:mod:`app.mockbench.simulated`); such a run, too, stops at a pause, its records
kept.

``--station BENCH.toml --mock-operator`` acquires on a mock bench running in
another process (``insitu mock-bench --station BENCH.toml``), through the same
drivers and transports as real hardware; a simulated operator hits each point
the run names (or attaches the shaker there) through the bench's control
channel, whose address is in the station's ``[extra.mock_bench]`` table. A run
on a mock bench (``--mock`` or ``--mock-operator``) that pauses (a device stopped
answering, the shaker's amplifier tripped) is stopped, its records kept: nobody is
there to fix the bench and resume.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import threading
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from app.acquire import HammerProcedure, Listener, load_plan
from app.acquire.events import HitRecord, RunState
from app.acquire.events import Progress as RunProgress
from app.acquire.overrides import override_run, parse_override
from app.acquire.plan import PlanError, TestPlan
from app.acquire.recording import RecordingProcedure, resumed_plan
from app.acquire.shaker import ShakerProcedure
from app.acquire.space import check_disk_space
from app.cli.common import VERB_HELP, UserError
from app.io.runfile import read_run
from drivers.station import StationConfig, load_station

if TYPE_CHECKING:  # the mock bench is imported by --mock, --mock-operator and [simulation]
    from app.mockbench.bench import InProcessBench
    from app.mockbench.simulated import SimulatedStation
    from hardware_mocks.operator import RemoteOperator, RemoteShakerOperator

#: what a pause that waits for the operator to attach the shaker says first
ATTACH = "attach the shaker"
#: seconds a stopped run has to end (its devices released, its file closed) before we exit
STOP_WAIT = 15.0

class ProgressBars(Listener):
    """Rich progress bars of a run: points (or stops) done, records of the current one."""

    def __init__(self, progress: Progress, plan: TestPlan, console: Console,
                 quiet_pause: bool = False) -> None:
        self.progress = progress
        self.console = console
        #: a pause the command answers itself (a mock bench stops there): its one line
        #: is the command's last
        self.quiet_pause = quiet_pause
        # a stop of the run: a point, or the points two shakers drive together
        self.points = progress.add_task(f"{plan.stop_word}s",
                                        total=len(plan.drives))
        self.hits = progress.add_task("hits at point", total=1)
        self.paused = ""

    def on_next_point(self, point: Any) -> None:
        self.progress.update(self.hits, description=f"hits at {point.label}", completed=0)
        if not self.console.is_terminal:  # no live bars in a log file: one line a point
            done = self.progress.tasks[self.points].completed
            self.console.print(f"{point.label} ({done:g} of "
                               f"{self.progress.tasks[self.points].total:g} done)")

    def on_hit(self, hit: HitRecord) -> None:
        if not hit.accepted:
            self.console.print(f"hit {hit.hit_id + 1} at point {hit.point + 1} rejected: "
                               f"{hit.reason}")

    def on_progress(self, p: RunProgress) -> None:
        self.progress.update(self.hits, total=p.point_needed, completed=p.point_accepted)
        self.progress.update(self.points, completed=p.points_done)

    def on_paused(self, reason: str) -> None:
        self.paused = reason
        if not reason.startswith(ATTACH) and not self.quiet_pause:
            self.console.print(f"[yellow]paused: {reason}[/yellow]")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("acquire", help=VERB_HELP["acquire"],
                       description=__doc__)
    p.add_argument("--station", type=Path, help="station.toml (default: built-in mock bench)")
    p.add_argument("--plan", type=Path, help="test plan TOML (default with --mock: the bench's)")
    p.add_argument("--out", type=Path, help="run file to write (RUN.h5)")
    p.add_argument("--resume", nargs="?", const=True, default=False, metavar="RUN.h5",
                   help="continue the interrupted run in RUN.h5 (or in --out)")
    p.add_argument("--override", action="append", default=[], metavar="HIT=VERDICT",
                   help="with --resume: accept, reject or clear the verdict of stored record "
                        "HIT (from 1); repeatable")
    p.add_argument("--mock", action="store_true", help="use the in-process mock bench")
    p.add_argument("--mock-operator", action="store_true",
                   help="with --station of a running insitu mock-bench: a simulated operator "
                        "hits (or moves the shaker) through its control channel")
    p.add_argument("--bench", help="mock bench (default engine; with --resume, the run's)")
    p.add_argument("--method", choices=("hammer", "shaker"), default="hammer",
                   help="mock plan: hammer or shaker (chirp, one block per --hits)")
    p.add_argument("--hits", type=int, default=1,
                   help="mock plan: accepted hits (or shaker blocks) per point")
    p.add_argument("--length", type=float, default=2.0,
                   help="mock plan: record (or shaker block) length, s")
    p.add_argument("--points", help="mock plan: excitation indices, comma separated")
    p.set_defaults(run=run)


def _mock_plan(args: argparse.Namespace) -> TestPlan:
    from app.mockbench.bench import plan_for_bench

    pts = [int(x) for x in args.points.split(",")] if args.points else None
    bench = args.bench or "engine"
    if args.method == "shaker":
        fs = 1024.0
        return plan_for_bench(bench, points=pts, fs=fs, method="shaker", shaker={
            "waveform": "chirp", "nperseg": round(args.length * fs), "averages": args.hits,
            "f_start": 2.0, "f_stop": fs / 2.56, "ramp": 0.2, "settle": 1.5})
    return plan_for_bench(bench, points=pts, hits=args.hits, length=args.length)


def _in_process_bench(name: str, fs: float, shakers: int = 1) -> InProcessBench:
    """The built-in mock bench ``name`` in this process (front end at ``fs`` Hz, ``shakers``
    shakers); one line where it cannot run."""
    from app.mockbench import unavailable

    if why := unavailable():
        raise UserError(f"--mock: {why}")
    from app.mockbench.bench import InProcessBench

    return InProcessBench(name, fs_frontend=fs, shakers=shakers)


def _simulated_station(station: StationConfig) -> SimulatedStation:
    """The simulated vendor APIs and operator of a station with a ``[simulation]`` table;
    one line where they cannot be built."""
    from app.mockbench.simulated import SimulatedStation, SimulationError

    try:
        return SimulatedStation(station)
    except SimulationError as err:
        raise UserError(str(err)) from err


def _procedure(plan: TestPlan, station: StationConfig, args: argparse.Namespace,
               bench: InProcessBench | None, sim: SimulatedStation | None = None
               ) -> RecordingProcedure:
    options = sim.device_options if sim is not None else None
    if plan.method == "shaker":
        if sim is not None and sim.shaker_operator is None:
            raise UserError(f"{station.source}: a shaker plan, but the simulated station has "
                            "no simulated shaker: use a hammer plan")
        operator = bench.shaker_operator if bench else sim.shaker_operator if sim else None
        return ShakerProcedure(plan, station, args.out, resume=args.resume,
                               listeners=[operator] if operator is not None else [],
                               confirm_attach=operator is None and not args.mock_operator,
                               device_options=options)
    operator = bench.operator if bench else sim.operator if sim else None
    return HammerProcedure(plan, station, args.out, resume=args.resume,
                           listeners=[operator] if operator is not None else [],
                           device_options=options)


def _remote_operator(station: StationConfig, plan: TestPlan, stack: contextlib.ExitStack
                     ) -> RemoteOperator | RemoteShakerOperator:
    """The simulated operator of the mock bench process ``station`` connects to."""
    from hardware_mocks.bench_control import BenchControl, BenchControlError, control_address
    from hardware_mocks.operator import RemoteOperator, RemoteShakerOperator, check_points

    try:
        host, port = control_address(station)
        control = stack.enter_context(BenchControl(host, port))
        if plan.method == "shaker":
            operator: RemoteOperator | RemoteShakerOperator = RemoteShakerOperator(
                control, shakers=plan.n_references)
        else:
            operator = RemoteOperator(control)
            stack.callback(operator.shutdown)
    except BenchControlError as err:
        raise UserError(f"--mock-operator: {err}") from err
    try:
        check_points(operator.bench, plan.excitations)
    except ValueError as err:
        raise UserError(f"{plan.source}: {err} (mock bench {operator.bench.name!r})") from err
    return operator


def _check_bench_shakers(plan: TestPlan, station: StationConfig) -> None:
    """A station of ``insitu mock-bench`` says how many shakers the bench runs: refuse a plan
    that needs another number now, in one line (its front end has one force input per
    shaker, F1, F2..., with two or more, and no input for the hammer then)."""
    table = station.extra.get("mock_bench")
    have = table.get("shakers", 1) if isinstance(table, Mapping) else None
    if not isinstance(have, int) or isinstance(have, bool):
        return
    need = plan.n_references
    if plan.method == "shaker" and need != have:
        raise UserError(f"{plan.source}: the plan drives {need} shaker{'s' if need > 1 else ''} "
                        f"at once but the mock bench runs {have}: restart it with insitu "
                        f"mock-bench --shakers {need}")
    if plan.method != "shaker" and have > 1:
        raise UserError(f"{plan.source}: a {plan.method} plan, but the mock bench runs {have} "
                        "shakers (its front end records their forces, not the hammer's): "
                        "restart it without --shakers")


def _check_rate(proc: RecordingProcedure, plan: TestPlan, station: StationConfig) -> None:
    """A mock bench's front end runs at its station's ``fs``: refuse another plan rate now."""
    fs = station.devices[proc.ref_name].fs
    if fs is not None and fs != plan.record.fs:
        raise UserError(f"{plan.source}: record.fs is {plan.record.fs:g} Hz but the mock "
                        f"bench's front end runs at {fs:g} Hz: make them equal (insitu "
                        f"mock-bench --fe-rate {plan.record.fs:g})")


def _apply_overrides(args: argparse.Namespace, console: Console) -> bool:
    """Apply ``--override``s to the stored run; True when the run is complete after them."""
    wanted: dict[int, str] = {}
    for text in args.override:
        i, what = parse_override(text)
        wanted[i] = what
    out = override_run(args.out, wanted)
    for i, (old, new) in out.changed.items():
        reason = out.run.records.reason[i]
        console.print(f"record {i + 1}: override {old or 'none'} -> {new or 'none'}"
                      + (f" (automatic verdict: {reason})" if reason else ""))
    if not out.complete:
        for j, n, need in out.missing:
            console.print(f"point {j + 1}: {n} of {need} accepted: acquiring the rest")
        return False
    if out.message:
        raise UserError(f"{args.out}: FRFs stored; {out.message}")
    what = "FRFs and identification" if out.result is not None else "FRFs (partial plan)"
    console.print(f"{what} recomputed and stored in {args.out}")
    if out.result is not None:
        from app.cli.summary import print_result
        from app.pipeline import RUN_FILE, load
        from processing.identify import fit

        print_result(fit(load(args.out, fmt=RUN_FILE)), console)
    return True


def _again(args: argparse.Namespace) -> str:
    """The options that continue this run: ``--resume RUN.h5`` and the station's."""
    station = f" --station {args.station}" if args.station is not None and not args.mock else ""
    return f"--resume {args.out}{station}{' --mock-operator' if args.mock_operator else ''}"


def _kept(path: Path, again: str) -> str:
    """What an ended run left, as it is on the disk: never a file that does not exist;
    ``again`` the options that continue it."""
    try:
        n = len(read_run(path, with_data=False).records) if path.is_file() else 0
    except ValueError as err:  # never "no record" for a file that may hold some
        return f"{err} (insitu repair {path} recovers the records written)"
    if n:
        return f"its {n} records are in {path} (continue with {again})"
    if path.is_file():
        return f"no record was acquired ({path} holds the run's settings; continue with " \
               f"{again})"
    return "no record was acquired and no run file was written"


def _stored_bench(station: Mapping[str, Any]) -> str | None:
    """The built-in mock bench a run file's stored station is (None: a station file)."""
    extra = station.get("extra")
    if isinstance(extra, Mapping) and isinstance(extra.get("in_process_bench"), str):
        return str(extra["in_process_bench"])
    # run files written before the station's [extra] was stored: the in-process bench's name
    if station.get("source") == "in-process mock station":
        name = str(station.get("name", ""))
        if name.startswith("in-process mock bench (") and name.endswith(")"):
            return name[len("in-process mock bench ("):-1]
    return None


def _resume_checks(args: argparse.Namespace, plan: TestPlan | None) -> TestPlan:
    """The plan a resumed run goes on with, its own; refusals before any device opens: a
    ``--plan`` that differs from it, a station or bench other than the run's."""
    run = read_run(args.out, with_data=False)
    try:
        stored = resumed_plan(run, plan, args.out.name,
                              "resume with the stored plan (omit --plan)")
    except PlanError as err:
        raise UserError(str(err)) from err
    bench = _stored_bench(run.station_data)
    source = run.station_data.get("source")
    if bench is not None:
        if args.station is not None and not args.mock:
            raise UserError(f"{args.out} was acquired on the built-in mock bench {bench}: "
                            "resume it without --station")
        if args.bench not in (None, bench):
            raise UserError(f"{args.out} was acquired on mock bench {bench}, not "
                            f"{args.bench}: resume it without --bench")
        args.bench = bench
    elif isinstance(source, str) and source and (args.mock or args.station is None):
        extra = run.station_data.get("extra")
        mock = isinstance(extra, Mapping) and "mock_bench" in extra
        raise UserError(f"{args.out} was acquired on station {source}: resume it with "
                        f"--station {source}" + (" (and --mock-operator for the simulated "
                                                 "operator)" if mock else ""))
    return stored


class _Signalled(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread as Ctrl-C raises KeyboardInterrupt."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


@contextlib.contextmanager
def _stop_signals() -> Iterator[None]:
    """SIGTERM and SIGHUP (a service manager, a closed terminal) stop the run as Ctrl-C
    does; one is enough: more while the run stops are ignored (its stop is bounded by
    :data:`STOP_WAIT`). Handlers can only be set in the main thread: elsewhere nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    seen: list[int] = []

    def handler(signum: int, frame: Any) -> None:
        if not seen:
            seen.append(signum)
            raise _Signalled(signal.Signals(signum).name)

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, previous in old.items():
            signal.signal(sig, previous)


def _check_paths(args: argparse.Namespace) -> None:
    """``--resume RUN.h5`` or ``--resume --out RUN.h5``; refusals before any device opens."""
    if args.override and not args.resume:
        raise UserError("--override changes a stored run: give --resume --out RUN.h5")
    if isinstance(args.resume, str):
        named = Path(args.resume)
        if args.out is not None and args.out != named:
            raise UserError(f"--resume names {named} and --out {args.out}: give the run file "
                            "once")
        args.out, args.resume = named, True
    if args.out is None:
        raise UserError("give --out RUN.h5 (the run file to write), or --resume RUN.h5")
    if args.resume:
        if not args.out.is_file():
            raise UserError(f"{args.out}: no run file to resume")
        if not args.override:
            data = read_run(args.out, with_data=False)
            if data.state == "finished":
                raise UserError(f"{args.out} is a finished run ({len(data.records)} records): "
                                f"nothing to resume; see it with insitu replay {args.out}, or "
                                "change a verdict with --override HIT=accept|reject")
        return
    if args.out.exists():
        raise UserError(f"{args.out} exists: choose another --out or use --resume")
    folder = args.out.parent
    if not folder.is_dir():
        raise UserError(f"--out {args.out}: folder {folder} does not exist: create it or "
                        "choose another path")
    if not os.access(folder, os.W_OK):
        raise UserError(f"--out {args.out}: folder {folder} is not writable: choose another "
                        "path")


def _stop(proc: RecordingProcedure, path: Path, again: str, reason: str) -> None:
    """Stop the run and wait for it to end, :data:`STOP_WAIT` s at most (a UserError then:
    every record written so far is on the disk, the file is left as interrupted)."""
    proc.stop(reason)
    proc.wait(STOP_WAIT)
    if proc.running:
        raise UserError(f"the run did not stop within {STOP_WAIT:g} s: {_kept(path, again)}")


def run(args: argparse.Namespace) -> int:
    _check_paths(args)
    if args.mock_operator and (args.mock or args.station is None):
        raise UserError("--mock-operator drives a bench started by insitu mock-bench: give "
                        "--station with its station file (--mock has its own operator)")
    console = Console()
    if args.override and _apply_overrides(args, console):
        return 0
    plan = load_plan(args.plan) if args.plan else None
    if args.resume:
        plan = _resume_checks(args, plan)
    again = _again(args)
    with _stop_signals(), contextlib.ExitStack() as stack:
        bench = None
        sim = None
        if args.mock or args.station is None:
            fs = plan.record.fs if plan is not None else 1024.0
            shakers = plan.n_references if plan is not None else 1
            bench = stack.enter_context(_in_process_bench(args.bench or "engine", fs, shakers))
            station = bench.station
            if plan is None:
                plan = _mock_plan(args)
        else:
            station = load_station(args.station)
            if plan is None:
                raise UserError("give --plan FILE (or --mock for the built-in bench's plan)")
            _check_bench_shakers(plan, station)
            if station.simulation:
                if args.mock_operator:
                    raise UserError(f"{station.source} simulates its bench ([simulation]), "
                                    "with its own simulated operator: drop --mock-operator")
                sim = stack.enter_context(_simulated_station(station))
        proc = _procedure(plan, station, args, bench, sim)
        check_disk_space(proc)  # before any device opens or the file is created
        operator = None
        if args.mock_operator:
            _check_rate(proc, proc.plan, station)
            operator = _remote_operator(station, proc.plan, stack)
            proc.add_listener(operator)
        gave_up = ""
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=console) as progress:
            simulated = bench is not None or sim is not None  # nobody at the bench to fix it
            bars = ProgressBars(progress, proc.plan, console,
                                quiet_pause=operator is not None or simulated)
            proc.add_listener(bars)
            proc.start()
            try:
                # until the worker ends: after the last record it still shuts the devices
                # and tells the listeners (the operator detaches the shakers through the
                # control channel this command closes when it returns)
                while proc.running:
                    if proc.wait(0.2) is RunState.FINISHED or not proc.running:
                        continue
                    if ((operator is not None and operator.error) or (
                            proc.state is RunState.PAUSED
                            and (operator is not None or simulated))):
                        # a simulated bench: nobody there to fix and resume: stop, the
                        # records are kept
                        gave_up = (operator.error if operator is not None else "") or \
                            f"run paused: {proc.message}"
                        _stop(proc, args.out, again, "stopped at a pause")
                    elif proc.state is RunState.PAUSED and bars.paused.startswith(ATTACH):
                        bars.paused = ""
                        console.input(f"{proc.message}: press Enter ")
                        proc.resume()
            except KeyboardInterrupt as err:
                _stop(proc, args.out, again, f"stopped by {err.name}"
                      if isinstance(err, _Signalled) else "stopped by the operator")
    if gave_up:
        raise UserError(f"{gave_up}; the run stopped, {_kept(args.out, again)}")
    if proc.state is not RunState.FINISHED:
        raise UserError(f"run {proc.state.value}: {proc.message}; {_kept(args.out, again)}")
    console.print(f"{len(proc.hits)} records, run written to {args.out}")
    result = proc.result
    if result is not None:
        from app.cli.summary import print_result

        print_result(result, console)
    return 0
