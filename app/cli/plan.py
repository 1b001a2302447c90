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

import numpy as np

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
                   help="expected first elastic mode of the unit (the model file's)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from app.acquire.plan import PlanError, parse_plan, plan_toml
    from app.io.planning import (
        PlanInputError,
        candidates_from_uff,
        load_candidates,
        load_model,
        model_from_result,
    )
    from app.pipeline.settings import RELATIVE_UNITS, TestUncertaintySettings, parse_quantity
    from processing.montecarlo import StatedUncertainty
    from processing.planning import PlanningError, TestConditions, plan_test

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
    try:
        model = (load_model(args.model) if args.model is not None
                 else model_from_result(args.result))
        if args.first_elastic is not None:
            import dataclasses

            model = dataclasses.replace(model, first_elastic_hz=args.first_elastic)
        if args.candidates is not None:
            cand, template = load_candidates(args.candidates)
        else:
            cand, template = candidates_from_uff(args.geometry), {}
        plan0 = parse_plan(_plan_data(template, cand), str(args.candidates or args.geometry))
        averages = args.averages or (plan0.shaker.averages if plan0.method == "shaker"
                                     else plan0.hits)
        conditions = TestConditions(_lines(plan0), noise=noise, averages=averages,
                                    stated=stated)
        design = plan_test(model, cand, args.sensors, args.points, conditions,
                           criterion=args.criterion, with_stiffness=args.with_stiffness)
    except (PlanInputError, PlanningError, PlanError) as err:
        raise UserError(str(err)) from err
    pred = design.prediction
    assert pred is not None
    S, P = list(design.layout.sensors), list(design.layout.excitations)
    data = _plan_data(template, cand, S, P)
    data["prediction"] = {
        "criterion": args.criterion + (" with K" if args.with_stiffness else ""),
        "noise": noise, "averages": averages, "location_uncertainty": stated.location,
        "angle_uncertainty": stated.angle, "gain_uncertainty": stated.gain,
        "cond_E": pred.geometry.cond_E, "cond_T": pred.geometry.cond_T,
        "mass_band": list(pred.mass_band),
        **{k: np.asarray(v).tolist() for k, v in pred.std.items()
           if k in ("mass", "cog", "inertia_cog", "inertia_origin", "principal_moments",
                    "stiffness")}}
    try:
        parse_plan(data, str(args.out))
    except PlanError as err:
        raise UserError(str(err)) from err
    header = (f"written by insitu plan ({args.criterion}-optimal; {args.sensors} sensors, "
              f"{args.points} excitations);\n[prediction] holds the predicted standard "
              "deviations (SI) the report shows beside the achieved ones")
    write_output(args.out, plan_toml(data, header))
    _print(design, data, args)
    return 0


def _lines(plan: Any) -> np.ndarray:
    """The analyser's lines of a plan: 1/length to fs/2.56 (hammer), the shaker's band."""
    if plan.method == "shaker":
        df = plan.record.fs / plan.shaker.nperseg
        lo, hi = plan.shaker.f_start, plan.shaker.f_stop
    else:
        df = 1.0 / plan.record.length
        lo, hi = df, plan.record.fs / 2.56
    f = df * np.arange(1, int(hi / df) + 1)
    return f[f >= lo]


def _plan_data(template: dict[str, Any], cand: Any, sensors: list[int] | None = None,
               points: list[int] | None = None) -> dict[str, Any]:
    """Plan data: the template's [plan], [record], [shaker] (defaults: a hammer test at
    1024 Hz, 2 s records, 3 hits), and the chosen (or every candidate's) points."""
    S = range(cand.sensor_nodes.size) if sensors is None else sensors
    P = range(cand.exc_point.size) if points is None else points
    names = template.get("sensor_channels", {})
    out: dict[str, Any] = {
        "plan": {"name": "planned test", "method": "hammer", "hits": 3,
                 **template.get("plan", {})},
        "record": {"fs": 1024.0, "length": 2.0, **template.get("record", {})},
    }
    if "shaker" in template:
        out["shaker"] = dict(template["shaker"])
    out["excitation"] = [{"node": int(cand.exc_nodes[i]), "xyz": cand.exc_xyz[i].tolist(),
                          "direction": cand.exc_dirs[i].tolist()} for i in P]
    out["response"] = [{"node": int(cand.sensor_nodes[i]), "xyz": cand.sensor_xyz[i].tolist(),
                        "channels": names.get(int(cand.sensor_nodes[i]),
                                              [f"a{k + 1}{ax}" for ax in "xyz"])}
                       for k, i in enumerate(S)]
    return out


def _print(design: Any, data: dict[str, Any], args: argparse.Namespace) -> None:
    from rich.console import Console
    from rich.table import Table

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
    u.add_column("number")
    u.add_column("std", justify="right")
    s = pred.std
    u.add_row("mass", f"{float(s['mass']):.3g} kg")
    for k, ax in enumerate("xyz"):
        u.add_row(f"CoG {ax}", f"{s['cog'][k] * 1000:.3g} mm")
    J = s["inertia_cog"]
    for (i, j), name in zip(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)),
                            ("Jxx", "Jyy", "Jzz", "Jxy", "Jxz", "Jyz"), strict=True):
        u.add_row(f"{name} about the CoG", f"{J[i, j]:.3g} kg m^2")
    K = s["stiffness"]
    for k, name in enumerate(("x", "y", "z", "rx", "ry", "rz")):
        u.add_row(f"K {name}{name}", f"{K[k, k]:.3g}")
    con.print(u)
    con.print("sources: " + "; ".join(pred.sources))


def _vec(v: Any) -> str:
    return "[" + ", ".join(f"{x:.3g}" for x in v) + "]"


