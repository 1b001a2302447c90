"""``insitu demo``: identify the built-in engine bench and compare with the model's truth.

The engine bench (article section 5.2: 4 triaxial points, 18 forces, 1024 lines)
is simulated with FRF noise and point-location errors, written to UFF, read back
and identified with the article's plain method and with the improved one.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from rich.console import Console

from app.cli.summary import print_result
from app.io.uff import read_frf_uff, write_frf_uff
from hardware_mocks.benches import BENCHES, get_bench
from processing.identify import IdentifyOptions, identify
from processing.inertia import inertia_properties


def add_parser(sub: Any) -> None:
    p = sub.add_parser("demo", help="run the main job on the built-in simulated bench",
                       description=__doc__)
    p.add_argument("--bench", choices=sorted(BENCHES), default="engine")
    p.add_argument("--noise", type=float, default=0.01)
    p.add_argument("--location-error", type=float, default=0.001)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    console = Console()
    bench = get_bench(args.bench)
    model = bench.model
    console.rule(f"insitu demo: {bench.description}")
    console.print(f"simulated with {args.noise * 100:g} % FRF noise and +-"
                  f"{args.location_error * 1e3:g} mm point-location errors")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{bench.name}.uff"
        write_frf_uff(path, bench.frfset(args.noise, args.location_error, seed=1))
        frf = read_frf_uff(path)
    truth = inertia_properties(model.theta)
    for method in ("plain", "improved"):
        console.rule(f"{method} method")
        result = identify(frf, IdentifyOptions(method=method))
        print_result(result, console, truth=truth, K_truth=model.K, C_truth=model.C)
    return 0
