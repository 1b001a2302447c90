"""``insitu plan``: choose the sensors and excitation points of a test before the first hit,
and predict how well the identification will know every number (docs/planning.md).

``insitu plan --model model.toml --candidates cand.toml --sensors 4 --points 9 --out
plan.toml`` (or ``--result earlier.json`` for the model, ``--geometry nodes.uff`` for the
candidates: every node a sensor and an excitation candidate, along the global axes) writes
the acquisition plan ``insitu acquire`` reads, with a ``[prediction]`` table that the report
shows beside the achieved uncertainty after the test.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from app.cli.common import VERB_HELP, UserError, check_output, check_range, write_output


def add_parser(sub: Any) -> None:
    p = sub.add_parser("plan", help=VERB_HELP["plan"], description=__doc__)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--model", type=Path, help="approximate model of the unit (TOML)")
    src.add_argument("--result", type=Path, help="an earlier test's result JSON as the model")
    cand = p.add_mutually_exclusive_group(required=True)
    cand.add_argument("--candidates", type=Path,
                      help="candidate sensors and excitation points (TOML)")
    cand.add_argument("--geometry", type=Path, help="a UFF file whose nodes are the candidates")
    p.add_argument("--sensors", type=int, required=True, help="triaxial sensors to use")
    p.add_argument("--points", type=int, required=True, help="excitations to use")
    p.add_argument("--out", type=Path, required=True, help="the plan TOML to write")
    p.add_argument("--noise", default="1%",
                   help="noise on force and responses, relative to each record's RMS (1%%)")
    p.add_argument("--averages", type=int, help="hits or blocks a point (the plan's)")
    p.add_argument("--location-uncertainty", metavar="LEN", help="e.g. 2mm (std)")
    p.add_argument("--angle-uncertainty", metavar="ANGLE", help="e.g. 1deg (std)")
    p.add_argument("--gain-uncertainty", metavar="REL", help="e.g. 1%% (std)")
    p.add_argument("--criterion", choices=("D", "A"), default="D",
                   help="D-optimal (log det) or A-optimal (trace) on the predicted covariance")
    p.add_argument("--with-stiffness", action="store_true",
                   help="the criterion covers K's 21 entries too")
    p.add_argument("--first-elastic", type=float, metavar="HZ",
                   help="expected first elastic mode of the unit (the model file's); the "
                   "prediction then holds generic elastic modes there (docs/planning.md)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from app.acquire.design import conditions, load_inputs, plan_data, plan_layout
    from app.acquire.plan import PlanError, parse_plan, plan_toml
    from app.io.planning import PlanInputError
    from app.pipeline.settings import RELATIVE_UNITS, TestUncertaintySettings, parse_quantity
    from processing.montecarlo import StatedUncertainty
    from processing.planning import PlanningError

    check_range("--sensors", args.sensors, 3, 1000, "")
    check_range("--points", args.points, 6, 10000, "")
    check_range("--averages", args.averages, 1, 100000, "")
    check_range("--first-elastic", args.first_elastic, 0, 1e6, "Hz", above=True)
    check_output(args.out, inputs=tuple(p for p in (args.model, args.result, args.candidates,
                                                      args.geometry) if p is not None))
    noise = parse_quantity("noise", args.noise, RELATIVE_UNITS, "1%", 0.5)
    unc = TestUncertaintySettings(args.location_uncertainty, args.angle_uncertainty,
                                  args.gain_uncertainty)
    stated = StatedUncertainty(location=unc.location, angle=unc.angle, gain=unc.gain)
    criterion = args.criterion + (" with K" if args.with_stiffness else "")
    try:
        inputs = load_inputs(args.model, args.candidates, result=args.result,
                             geometry=args.geometry, first_elastic=args.first_elastic)
        cond = conditions(inputs, noise, args.averages, stated)
        design = plan_layout(inputs, args.sensors, args.points, cond, args.criterion,
                             args.with_stiffness)
        data = plan_data(inputs, design.layout.sensors, design.layout.excitations,
                         design.prediction, cond, criterion)
        parse_plan(data, str(args.out))
    except (PlanInputError, PlanningError, PlanError) as err:
        raise UserError(str(err)) from err
    header = (f"written by insitu plan ({args.criterion}-optimal; {args.sensors} sensors, "
              f"{args.points} excitations);\n[prediction] holds the predicted standard "
              "deviations (SI) the report shows beside the achieved ones")
    write_output(args.out, plan_toml(data, header))
    _print(design, data, args)
    return 0


def _print(design: Any, data: dict[str, Any], args: argparse.Namespace) -> None:
    from rich.console import Console
    from rich.table import Table

    from app.report.tables import predicted_rows

    pred = design.prediction
    con = Console()
    con.print(f"[bold]{args.out}[/bold]: {len(data['response'])} triaxial sensors, "
              f"{len(data['excitation'])} excitations; {design.criterion}-optimal"
              f"{' with K' if design.with_stiffness else ''} criterion "
              f"{design.layout.value:.4g} ({design.layout.steps} steps); cond(E) "
              f"{pred.geometry.cond_E:.1f}, cond(T) {pred.geometry.cond_T:.1f}; predicted "
              f"mass line {pred.mass_band[0]:.1f}-{pred.mass_band[1]:.1f} Hz")
    t = Table(title="chosen layout")
    t.add_column("kind")
    t.add_column("node", justify="right")
    t.add_column("xyz, m")
    t.add_column("direction / channels")
    for r in data["response"]:
        t.add_row("sensor", str(r["node"]), _vec(r["xyz"]), ", ".join(r["channels"]))
    for e in data["excitation"]:
        t.add_row("excitation", str(e["node"]), _vec(e["xyz"]), _vec(e["direction"]))
    con.print(t)
    u = Table(title="predicted standard deviation (the identification's own uncertainty)")
    for h in ("number", "unit", "std", "95 %"):
        u.add_column(h, justify="left" if h in ("number", "unit") else "right")
    for row in predicted_rows(pred.std):
        u.add_row(*row)
    con.print(u)
    con.print("sources: " + "; ".join(pred.sources))


def _vec(v: Any) -> str:
    return "[" + ", ".join(f"{x:.3g}" for x in v) + "]"


