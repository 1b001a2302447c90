"""The test plan: where to excite, where the responses are measured, and how to record.

A plan is a TOML file::

    [plan]
    name = "engine"
    method = "hammer"            # or "shaker"
    hits = 3                     # accepted hits (hammer) per excitation point

    [record]
    fs = 1024                    # Hz, sample rate of the front end
    length = 2.0                 # s, record length per hit (line spacing 1/length Hz)
    pretrigger = 0.05            # s kept before the trigger
    trigger_level = 20.0         # N, force trigger level (rising)
    exp_tau = 0.0                # s, exponential window (0: none)

    [shaker]                     # method = "shaker" only
    waveform = "random"          # random, burst-random, chirp
    level = 0.5                  # V RMS (random) or V peak
    f_start = 2.0                # Hz
    f_stop = 200.0               # Hz, at most record.fs / 2 (Nyquist)
    averages = 20
    nperseg = 2048               # samples per block (line spacing fs/nperseg; chirp period)
    ramp = 1.0                   # s, output ramp up and down
    settle = 1.0                 # s streamed after the ramp before the first block
    duty = 0.5                   # burst random: fraction of each block the burst is on
    shakers = 1                  # shakers driven at once (multiple-reference H1)

    [[excitation]]
    node = 101
    xyz = [0.25, 0.10, 0.20]     # m
    direction = [1, 0, 0]        # force direction, global frame

    [[response]]
    node = 1
    xyz = [0.20, 0.00, 0.26]
    channels = ["a1x", "a1y", "a1z"]   # station channels that measure this point

Response directions come from the station channels (their ``direction``).

With ``shakers = 2`` (or more) the ``[[excitation]]`` tables are taken ``shakers`` at a
time, in order: with two, the first two are driven together (one shaker each, different
random signals, correlated or not), then the next two, and so on. Each such *drive* is
one stop of the test: its blocks hold every force (the front end's force channels, in
plan order) then the responses, and one multiple-reference H1 (``H = G_xf G_ff^-1``)
gives one FRF column per excitation driven; ``averages`` counts blocks per drive. With
one shaker each drive is one excitation. Random or burst-random only (each shaker its
own signal; burst random needs generators that start their bursts together), and more
blocks per drive than shakers.

Every error is one line naming the key, as ``plan.toml: record.fs: must be > 0, got -1``.

Example
-------
>>> plan = parse_plan({"plan": {"method": "hammer"}, "record": {"fs": 1024, "length": 1.0,
...     "trigger_level": 10.0}, "excitation": [{"node": 9, "xyz": [0, 0, 0],
...     "direction": [0, 0, 1]}], "response": [{"node": 1, "xyz": [0, 0, 0],
...     "channels": ["a1z"]}]})
>>> plan.record.n_samples
1024
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from drivers.base import ChannelConfig
from drivers.errors import one_line
from drivers.station import StationConfig
from processing.data import Geometry
from processing.geometry import GeometryReport, check_geometry

__all__ = [
    "ExcitationPoint",
    "PlanError",
    "RecordSettings",
    "ResponsePoint",
    "ShakerSettings",
    "TestPlan",
    "load_plan",
    "parse_plan",
    "plan_differences",
    "plan_toml",
]

Method = Literal["hammer", "shaker"]


class PlanError(ValueError):
    """The test plan is invalid or does not fit the station; one line naming the key."""


@dataclass(frozen=True)
class ExcitationPoint:
    """Where and along which direction the structure is excited.

    Attributes
    ----------
    index : int
        Position in the plan (0-based).
    node : int
        Node id of the excitation DOF.
    xyz : (3,) tuple of float
        Coordinates in the global frame, m.
    direction : (3,) tuple of float
        Unit vector of the force in the global frame.
    """

    index: int
    node: int
    xyz: tuple[float, float, float]
    direction: tuple[float, float, float]

    @property
    def label(self) -> str:
        d = "".join(f"{c:+.2g}" for c in self.direction)
        return f"point {self.index + 1} (node {self.node}, dir {d})"


@dataclass(frozen=True)
class ResponsePoint:
    """A measurement point and the station channels that measure it (xyz in m)."""

    node: int
    xyz: tuple[float, float, float]
    channels: tuple[str, ...]


@dataclass(frozen=True)
class RecordSettings:
    """Recording settings.

    Attributes
    ----------
    fs : float
        Sample rate of the front end (the reference clock), Hz.
    length : float
        Record length per hit, s (line spacing ``1 / length`` Hz).
    pretrigger : float
        Time kept before the trigger, s.
    trigger_level : float
        Force trigger level, N (rising edge).
    exp_tau : float or None
        Exponential window time constant, s; None for no window.
    estimator : {"H1", "H2", "Hv"}
    """

    fs: float
    length: float
    pretrigger: float = 0.05
    trigger_level: float = 20.0
    exp_tau: float | None = None
    estimator: str = "H1"

    @property
    def n_samples(self) -> int:
        """Samples per record."""
        return round(self.length * self.fs)

    @property
    def n_pretrigger(self) -> int:
        return round(self.pretrigger * self.fs)


@dataclass(frozen=True)
class ShakerSettings:
    """Shaker drive and averaging.

    Attributes
    ----------
    waveform : {"random", "burst-random", "chirp"}
    level : float
        V RMS (random, burst random) or V peak (chirp).
    f_start, f_stop : float
        Band of the random signal, sweep of the chirp, Hz.
    averages : int
        Accepted blocks per excitation point.
    nperseg : int
        Samples per block (line spacing ``fs / nperseg`` Hz); the chirp's and the
        burst's period is one block.
    ramp : float
        Output ramp time up and down, s.
    settle : float
        Time streamed after the ramp before the first block (transients die out), s.
    duty : float
        Burst random: fraction of each block the burst is on (the rest lets the
        response decay).
    shakers : int
        Shakers driven at once, each at its own excitation point (see the module doc).
    """

    waveform: str = "random"
    level: float = 0.5
    f_start: float = 2.0
    f_stop: float = 200.0
    averages: int = 20
    nperseg: int = 2048
    ramp: float = 1.0
    settle: float = 1.0
    duty: float = 0.5
    shakers: int = 1


@dataclass(frozen=True)
class TestPlan:
    """A whole test plan; see the module docstring for the file format."""

    name: str
    method: Method
    hits: int
    record: RecordSettings
    excitations: tuple[ExcitationPoint, ...]
    responses: tuple[ResponsePoint, ...]
    shaker: ShakerSettings = field(default_factory=ShakerSettings)
    source: str = "plan.toml"
    #: ``[prediction]``: what ``insitu plan`` predicted for this layout (criterion, the
    #: test's stated noise and uncertainties, the std of mass, cog, inertia_cog, stiffness);
    #: kept and shown beside the achieved uncertainty, never used to acquire
    prediction: dict[str, Any] | None = None

    __test__ = False  # not a pytest test class

    def geometry(self) -> Geometry:
        """Node ids and coordinates (m) of every response and excitation node."""
        nodes: dict[int, tuple[float, float, float]] = {}
        points: list[ResponsePoint | ExcitationPoint] = [*self.responses, *self.excitations]
        for p in points:
            if p.node in nodes and not np.allclose(nodes[p.node], p.xyz):
                raise PlanError(f"{self.source}: node {p.node} is given two different xyz")
            nodes[p.node] = p.xyz
        ids = sorted(nodes)
        return Geometry(np.array(ids, dtype=np.int64), np.array([nodes[i] for i in ids]))

    @property
    def n_references(self) -> int:
        """Force channels per record: the shakers driven at once (1 for a hammer)."""
        return self.shaker.shakers if self.method == "shaker" else 1

    @property
    def drives(self) -> tuple[tuple[int, ...], ...]:
        """The excitation indices driven together, stop by stop (one each with one shaker)."""
        k, n = self.n_references, len(self.excitations)
        return tuple(tuple(range(i, i + k)) for i in range(0, n, k))

    @property
    def stop_word(self) -> str:
        """What one of :attr:`drives` is called to the operator: "point" (one force), or
        "drive" (the points two or more shakers drive together)."""
        return "point" if self.n_references == 1 else "drive"

    @property
    def exc_nodes(self) -> NDArray[np.int64]:
        return np.array([e.node for e in self.excitations], dtype=np.int64)

    @property
    def exc_dirs(self) -> NDArray[np.float64]:
        return np.array([e.direction for e in self.excitations], dtype=float)

    def response_channels(self, station: StationConfig) -> tuple[ChannelConfig, ...]:
        """The station channels of every response point, in plan order."""
        by_name = {c.name: c for d in station.devices.values() for c in d.channels}
        out = []
        for i, r in enumerate(self.responses):
            for name in r.channels:
                ch = by_name.get(name)
                if ch is None:
                    raise PlanError(f"{self.source}: response[{i}].channels: station "
                                    f"{station.source} has no channel {name!r}")
                if ch.quantity != "acceleration" or ch.direction is None:
                    raise PlanError(f"{self.source}: response[{i}].channels: {name!r} must be "
                                    "an acceleration channel with a direction in the station")
                out.append(ch)
        return tuple(out)

    def response_dofs(self, station: StationConfig
                      ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Node id and unit direction of every response DOF, in plan order."""
        chans = self.response_channels(station)
        node_of = {n: r.node for r in self.responses for n in r.channels}
        nodes = np.array([node_of[c.name] for c in chans], dtype=np.int64)
        dirs = np.array([c.direction for c in chans], dtype=float)
        return nodes, dirs

    def check(self, station: StationConfig, strict: bool = True) -> GeometryReport:
        """Rank and condition of E and T; raises PlanError when they cannot span 6 DOFs
        (``strict=False``: only report it, for partial plans measured in several runs)."""
        nodes, dirs = self.response_dofs(station)
        g = self.geometry()
        rep = check_geometry(g.coordinates(nodes), dirs, g.coordinates(self.exc_nodes),
                             self.exc_dirs)
        if strict and not rep.ok:
            raise PlanError(f"{self.source}: {'; '.join(rep.messages)}")
        return rep

    def to_dict(self) -> dict[str, Any]:
        """The plan as TOML-like data; ``parse_plan(plan.to_dict())`` gives it back."""
        rec: dict[str, Any] = {"fs": self.record.fs, "length": self.record.length,
                               "pretrigger": self.record.pretrigger,
                               "trigger_level": self.record.trigger_level,
                               "exp_tau": self.record.exp_tau or 0.0,
                               "estimator": self.record.estimator}
        s = self.shaker
        extra = {} if self.prediction is None else {"prediction": dict(self.prediction)}
        return {
            **extra,
            "plan": {"name": self.name, "method": self.method, "hits": self.hits},
            "record": rec,
            "shaker": {"waveform": s.waveform, "level": s.level, "f_start": s.f_start,
                       "f_stop": s.f_stop, "averages": s.averages, "nperseg": s.nperseg,
                       "ramp": s.ramp, "settle": s.settle, "duty": s.duty,
                       "shakers": s.shakers},
            "excitation": [{"node": e.node, "xyz": list(e.xyz), "direction": list(e.direction)}
                           for e in self.excitations],
            "response": [{"node": r.node, "xyz": list(r.xyz), "channels": list(r.channels)}
                         for r in self.responses],
        }


class _Ctx:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, key: str, msg: str) -> PlanError:
        return PlanError(one_line(f"{self.source}: {key}: {msg}"))

    def table(self, data: Mapping[str, Any], name: str, allowed: set[str]) -> dict[str, Any]:
        t = data.get(name, {})
        if not isinstance(t, dict):
            raise self.fail(name, f"must be a table, got {type(t).__name__}")
        extra = sorted(set(t) - allowed)
        if extra:
            raise self.fail(f"{name}.{extra[0]}",
                            f"unknown key; allowed: {', '.join(sorted(allowed))}")
        return t

    def number(self, t: Mapping[str, Any], name: str, key: str, default: Any = None, *,
               integer: bool = False, minimum: float = 0.0, strict: bool = True) -> Any:
        if name not in t:
            if default is None:
                raise self.fail(f"{key}.{name}", "missing")
            return default
        v = t[name]
        types = (int,) if integer else (int, float)
        if isinstance(v, bool) or not isinstance(v, types) or not np.isfinite(v):
            raise self.fail(f"{key}.{name}",
                            f"must be {'an integer' if integer else 'a number'}, got {v!r}")
        if (v <= minimum) if strict else (v < minimum):
            raise self.fail(f"{key}.{name}", f"must be {'>' if strict else '>='} {minimum:g}, "
                            f"got {v!r}")
        return v

    def vector(self, t: Mapping[str, Any], name: str, key: str, *, nonzero: bool
               ) -> tuple[float, float, float]:
        v = t.get(name)
        if (not isinstance(v, list) or len(v) != 3
                or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
                or not all(np.isfinite(v))):
            raise self.fail(f"{key}.{name}", "missing" if v is None else
                            f"must be [x, y, z] numbers, got {v!r}")
        a = np.asarray(v, dtype=float)
        if nonzero:
            big = float(np.abs(a).max())
            if big == 0:
                raise self.fail(f"{key}.{name}", "must be a non-zero direction")
            a = a / big  # scaled first: the norm of [1e200, 0, 1] does not overflow
            a = a / float(np.linalg.norm(a))
        return (float(a[0]), float(a[1]), float(a[2]))

    def node(self, t: Mapping[str, Any], key: str) -> int:
        v = t.get("node")
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(f"{key}.node", "missing" if v is None else
                            f"must be an integer node id, got {v!r}")
        return v

    def points(self, data: Mapping[str, Any], name: str) -> list[dict[str, Any]]:
        v = data.get(name)
        if not isinstance(v, list) or not v or not all(isinstance(x, dict) for x in v):
            raise self.fail(name, f"missing: give at least one [[{name}]] table")
        return v


_TOP = {"plan", "record", "shaker", "excitation", "response", "prediction"}

#: ``[prediction]`` keys (numbers, or nested lists of numbers for the std arrays; texts for
#: the criterion and what was propagated)
_PREDICTION = {"criterion": str, "sources": list, "noise": float, "averages": int,
               "location_uncertainty": float, "angle_uncertainty": float,
               "gain_uncertainty": float, "cond_E": float, "cond_T": float, "mass": float,
               "cog": list, "inertia_cog": list, "inertia_origin": list,
               "principal_moments": list, "stiffness": list, "mass_band": list}


def _prediction(c: _Ctx, data: Mapping[str, Any]) -> dict[str, Any] | None:
    """The optional ``[prediction]`` table written by ``insitu plan``."""
    if "prediction" not in data:
        return None
    t = c.table(data, "prediction", set(_PREDICTION))
    for key, kind in _PREDICTION.items():
        if key not in t:
            continue
        v = t[key]
        if kind is str:
            ok = isinstance(v, str)
        elif kind is list:
            flat = np.asarray(v, dtype=object).ravel() if isinstance(v, list) else None
            ok = flat is not None and all(
                isinstance(x, str) if key == "sources" else
                isinstance(x, int | float) and not isinstance(x, bool) for x in flat)
        else:
            ok = isinstance(v, int | float) and not isinstance(v, bool) and bool(np.isfinite(v))
        if not ok:
            raise c.fail(f"prediction.{key}", f"must be {kind.__name__}-valued, got {v!r}")
    return dict(t)


def parse_plan(data: Mapping[str, Any], source: str = "plan.toml") -> TestPlan:
    """Validate parsed plan data; raises :class:`PlanError` naming the bad key."""
    c = _Ctx(source)
    extra = sorted(set(data) - _TOP)
    if extra:
        raise c.fail(extra[0], f"unknown key; allowed: {', '.join(sorted(_TOP))}")
    name, method, hits = _plan_table(c, data, source)
    record = _record_settings(c, data, method)
    shaker = _shaker_settings(c, data)
    excs = _excitations(c, data)
    resps = _responses(c, data)
    _check_shakers(c, method, shaker, excs)
    if method == "shaker" and shaker.f_stop > record.fs / 2:
        raise c.fail("shaker.f_stop", f"{shaker.f_stop:g} Hz is above the Nyquist frequency "
                     f"of record.fs = {record.fs:g} Hz ({record.fs / 2:g} Hz): lower "
                     "shaker.f_stop or raise record.fs")
    plan = TestPlan(name, method, hits, record, tuple(excs), tuple(resps), shaker, source,
                    _prediction(c, data))
    plan.geometry()  # nodes with two coordinates
    return plan


def _plan_table(c: _Ctx, data: Mapping[str, Any], source: str) -> tuple[str, Method, int]:
    """The ``[plan]`` table: name (default the file's stem), method and hits."""
    p = c.table(data, "plan", {"name", "method", "hits"})
    name = p.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise c.fail("plan.name", f"must be a string, got {name!r}")
    method = p.get("method", "hammer")
    if method not in ("hammer", "shaker"):
        raise c.fail("plan.method", f"must be 'hammer' or 'shaker', got {method!r}")
    hits = c.number(p, "hits", "plan", 3, integer=True)
    return name, method, int(hits)


def _record_settings(c: _Ctx, data: Mapping[str, Any], method: Method) -> RecordSettings:
    """The ``[record]`` table; a shaker plan without a length records one ``nperseg`` block."""
    r = c.table(data, "record", {"fs", "length", "lines", "pretrigger", "trigger_level",
                                 "exp_tau", "estimator"})
    fs = float(c.number(r, "fs", "record"))
    if "length" in r and "lines" in r:
        raise c.fail("record.lines", "give either length (s) or lines, not both")
    if "lines" in r:
        length = 2 * c.number(r, "lines", "record", integer=True) / fs
    elif method == "shaker" and "length" not in r:  # one block
        nps = data.get("shaker", {}).get("nperseg") if isinstance(data.get("shaker"), dict) \
            else None
        length = (nps if isinstance(nps, int) and not isinstance(nps, bool) and nps > 0
                  else 2048) / fs
    else:
        length = float(c.number(r, "length", "record"))
    pre = float(c.number(r, "pretrigger", "record", 0.05, strict=False))
    if pre >= length:
        raise c.fail("record.pretrigger", f"must be shorter than the record ({length:g} s)")
    level = float(c.number(r, "trigger_level", "record", 20.0))
    tau = float(c.number(r, "exp_tau", "record", 0.0, strict=False)) or None
    est = r.get("estimator", "H1")
    if est not in ("H1", "H2", "Hv"):
        raise c.fail("record.estimator", f"must be H1, H2 or Hv, got {est!r}")
    if round(length * fs) < 64:
        raise c.fail("record.length", f"{length:g} s at {fs:g} Hz is under 64 samples")
    return RecordSettings(fs, length, pre, level, tau, est)


def _shaker_settings(c: _Ctx, data: Mapping[str, Any]) -> ShakerSettings:
    """The ``[shaker]`` table, with its defaults."""
    s = c.table(data, "shaker", {"waveform", "level", "f_start", "f_stop", "averages",
                                 "nperseg", "ramp", "settle", "duty", "shakers"})
    wf = s.get("waveform", "random")
    if wf not in ("random", "burst-random", "chirp"):
        raise c.fail("shaker.waveform", f"must be random, burst-random or chirp, got {wf!r}")
    shaker = ShakerSettings(
        wf, float(c.number(s, "level", "shaker", 0.5)),
        float(c.number(s, "f_start", "shaker", 2.0)),
        float(c.number(s, "f_stop", "shaker", 200.0)),
        int(c.number(s, "averages", "shaker", 20, integer=True)),
        int(c.number(s, "nperseg", "shaker", 2048, integer=True, minimum=8)),
        float(c.number(s, "ramp", "shaker", 1.0, strict=False)),
        float(c.number(s, "settle", "shaker", 1.0, strict=False)),
        float(c.number(s, "duty", "shaker", 0.5)),
        int(c.number(s, "shakers", "shaker", 1, integer=True)))
    if shaker.duty > 1:
        raise c.fail("shaker.duty", f"must be <= 1, got {shaker.duty:g}")
    if shaker.f_start >= shaker.f_stop:
        raise c.fail("shaker.f_stop", f"must be above f_start ({shaker.f_start:g} Hz)")
    return shaker


def _excitations(c: _Ctx, data: Mapping[str, Any]) -> list[ExcitationPoint]:
    """The ``[[excitation]]`` points, in order."""
    excs = []
    for i, e in enumerate(c.points(data, "excitation")):
        key = f"excitation[{i}]"
        bad = sorted(set(e) - {"node", "xyz", "direction"})
        if bad:
            raise c.fail(f"{key}.{bad[0]}", "unknown key; allowed: direction, node, xyz")
        excs.append(ExcitationPoint(i, c.node(e, key), c.vector(e, "xyz", key, nonzero=False),
                                    c.vector(e, "direction", key, nonzero=True)))
    return excs


def _responses(c: _Ctx, data: Mapping[str, Any]) -> list[ResponsePoint]:
    """The ``[[response]]`` points, in order; a station channel may serve one point only."""
    resps = []
    seen: dict[str, int] = {}
    for i, rp in enumerate(c.points(data, "response")):
        key = f"response[{i}]"
        bad = sorted(set(rp) - {"node", "xyz", "channels"})
        if bad:
            raise c.fail(f"{key}.{bad[0]}", "unknown key; allowed: channels, node, xyz")
        ch = rp.get("channels")
        if (not isinstance(ch, list) or not ch
                or not all(isinstance(x, str) and x for x in ch)):
            raise c.fail(f"{key}.channels", "must be a non-empty list of station channel names")
        for nm in ch:
            if nm in seen:
                raise c.fail(f"{key}.channels", f"channel {nm!r} already used by "
                             f"response[{seen[nm]}]")
            seen[nm] = i
        resps.append(ResponsePoint(c.node(rp, key), c.vector(rp, "xyz", key, nonzero=False),
                                   tuple(ch)))
    return resps


def _check_shakers(c: _Ctx, method: Method, shaker: ShakerSettings,
                   excs: list[ExcitationPoint]) -> None:
    """Refuse several shakers where their forces could not be told apart."""
    k = shaker.shakers
    if k > 1:
        if method != "shaker":
            raise c.fail("shaker.shakers", f"{k} shakers need plan.method = 'shaker'")
        if shaker.waveform == "chirp":
            raise c.fail("shaker.shakers", f"{k} shakers need random or burst-random signals "
                         "(every shaker would play the same chirp: the forces could not be "
                         "told apart)")
        if shaker.averages <= k:
            raise c.fail("shaker.averages", f"must be more than shaker.shakers ({k}): with "
                         f"{shaker.averages} blocks for {k} forces the coherence is 1 whatever "
                         "the data, and nothing is averaged")
        if len(excs) % k:
            raise c.fail("excitation", f"{len(excs)} excitations for shaker.shakers = {k}: "
                         f"give them {k} at a time (the points driven together)")
        for i in range(0, len(excs), k):
            dofs = {(e.node, e.direction) for e in excs[i:i + k]}
            if len(dofs) < k:
                raise c.fail(f"excitation[{i}]", f"the {k} excitations driven together "
                             f"(excitation[{i}] to [{i + k - 1}]) must differ")


#: the unit of each plan key in messages
_UNITS = {"record.fs": "Hz", "record.length": "s", "record.pretrigger": "s",
          "record.trigger_level": "N", "record.exp_tau": "s", "shaker.level": "V",
          "shaker.f_start": "Hz", "shaker.f_stop": "Hz", "shaker.ramp": "s",
          "shaker.settle": "s", "xyz": "m"}
#: keys a method does not use (a hammer plan's [shaker] table, a shaker plan's trigger)
_UNUSED = {"hammer": ("shaker.",),
           "shaker": ("plan.hits", "record.pretrigger", "record.trigger_level",
                      "record.exp_tau")}


def _flat(data: Mapping[str, Any]) -> dict[str, Any]:
    """``to_dict()`` data as ``{"record.length": 1.5, "excitation[0].xyz": [...], ...}``."""
    out: dict[str, Any] = {}
    for table, t in data.items():
        if isinstance(t, list):
            for i, item in enumerate(t):
                out.update({f"{table}[{i}].{k}": v for k, v in item.items()})
        else:
            out.update({f"{table}.{k}": v for k, v in t.items()})
    return out


def _worded(key: str, value: Any) -> str:
    unit = _UNITS.get(key, _UNITS.get(key.rsplit(".", 1)[-1], ""))
    if isinstance(value, list):
        text = f"[{', '.join(f'{x:g}' if isinstance(x, float) else str(x) for x in value)}]"
    elif isinstance(value, float):
        text = f"{value:g}"
    else:
        text = str(value)
    return f"{text} {unit}" if unit else text


def plan_differences(old: TestPlan, new: TestPlan, old_name: str, new_name: str,
                     most: int = 3) -> list[str]:
    """What differs between two plans, in the plan file's words, as
    ``"record.length 1.5 s in run.h5, 2 s in plan.toml"``; empty when they acquire alike.

    The plan's name is not compared, nor the keys its method does not use (a hammer
    plan's ``[shaker]`` table, a shaker plan's hits and trigger settings). Points are
    compared in order; a different number of them is one difference. At most ``most``
    differences are listed, then how many more there are.
    """
    a, b = _flat(old.to_dict()), _flat(new.to_dict())
    unused = _UNUSED[old.method] if old.method == new.method else ()
    counts = {"excitation": (len(old.excitations), len(new.excitations)),
              "response": (len(old.responses), len(new.responses))}
    found: list[str] = []
    for key, value in a.items():
        table = key.split("[")[0]
        if (key == "plan.name" or key.startswith(unused) or key.startswith("prediction.")
                or value == b.get(key)
                or (table in counts and counts[table][0] != counts[table][1])):
            continue
        found.append(f"{key} {_worded(key, value)} in {old_name}, "
                     f"{_worded(key, b.get(key))} in {new_name}")
    found += [f"{table} {n_old} points in {old_name}, {n_new} in {new_name}"
              for table, (n_old, n_new) in counts.items() if n_old != n_new]
    if len(found) > most:
        found = [*found[:most], f"{len(found) - most} more"]
    return found


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML form for {type(v).__name__}")


def plan_toml(data: Mapping[str, Any], header: str = "") -> str:
    """``to_dict()``-like plan data as TOML text (tables, then arrays of tables), ``header``
    as comment lines first; ``load_plan`` reads it back."""
    lines = [f"# {h}" if h else "#" for h in header.splitlines()]
    for name, t in data.items():
        if isinstance(t, dict):
            lines += ["", f"[{name}]", *(f"{k} = {_toml_value(v)}" for k, v in t.items())]
    for name, t in data.items():
        if isinstance(t, list):
            for item in t:
                lines += ["", f"[[{name}]]", *(f"{k} = {_toml_value(v)}"
                                               for k, v in item.items())]
    return "\n".join(lines).lstrip("\n") + "\n"


def load_plan(path: str | Path) -> TestPlan:
    """Read and validate a plan file; raises :class:`PlanError` (one line) on any problem."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise PlanError(f"{p}: not valid TOML: {err}") from err
    except OSError as err:
        raise PlanError(f"{p}: cannot read the plan file: {err.strerror or err}") from err
    return parse_plan(data, str(p))
