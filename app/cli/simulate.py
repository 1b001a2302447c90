"""``insitu simulate BENCH --out FILE.uff``: FRFs and geometry of a simulated bench."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from app.cli.common import VERB_HELP, UserError, check_output, check_range, reason
from app.io.uff import write_frf_uff
from app.pipeline.formats import UFF_SUFFIXES
from hardware_mocks.benches import BENCHES, get_bench

#: largest relative FRF noise and point-location error bound (m) a simulation takes
MAX_NOISE = 1.0
MAX_LOCATION_ERROR = 0.1


def add_parser(sub: Any) -> None:
    p = sub.add_parser("simulate", help=VERB_HELP["simulate"],
                       description=__doc__)
    p.add_argument("bench", choices=sorted(BENCHES), help="built-in bench")
    p.add_argument("--out", type=Path, required=True, help="UFF file to write")
    p.add_argument("--noise", type=float, default=0.0,
                   help="relative FRF noise (0.02 = 2 %% of |H|)")
    p.add_argument("--location-error", type=float, default=0.0,
                   help="uniform point-location error bound in m (0.003 = +-3 mm)")
    p.add_argument("--seed", type=int, default=0, help="random seed")
    p.add_argument("--binary", action="store_true", help="binary 58b records")
    p.add_argument("--mm", action="store_true", help="write geometry in mm")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    check_range("--noise", args.noise, 0, MAX_NOISE, "(relative to |H|)")
    check_range("--location-error", args.location_error, 0, MAX_LOCATION_ERROR, "m")
    check_range("--seed", args.seed, 0, 2**32 - 1, "")
    if args.out.suffix.lower() not in UFF_SUFFIXES:
        raise UserError(f"--out {args.out}: simulate writes UFF: give a .uff or .unv name")
    check_output(args.out)
    bench = get_bench(args.bench)
    frf = bench.frfset(args.noise, args.location_error, args.seed)
    try:
        write_frf_uff(args.out, frf, binary=args.binary, length_unit="mm" if args.mm else "m")
    except OSError as err:  # the disk filled or the folder went away since the check
        raise UserError(f"--out {args.out}: {reason(err)}: free some space or choose another "
                        "--out") from err
    print(f"{bench.description}: {frf.H.shape[0]} x {frf.H.shape[1]} FRFs, "
          f"{frf.freq.size} lines, written to {args.out}")
    return 0
