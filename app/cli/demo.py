"""``insitu demo``: acquire the built-in engine bench by hammer, identify, compare with the truth.

The mock bench starts in this process (front end on a virtual CAN bus, hammer
digitiser on a pseudo-terminal, a simulated operator arm); the article's engine plan
(4 triaxial points, 18 forces) is acquired hit by hit through the real drivers into
an HDF5 run file, then identified and printed beside the model's truth.
``--frf-only`` skips the acquisition: exact FRFs with noise and location errors,
through UFF, identified with the plain and the improved methods.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from app.acquire.events import Listener
from app.cli.common import VERB_HELP, UserError, check_output, check_range
from app.cli.simulate import MAX_LOCATION_ERROR, MAX_NOISE
from app.cli.summary import print_result
from app.io.uff import write_frf_uff
from app.pipeline import FRF_UFF, load
from app.pipeline.formats import H5_SUFFIXES
from hardware_mocks.benches import BENCHES, get_bench
from processing.identify import IdentifyOptions, fit
from processing.inertia import inertia_properties


def add_parser(sub: Any) -> None:
    p = sub.add_parser("demo", help=VERB_HELP["demo"],
                       description=__doc__)
    p.add_argument("--bench", choices=sorted(BENCHES), default="engine")
    p.add_argument("--noise", type=float, default=0.01)
    p.add_argument("--location-error", type=float, default=0.001)
    p.add_argument("--frf-only", action="store_true",
                   help="skip the acquisition: identify simulated FRFs (fast)")
    p.add_argument("--out", type=Path,
                   help="run file to write (default: demo-run.h5 in the current folder, "
                        "numbered if it exists)")
    p.add_argument("--hits", type=int, default=DEMO_HITS,
                   help="hits a point (3 or more: the bootstrap over hits runs)")
    p.add_argument("--length", type=float, default=DEMO_LENGTH, help="record length per hit, s")
    p.add_argument("--exp-tau", type=float, default=None,
                   help="exponential window time constant, s (default: the record's "
                        "length after the pre-trigger / 5; 0: none)")
    p.set_defaults(run=run)


#: hits a point. One: the simulated operator lets the bench ring out between hits
#: (:data:`RING_OUT`), 2.8 s on the engine, so 18 hits take 50 s; three a point (the
#: bootstrap over hits runs) take 2.5 min
DEMO_HITS = 1
#: s, record length per hit (0.5 Hz lines)
DEMO_LENGTH = 2.0
#: the exponential window falls to exp(-EXP_FALL) (0.7 %) at the record's end
EXP_FALL = 5.0
#: the operator hits again once the previous hit's response has decayed to exp(-RING_OUT)
#: (0.25 %) of its start: RING_OUT times the bench's slowest decay time constant
RING_OUT = 6.0


def demo_exp_tau(length: float, pretrigger: float) -> float:
    """The demo's exponential window time constant, s: the engine's rigid-body modes (10
    to 30 Hz, 3 to 9 % damping, decay time constants up to 0.46 s) still ring at the end of a
    2 s record, and the rectangular window leaks them into the mass line; the exponential
    window takes them to exp(-:data:`EXP_FALL`) of their start by its end (the damping it
    adds is taken off C)."""
    return (length - pretrigger) / EXP_FALL


def ring_out(bench_name: str) -> float:
    """s between two hits of the demo's operator on built-in bench ``bench_name``:
    :data:`RING_OUT` times its slowest decay time constant (2.8 s on the engine). A hit
    sooner finds the previous one still ringing (a 0.2 s pause after each 1.5 s record left
    2.5 % of it, and the mass came out 1 % high)."""
    from hardware_mocks.signals import settling_time

    return RING_OUT * settling_time(get_bench(bench_name).model)


#: how often the demo resumes its simulated bench after a pause before it stops the run
DEMO_RESUMES = 3
#: s the demo waits before resuming, so a device that lagged under load catches up
RESUME_DELAY = 0.5


class _Resumer(Listener):
    """Resumes a paused demo run (nobody stands at the simulated bench), :data:`DEMO_RESUMES`
    times at most, then stops it: the records stay in the run file.

    Called on the run's worker thread, which reads the command after the pause's listeners."""

    def __init__(self, proc: Any, console: Console) -> None:
        self.proc, self.console, self.pauses, self.reason = proc, console, 0, ""

    def on_paused(self, reason: str) -> None:
        self.pauses += 1
        self.reason = reason
        if self.pauses > DEMO_RESUMES:
            self.console.print(f"[yellow]paused again: {reason}; stopping the demo run[/yellow]")
            self.proc.stop()
            return
        self.console.print(f"[yellow]paused: {reason}; resuming the simulated bench "
                           f"({self.pauses} of {DEMO_RESUMES})[/yellow]")
        time.sleep(RESUME_DELAY)
        self.proc.resume()


def _acquire(args: argparse.Namespace, console: Console) -> int:
    from app.acquire import HammerProcedure
    from app.acquire.events import RunState
    from app.cli.acquire import ProgressBars
    from app.mockbench import unavailable

    if why := unavailable():
        raise UserError(f"{why} (insitu demo --frf-only identifies simulated FRFs)")
    from app.mockbench.bench import InProcessBench, plan_for_bench

    name = "engine" if args.bench == "engine" else args.bench
    if args.hits < 1 or not args.length > 0 or (args.exp_tau is not None and args.exp_tau < 0):
        raise UserError("--hits must be at least 1, --length positive and --exp-tau not "
                        "negative")
    if args.out is not None and args.out.exists():
        raise UserError(f"{args.out} exists: choose another --out")
    path = args.out or _free_name()
    settle = ring_out(name)
    with InProcessBench(name, operator={"settle": settle}) as bench:
        plan = plan_for_bench(name, hits=args.hits, length=args.length)
        rec = plan.record
        tau = demo_exp_tau(rec.length, rec.pretrigger) if args.exp_tau is None else args.exp_tau
        plan = dataclasses.replace(plan, record=dataclasses.replace(rec, exp_tau=tau or None))
        console.rule(f"insitu demo: {bench.bench.description}")
        hits = f"{plan.hits} hit{'s' * (plan.hits > 1)} a point"
        console.print(f"hammer test of {len(plan.excitations)} points, {hits} "
                      f"({rec.length:g} s records, exponential window "
                      f"{'none' if plan.record.exp_tau is None else f'{tau:g} s'}; the bench "
                      f"rings out {settle:.1f} s between hits) through the drivers (mock front "
                      f"end on CAN, hammer on {bench.hammer.path}) into {path}")
        proc = HammerProcedure(plan, bench.station, path, listeners=[bench.operator])
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=console) as progress:
            # the resumer's line is the pause's one line
            proc.add_listener(ProgressBars(progress, plan, console, quiet_pause=True))
            resumer = _Resumer(proc, console)
            proc.add_listener(resumer)
            proc.start()
            proc.wait()
        if proc.state is not RunState.FINISHED or proc.result is None:
            why = (f"paused {resumer.pauses} times ({resumer.reason})"
                   if resumer.pauses > DEMO_RESUMES else f"{proc.state.value}: {proc.message}")
            raise UserError(f"demo run {why}; its {len(proc.hits)} hits are in {path} "
                            f"(see them with insitu replay {path})")
        model = bench.bench.model
        print_result(proc.result, console, truth=inertia_properties(model.theta),
                     K_truth=model.K, C_truth=model.C)
        console.print(f"run file {path} kept ({path.stat().st_size / 1e6:.1f} MB, "
                      f"{len(proc.hits)} hits): replay it with insitu replay {path}")
    return 0


def _free_name(base: str = "demo-run") -> Path:
    """``demo-run.h5`` in the current folder, or ``demo-run-2.h5``...: the first free one."""
    path, k = Path(f"{base}.h5"), 1
    while path.exists():
        k += 1
        path = Path(f"{base}-{k}.h5")
    return path


def run(args: argparse.Namespace) -> int:
    check_range("--noise", args.noise, 0, MAX_NOISE, "(relative to |H|)")
    check_range("--location-error", args.location_error, 0, MAX_LOCATION_ERROR, "m")
    check_range("--length", args.length, 0.1, 60, "s")
    if args.frf_only and args.out is not None:
        raise UserError("--frf-only writes no run file: leave out --out")
    if not args.frf_only:
        if args.out is not None:
            if args.out.suffix.lower() not in H5_SUFFIXES:
                raise UserError(f"--out {args.out}: the demo writes a run file: give a .h5 "
                                "name")
            if args.out.exists():
                raise UserError(f"{args.out} exists: choose another --out")
            check_output(args.out)
        return _acquire(args, Console())
    console = Console()
    bench = get_bench(args.bench)
    model = bench.model
    console.rule(f"insitu demo: {bench.description}")
    console.print(f"simulated with {args.noise * 100:g} % FRF noise and +-"
                  f"{args.location_error * 1e3:g} mm point-location errors")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{bench.name}.uff"
        write_frf_uff(path, bench.frfset(args.noise, args.location_error, seed=1))
        m = load(path, fmt=FRF_UFF)
    truth = inertia_properties(model.theta)
    for method in ("plain", "improved"):
        console.rule(f"{method} method")
        result = fit(m, IdentifyOptions(method=method))
        print_result(result, console, truth=truth, K_truth=model.K, C_truth=model.C)
    return 0
