"""``insitu mock-bench [--station FILE] [--bench engine] [--shakers 1|2]``: a simulated bench.

Starts every mock device of the bench, as its own process, on one shared physical
model: the hammer digitiser and the shaker generator (two with ``--shakers 2``, for
plans with ``[shaker] shakers = 2``) on pseudo-terminals, the accelerometer front
end behind a socketcand server on 127.0.0.1 (classic CAN frames). Prints the
station file that connects the drivers to it (and writes it to FILE), then runs
until Ctrl-C or SIGTERM. An operator hits the structure or attaches the shaker
through the control channel named in the station file's ``[extra.mock_bench]``
table (``hardware_mocks.bench_control.BenchControl``).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from pathlib import Path
from types import FrameType
from typing import Any

from app.cli.common import VERB_HELP, UserError
from app.mockbench import bench_names

FE_RATES = (256, 512, 1024, 2048, 4096)
HAMMER_RATES = (1024, 2048, 4096, 8192, 16384)
SHAKERS = ("1", "2")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("mock-bench", help=VERB_HELP["mock-bench"],
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--station", type=Path, help="also write the station file here")
    p.add_argument("--bench", choices=bench_names(), default="engine", help="built-in bench")
    p.add_argument("--fe-rate", type=int, choices=FE_RATES, default=1024,
                   help="front-end sampling rate in the station file, Hz")
    p.add_argument("--hammer-rate", type=int, choices=HAMMER_RATES, default=4096,
                   help="hammer sampling rate in the station file, Hz")
    p.add_argument("--accel-noise", type=float, default=0.0, help="sensor noise, m/s^2 RMS")
    p.add_argument("--force-noise", type=float, default=0.0, help="sensor noise, N RMS")
    p.add_argument("--shakers", default="1", metavar="N",
                   help="shakers on the bench: 1, or 2 (each force on its own front-end "
                        "input F1, F2; for plans with [shaker] shakers = 2)")
    p.set_defaults(run=run)


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise UserError(f"cannot write the station file {path}: {err}") from err


def run(args: argparse.Namespace) -> int:
    if args.accel_noise < 0 or args.force_noise < 0:
        raise UserError("--accel-noise and --force-noise must be >= 0")
    if str(args.shakers) not in SHAKERS:
        raise UserError(f"--shakers {args.shakers}: the mock bench has 1 or 2 shakers")
    shakers = int(args.shakers)
    from app.mockbench import unavailable

    if why := unavailable():
        raise UserError(why)
    from hardware_mocks.bench_process import MockBench

    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with MockBench(args.bench, fe_rate=args.fe_rate, hammer_rate=args.hammer_rate,
                       accel_noise=args.accel_noise, force_noise=args.force_noise,
                       shakers=shakers) as bench:
            text = bench.station_toml()
            if args.station is not None:
                _write_atomically(args.station, text)
            sys.stdout.write(text)
            sys.stdout.flush()
            print(f"insitu mock-bench: bench {args.bench!r} running"
                  + (f" with {shakers} shakers" if shakers > 1 else "")
                  + (f", station file {args.station}" if args.station else "")
                  + "; Ctrl-C to stop", file=sys.stderr, flush=True)
            while not stop.wait(0.2):
                pass
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    print("insitu mock-bench: stopped", file=sys.stderr, flush=True)
    return 0
