"""The inputs of ``insitu plan`` (docs/planning.md): the approximate model (TOML, or an earlier
result JSON) and the candidate sensors and excitation points (TOML, or a UFF file's nodes).

Model file::

    [model]
    mass = 110.0                      # kg
    cog = [0.02, 0.20, 0.13]          # m, the guess
    inertia_cog = [[5, 0, 0], [0, 8, 0], [0, 0, 9]]   # kg m^2, or:
    box = [0.48, 0.36, 0.36]          # m, a uniform box's size gives the inertia guess
    first_elastic_hz = 250.0          # optional: the unit's expected first elastic mode

    [[mount]]
    position = [-0.15, 0.05, -0.05]   # m
    axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]   # optional: rows u, v, w (global axes)
    rates = [2e5, 2e5, 6e5]           # N/m along u, v, w (rough)
    loss_factors = [0.1, 0.1, 0.1]    # optional (0.1 each)

Candidates file (``[plan]``, ``[record]``, ``[shaker]`` are copied into the plan as they are)::

    [[sensor]]
    node = 1
    xyz = [0.2, 0.0, 0.26]
    channels = ["a1x", "a1y", "a1z"]  # optional (a1x.. by the chosen order)

    [[point]]
    node = 101
    xyz = [0.25, 0.1, 0.2]
    directions = [[-1, 0, 0], [0, 0, -1]]   # the force directions the hammer reaches there

Every error is one line naming the file and the key.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from processing.planning import ApproximateModel, Candidates, box_inertia, mount_stiffness

__all__ = ["PlanInputError", "candidates_from_uff", "load_candidates", "load_model",
           "model_from_result"]


class PlanInputError(ValueError):
    """A planning input file is missing or wrong (one line naming the key)."""


def _toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise PlanInputError(f"{path}: not valid TOML: {err}") from err
    except OSError as err:
        raise PlanInputError(f"{path}: cannot read it: {err.strerror or err}") from err


def _keys(src: str, where: str, t: Any, allowed: set[str]) -> dict[str, Any]:
    if not isinstance(t, dict):
        raise PlanInputError(f"{src}: {where}: must be a table")
    bad = sorted(set(t) - allowed)
    if bad:
        raise PlanInputError(f"{src}: {where}.{bad[0]}: unknown key; allowed: "
                             f"{', '.join(sorted(allowed))}")
    return t


def _array(src: str, key: str, v: Any, shape: tuple[int, ...], *, positive: bool = False
           ) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if v is None:
        raise PlanInputError(f"{src}: {key}: missing")
    if a.shape != shape or not np.all(np.isfinite(a)) or (positive and np.any(a <= 0)):
        what = "positive numbers" if positive else "numbers"
        raise PlanInputError(f"{src}: {key}: must be {what} of shape {shape}, got {v!r}")
    return a


def load_model(path: str | Path) -> ApproximateModel:
    """The approximate model of a model file (see the module's docstring)."""
    p = Path(path)
    data = _keys(str(p), "file", _toml(p), {"model", "mount"})
    src = str(p)
    m = _keys(src, "model", data.get("model", {}), {"mass", "cog", "inertia_cog", "box",
                                                     "first_elastic_hz"})
    mass = float(_array(src, "model.mass", m.get("mass"), (), positive=True))
    cog = _array(src, "model.cog", m.get("cog"), (3,))
    if ("inertia_cog" in m) == ("box" in m):
        raise PlanInputError(f"{src}: model: give inertia_cog or box (one of them)")
    J = (_array(src, "model.inertia_cog", m["inertia_cog"], (3, 3)) if "inertia_cog" in m
         else box_inertia(mass, _array(src, "model.box", m["box"], (3,), positive=True)))
    fe = m.get("first_elastic_hz")
    fe = None if fe is None else float(_array(src, "model.first_elastic_hz", fe, (),
                                              positive=True))
    mounts = data.get("mount")
    if not isinstance(mounts, list) or len(mounts) < 3:
        raise PlanInputError(f"{src}: mount: give at least three [[mount]] tables (their "
                             "positions and rough rates)")
    K, D = np.zeros((6, 6)), np.zeros((6, 6))
    for i, mt in enumerate(mounts):
        key = f"mount[{i}]"
        mt = _keys(src, key, mt, {"name", "position", "axes", "rates", "loss_factors"})
        axes = _array(src, f"{key}.axes", mt.get("axes", np.eye(3).tolist()), (3, 3))
        k, d = mount_stiffness(_array(src, f"{key}.position", mt.get("position"), (3,)),
                               axes, _array(src, f"{key}.rates", mt.get("rates"), (3,),
                                            positive=True),
                               _array(src, f"{key}.loss_factors",
                                      mt.get("loss_factors", [0.1] * 3), (3,)))
        K, D = K + k, D + d
    try:
        return ApproximateModel(mass, cog, J, K, D, first_elastic_hz=fe)
    except ValueError as err:
        raise PlanInputError(f"{src}: {err}") from err


def model_from_result(path: str | Path) -> ApproximateModel:
    """The approximate model of an earlier test's result JSON (mass, cog, inertia_cog,
    stiffness, damping)."""
    p = Path(path)
    try:
        r = json.loads(p.read_text(encoding="utf-8"))
    except OSError as err:
        raise PlanInputError(f"{p}: cannot read it: {err.strerror or err}") from err
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise PlanInputError(f"{p}: not a result JSON: {err}") from err
    if not isinstance(r, dict):
        raise PlanInputError(f"{p}: not a result JSON (an object)")
    src = str(p)
    try:
        return ApproximateModel(
            float(_array(src, "mass", r.get("mass"), (), positive=True)),
            _array(src, "cog", r.get("cog"), (3,)),
            _array(src, "inertia_cog", r.get("inertia_cog"), (3, 3)),
            _array(src, "stiffness", r.get("stiffness"), (6, 6)),
            C=_array(src, "damping", r.get("damping", np.zeros((6, 6)).tolist()), (6, 6)))
    except ValueError as err:
        raise PlanInputError(f"{src}: {err}") from err


def load_candidates(path: str | Path) -> tuple[Candidates, dict[str, Any]]:
    """Candidates of a candidates file, and its plan tables ([plan], [record], [shaker])
    with ``sensor_channels`` (node -> channel names) for the plan writer."""
    p = Path(path)
    src = str(p)
    data = _keys(src, "file", _toml(p), {"sensor", "point", "plan", "record", "shaker"})
    sensors, points = data.get("sensor"), data.get("point")
    if not isinstance(sensors, list) or not sensors:
        raise PlanInputError(f"{src}: sensor: give the candidate sensors as [[sensor]] tables")
    if not isinstance(points, list) or not points:
        raise PlanInputError(f"{src}: point: give the candidate points as [[point]] tables")
    coords: dict[int, np.ndarray] = {}

    def node(key: str, t: dict[str, Any]) -> tuple[int, np.ndarray]:
        n = t.get("node")
        if isinstance(n, bool) or not isinstance(n, int):
            raise PlanInputError(f"{src}: {key}.node: must be an integer node id, got {n!r}")
        xyz = _array(src, f"{key}.xyz", t.get("xyz"), (3,))
        if n in coords and not np.allclose(coords[n], xyz):
            raise PlanInputError(f"{src}: {key}.node: node {n} is given two different xyz")
        coords[n] = xyz
        return n, xyz

    sn, sx, channels = [], [], {}
    for i, t in enumerate(sensors):
        key = f"sensor[{i}]"
        t = _keys(src, key, t, {"node", "xyz", "channels"})
        n, xyz = node(key, t)
        if n in sn:
            raise PlanInputError(f"{src}: {key}.node: sensor node {n} is given twice")
        sn.append(n)
        sx.append(xyz)
        if "channels" in t:
            ch = t["channels"]
            if not (isinstance(ch, list) and len(ch) == 3 and all(isinstance(c, str) and c
                                                                  for c in ch)):
                raise PlanInputError(f"{src}: {key}.channels: must be three station channel "
                                     "names (x, y, z)")
            channels[n] = ch
    pn, px, ep, ed = [], [], [], []
    for i, t in enumerate(points):
        key = f"point[{i}]"
        t = _keys(src, key, t, {"node", "xyz", "directions"})
        n, xyz = node(key, t)
        dirs = t.get("directions")
        if not isinstance(dirs, list) or not dirs:
            raise PlanInputError(f"{src}: {key}.directions: give the force directions the "
                                 "operator can reach there, e.g. [[0, 0, -1]]")
        d = _array(src, f"{key}.directions", dirs, (len(dirs), 3))
        if np.any(np.linalg.norm(d, axis=1) == 0):
            raise PlanInputError(f"{src}: {key}.directions: a direction is zero")
        pn.append(n)
        px.append(xyz)
        ep += [len(pn) - 1] * d.shape[0]
        ed += list(d)
    template: dict[str, Any] = {k: data[k] for k in ("plan", "record", "shaker") if k in data}
    template["sensor_channels"] = channels
    return Candidates(np.array(sn), np.array(sx), np.array(pn), np.array(px), np.array(ep),
                      np.array(ed)), template


def candidates_from_uff(path: str | Path) -> Candidates:
    """Every node of a UFF file's geometry as a candidate sensor and a candidate point,
    the point reachable along the six global half-axes."""
    from app.io.uff_geometry import read_geometry_uff

    try:
        geo, _ = read_geometry_uff(path)
    except (OSError, ValueError) as err:
        raise PlanInputError(f"{path}: cannot read its geometry: {err}") from err
    ids = np.asarray(geo.node_ids, dtype=np.int64)
    xyz = np.asarray(geo.xyz, dtype=float)
    if ids.size == 0:
        raise PlanInputError(f"{path}: the file holds no node (dataset 15 or 2411)")
    axes = np.vstack([np.eye(3), -np.eye(3)])
    return Candidates(ids, xyz, ids, xyz, np.repeat(np.arange(ids.size), 6),
                      np.tile(axes, (ids.size, 1)))
