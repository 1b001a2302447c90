"""A planned test, one way through for ``insitu plan`` and the GUI's planner
(docs/planning.md): the inputs read once, the layout chosen by
:func:`processing.planning.plan_test`, an edited layout predicted by
:func:`processing.planning.predict`, and the acquisition plan's data with its
``[prediction]`` table.

>>> inputs = load_inputs(Path("model.toml"), Path("cand.toml"))      # doctest: +SKIP
>>> cond = conditions(inputs, noise=0.01, stated=StatedUncertainty(location=0.002))
>>> design = plan_layout(inputs, 4, 9, cond)                         # doctest: +SKIP
>>> data = plan_data(inputs, design.layout.sensors, design.layout.excitations,
...                  design.prediction, cond, "D")                   # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from app.acquire.plan import TestPlan, parse_plan
from app.io.planning import candidates_from_uff, load_candidates, load_model, model_from_result
from processing.montecarlo import StatedUncertainty
from processing.planning import (
    ApproximateModel,
    Candidates,
    Criterion,
    PlanningError,
    Prediction,
    TestConditions,
    TestDesign,
    plan_test,
    predict,
)

__all__ = ["PREDICTED_KEYS", "PlanInputs", "conditions", "load_inputs", "plan_data",
           "plan_layout", "predict_layout"]

#: the predicted std a plan's ``[prediction]`` table keeps (SI)
PREDICTED_KEYS = ("mass", "cog", "inertia_cog", "inertia_origin", "principal_moments",
                  "stiffness")


@dataclass(frozen=True)
class PlanInputs:
    """What a planning starts from: the approximate model, the candidates, and the
    candidates file's plan tables (``[plan]``, ``[record]``, ``[shaker]``,
    ``sensor_channels``); ``source`` names the candidates' file."""

    model: ApproximateModel
    candidates: Candidates
    template: dict[str, Any]
    source: str


def load_inputs(model: Path | None, candidates: Path | None, *, result: Path | None = None,
                geometry: Path | None = None, first_elastic: float | None = None
                ) -> PlanInputs:
    """Read the model (a model TOML, or ``result``: an earlier result JSON) and the
    candidates (a candidates TOML, or ``geometry``: a UFF file's nodes); ``first_elastic``
    (Hz) replaces the model's expected first elastic mode. One-line
    :class:`~app.io.planning.PlanInputError` on a bad file."""
    if (model is None) == (result is None) or (candidates is None) == (geometry is None):
        raise PlanningError("give one model (model TOML or result JSON) and one candidates "
                            "source (candidates TOML or UFF geometry)")
    approx = load_model(model) if model is not None else model_from_result(Path(str(result)))
    if first_elastic is not None:
        approx = dataclasses.replace(approx, first_elastic_hz=first_elastic)
    if candidates is not None:
        cand, template = load_candidates(candidates)
        source = str(candidates)
    else:
        assert geometry is not None
        cand, template, source = candidates_from_uff(geometry), {}, str(geometry)
    inputs = PlanInputs(approx, cand, template, source)
    template_plan(inputs)  # the copied [plan], [record], [shaker] checked now
    return inputs


def template_plan(inputs: PlanInputs) -> TestPlan:
    """The candidates file's plan with every candidate (its record and shaker settings)."""
    n_s, n_e = inputs.candidates.sensor_nodes.size, inputs.candidates.exc_point.size
    return parse_plan(_data(inputs, range(n_s), range(n_e)), inputs.source)


def _lines(plan: TestPlan) -> NDArray[np.float64]:
    """The analyser's lines of a plan: 1/length to fs/2.56 (hammer), the shaker's band."""
    if plan.method == "shaker":
        df = plan.record.fs / plan.shaker.nperseg
        lo, hi = plan.shaker.f_start, plan.shaker.f_stop
    else:
        df = 1.0 / plan.record.length
        lo, hi = df, plan.record.fs / 2.56
    f = df * np.arange(1, int(hi / df) + 1)
    return np.asarray(f[f >= lo], dtype=np.float64)


def conditions(inputs: PlanInputs, noise: float, averages: int | None = None,
               stated: StatedUncertainty | None = None) -> TestConditions:
    """How the test will measure: the plan's lines, ``noise`` (relative to each record's
    RMS), ``averages`` (default the plan's hits, or its shaker averages) and the stated
    test uncertainties."""
    plan = template_plan(inputs)
    n = averages or (plan.shaker.averages if plan.method == "shaker" else plan.hits)
    return TestConditions(_lines(plan), noise=noise, averages=n,
                          stated=stated or StatedUncertainty())


def plan_layout(inputs: PlanInputs, n_sensors: int, n_points: int, cond: TestConditions,
                criterion: Criterion = "D", with_stiffness: bool = False) -> TestDesign:
    """Choose the layout and predict it (:func:`processing.planning.plan_test`)."""
    return plan_test(inputs.model, inputs.candidates, n_sensors, n_points, cond,
                     criterion=criterion, with_stiffness=with_stiffness)


def predict_layout(inputs: PlanInputs, sensors: Sequence[int], excitations: Sequence[int],
                   cond: TestConditions) -> Prediction:
    """The prediction of a layout the operator edited: candidate sensor indices and
    candidate excitation indices (:func:`processing.planning.predict`, as
    :func:`plan_layout` predicts its own)."""
    c = inputs.candidates
    S, P = [int(i) for i in sensors], [int(i) for i in excitations]
    if not S or not P:
        raise PlanningError(f"the layout needs sensors and excitations, it has {len(S)} "
                            f"sensors and {len(P)} excitations: add candidates")
    return predict(inputs.model, c.sensor_xyz[S], c.exc_xyz[P], c.exc_dirs[P], cond,
                   resp_nodes=c.sensor_nodes[S], exc_nodes=c.exc_nodes[P])


def plan_data(inputs: PlanInputs, sensors: Sequence[int], excitations: Sequence[int],
              prediction: Prediction | None, cond: TestConditions, criterion: str
              ) -> dict[str, Any]:
    """The acquisition plan's data for a layout (``plan_toml`` writes it, ``parse_plan``
    reads it), with the ``[prediction]`` table when ``prediction`` is given: the
    criterion (a word), the stated noise and uncertainties, cond(E), cond(T), the
    predicted mass line and the predicted std (SI) of :data:`PREDICTED_KEYS`."""
    data = _data(inputs, sensors, excitations)
    if prediction is not None:
        s = cond.stated
        data["prediction"] = {
            "criterion": criterion, "noise": cond.noise, "averages": cond.averages,
            "location_uncertainty": s.location, "angle_uncertainty": s.angle,
            "gain_uncertainty": s.gain, "cond_E": prediction.geometry.cond_E,
            "cond_T": prediction.geometry.cond_T, "mass_band": list(prediction.mass_band),
            **{k: np.asarray(v).tolist() for k, v in prediction.std.items()
               if k in PREDICTED_KEYS}}
    return data


def _data(inputs: PlanInputs, sensors: Sequence[int], excitations: Sequence[int]
          ) -> dict[str, Any]:
    """Plan data: the template's [plan], [record], [shaker] (defaults: a hammer test at
    1024 Hz, 2 s records, 3 hits), and the given candidates' points."""
    cand, template = inputs.candidates, inputs.template
    names = template.get("sensor_channels", {})
    out: dict[str, Any] = {
        "plan": {"name": "planned test", "method": "hammer", "hits": 3,
                 **template.get("plan", {})},
        "record": {"fs": 1024.0, "length": 2.0, **template.get("record", {})},
    }
    if "shaker" in template:
        out["shaker"] = dict(template["shaker"])
    out["excitation"] = [{"node": int(cand.exc_nodes[i]), "xyz": cand.exc_xyz[i].tolist(),
                          "direction": cand.exc_dirs[i].tolist()} for i in excitations]
    out["response"] = [{"node": int(cand.sensor_nodes[i]), "xyz": cand.sensor_xyz[i].tolist(),
                        "channels": names.get(int(cand.sensor_nodes[i]),
                                              [f"a{k + 1}{ax}" for ax in "xyz"])}
                       for k, i in enumerate(sensors)]
    return out
