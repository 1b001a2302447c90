"""The channel map of a TDMS or MDF file: which channels hold the force and the responses.

A TDMS or MDF file names its channels but says nothing of the test: the map (a TOML file,
``docs/time-files.md``) gives the force channel, each response channel's node and
direction, the units and sensitivities, how the file's groups split into runs, where each
run's force acted, and the node coordinates. :func:`read_channel_map` parses and checks it
once; :func:`map_text` writes the map of runs exported by ``insitu export``.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from processing.data import Geometry, InputError

__all__ = ["ChannelMap", "ChannelSpec", "ExcitationSpec", "default_map_path", "map_text",
           "read_channel_map"]

#: SI factor of each unit a force or an acceleration channel may be stored in
FORCE_UNITS = {"N": 1.0, "kN": 1e3, "lbf": 4.4482216152605}
ACCELERATION_UNITS = {"m/s^2": 1.0, "m/s2": 1.0, "mm/s^2": 1e-3, "mm/s2": 1e-3,
                      "g": 9.80665}
#: voltage units (need a sensitivity), in mV
VOLT_UNITS = {"mV": 1.0, "V": 1e3}
_AXES = {"x": 0, "y": 1, "z": 2}
_SENSITIVITY = re.compile(
    r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(mV|V)\s*/\s*\(?\s*([A-Za-z/^0-9]+)"
    r"\s*\)?\s*$")


def default_map_path(data: Path) -> Path:
    """The map read when none is given: ``run.map.toml`` beside ``run.tdms``."""
    return data.with_name(data.stem + ".map.toml")


@dataclass(frozen=True)
class ChannelSpec:
    """One mapped channel: its name in the file, the factor taking its samples to SI (None:
    from the unit the file gives, :meth:`factor`), and for a response its node and unit
    direction (global frame)."""

    name: str
    quantity: Literal["force", "acceleration"]
    unit: str | None
    sensitivity: str | float | None
    node: int = 0
    direction: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def factor(self, file_unit: str, where: str) -> float:
        """The SI factor of the samples: the map's unit, else ``file_unit`` (the file's own
        unit property); InputError (naming ``where``) when neither is known."""
        unit = self.unit or file_unit.strip()
        if not unit:
            raise InputError(f"{where}: channel {self.name!r} has no unit in the file: give "
                             f"its unit in the channel map")
        return si_factor(self.quantity, unit, self.sensitivity, f"{where}: channel {self.name!r}")


@dataclass(frozen=True)
class ExcitationSpec:
    """Where the force of some runs acted: node, unit direction (global frame), and the runs
    (``groups``: group names; ``point``: a value of the point channel)."""

    node: int
    direction: tuple[float, float, float]
    groups: tuple[str, ...] = ()
    point: int | None = None


@dataclass(frozen=True)
class ChannelMap:
    """A parsed channel map (``docs/time-files.md``).

    Attributes
    ----------
    path : the map file
    runs : ``"groups"`` (each group holding the force channel is a run) or
        ``"point-channel"`` (runs are the stretches of one nonzero value of ``point_channel``)
    groups : the groups read (empty: every group holding the force channel)
    point_channel : the channel of point indices (``"point-channel"`` only)
    force, responses : the mapped channels
    excitations : where each run's force acted
    geometry : node coordinates, m
    """

    path: Path
    runs: Literal["groups", "point-channel"]
    groups: tuple[str, ...]
    point_channel: str
    force: ChannelSpec
    responses: tuple[ChannelSpec, ...]
    excitations: tuple[ExcitationSpec, ...]
    geometry: Geometry

    @property
    def channels(self) -> tuple[ChannelSpec, ...]:
        """The force then the responses."""
        return (self.force, *self.responses)

    def excitation_of_group(self, group: str) -> ExcitationSpec | None:
        return next((e for e in self.excitations if group in e.groups), None)

    def excitation_of_point(self, point: int) -> ExcitationSpec | None:
        return next((e for e in self.excitations if e.point == point), None)

    @property
    def resp_nodes(self) -> NDArray[np.int64]:
        return np.array([c.node for c in self.responses], dtype=np.int64)

    @property
    def resp_dirs(self) -> NDArray[np.float64]:
        return np.array([c.direction for c in self.responses], dtype=float).reshape(-1, 3)


def si_factor(quantity: str, unit: str, sensitivity: str | float | None, where: str) -> float:
    """The factor taking samples stored in ``unit`` to N or m/s^2; a voltage needs the
    ``sensitivity`` (a number in mV per N or per m/s^2, or a text such as ``"100 mV/g"``)."""
    units = FORCE_UNITS if quantity == "force" else ACCELERATION_UNITS
    si = "N" if quantity == "force" else "m/s^2"
    if unit in units:
        if sensitivity is not None:
            raise InputError(f"{where}: a sensitivity is given but the unit is {unit}: give a "
                             "sensitivity only for channels stored in V or mV")
        return units[unit]
    if unit not in VOLT_UNITS:
        raise InputError(f"{where}: unknown unit {unit!r} for a {quantity}: use "
                         f"{', '.join([*units, *VOLT_UNITS])} (with a sensitivity for V, mV)")
    if sensitivity is None:
        raise InputError(f"{where}: stored in {unit}: give its sensitivity (e.g. "
                         f"\"{'2.25 mV/N' if quantity == 'force' else '100 mV/g'}\")")
    if isinstance(sensitivity, str):
        m = _SENSITIVITY.match(sensitivity)
        if m is None or m.group(3) not in units:
            raise InputError(f"{where}: sensitivity {sensitivity!r} is not a number with a unit "
                             f"such as mV/{si} or mV/{next(iter(set(units) - {si}), si)}")
        mv = float(m.group(1)) * VOLT_UNITS[m.group(2)] / units[m.group(3)]  # mV per SI unit
    else:
        mv = float(sensitivity)
    if not (math.isfinite(mv) and mv > 0):
        raise InputError(f"{where}: sensitivity {sensitivity!r} must be positive")
    return VOLT_UNITS[unit] / mv


def _direction(value: Any, where: str) -> tuple[float, float, float]:
    """``"+x"``, ``"-z"`` ... or a vector ``[dx, dy, dz]``, as a unit vector."""
    if isinstance(value, str):
        m = re.fullmatch(r"\s*([+-]?)\s*([xyzXYZ])\s*", value)
        if m is None:
            raise InputError(f"{where}: direction {value!r}: give +x, -x, +y, -y, +z, -z or a "
                             "vector [dx, dy, dz]")
        v = np.zeros(3)
        v[_AXES[m.group(2).lower()]] = -1.0 if m.group(1) == "-" else 1.0
    else:
        try:
            v = np.asarray(value, dtype=float).reshape(3)
        except (TypeError, ValueError) as err:
            raise InputError(f"{where}: direction {value!r}: give +x, -x, ... or a vector "
                             "[dx, dy, dz]") from err
    n = float(np.linalg.norm(v))
    if not (math.isfinite(n) and n > 1e-12):
        raise InputError(f"{where}: direction {value!r} is zero or not finite")
    v = v / n
    return float(v[0]), float(v[1]), float(v[2])


def _table(data: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = data.get(key)
    if not isinstance(value, dict):
        raise InputError(f"{where}: no [{key}] table: give one (docs/time-files.md)")
    return value


def _only(data: dict[str, Any], allowed: Sequence[str], where: str) -> None:
    """Refuses a key the map does not know (a typo would otherwise be ignored)."""
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r}: use {', '.join(allowed)}")


def _channel(data: Any, quantity: Literal["force", "acceleration"],
             where: str) -> ChannelSpec:
    if not isinstance(data, dict):
        raise InputError(f"{where}: give a table with channel = \"name\"")
    keys = ["channel", "unit", "sensitivity"] + (["node", "direction"]
                                                 if quantity == "acceleration" else [])
    _only(data, keys, where)
    name = data.get("channel")
    if not isinstance(name, str) or not name:
        raise InputError(f"{where}: no channel name: give channel = \"name in the file\"")
    unit = data.get("unit")
    if unit is not None and not isinstance(unit, str):
        raise InputError(f"{where}: unit must be text, e.g. \"N\" or \"g\"")
    sens = data.get("sensitivity")
    if sens is not None and not isinstance(sens, (str, int, float)):
        raise InputError(f"{where}: sensitivity must be a number (mV per SI unit) or a text "
                         "such as \"100 mV/g\"")
    if unit is not None:
        si_factor(quantity, unit, sens, f"{where}: channel {name!r}")  # checked now
    if quantity == "force":
        return ChannelSpec(name, quantity, unit, sens)
    node = data.get("node")
    if not isinstance(node, int) or isinstance(node, bool):
        raise InputError(f"{where}: channel {name!r}: give its node number (node = 11)")
    if "direction" not in data:
        raise InputError(f"{where}: channel {name!r}: give its direction (+x, ..., or a vector)")
    return ChannelSpec(name, quantity, unit, sens, node,
                       _direction(data["direction"], f"{where}: channel {name!r}"))


def _geometry(data: dict[str, Any], path: Path) -> Geometry:
    """``[nodes]`` (node = [x, y, z], m) or ``geometry = "file.uff"`` (relative to the map)."""
    where = path.name
    if ("nodes" in data) == ("geometry" in data):
        raise InputError(f"{where}: give the node coordinates, either a [nodes] table "
                         "(11 = [x, y, z], m) or geometry = \"file.uff\"")
    if "geometry" in data:
        from app.io.uff_geometry import read_geometry_uff

        src = path.parent / str(data["geometry"])
        if not src.is_file():
            raise InputError(f"{where}: geometry file {src} not found: check the path (relative "
                             "to the map)")
        return read_geometry_uff(src)[0]
    nodes = data["nodes"]
    if not isinstance(nodes, dict) or not nodes:
        raise InputError(f"{where}: [nodes] is empty: give 11 = [x, y, z] (m) per node")
    ids, xyz = [], []
    for key, value in nodes.items():
        if not re.fullmatch(r"-?\d+", key):
            raise InputError(f"{where}: [nodes] key {key!r} is not a node number")
        try:
            xyz.append(np.asarray(value, dtype=float).reshape(3))
        except (TypeError, ValueError) as err:
            raise InputError(f"{where}: node {key}: give [x, y, z] in m") from err
        ids.append(int(key))
    return Geometry(np.array(ids, dtype=np.int64), np.array(xyz))


def _excitation(data: Any, runs: str, where: str) -> ExcitationSpec:
    if not isinstance(data, dict):
        raise InputError(f"{where}: give a table with node, direction and "
                         + ("groups" if runs == "groups" else "point"))
    _only(data, ["node", "direction", "groups", "point"], where)
    node = data.get("node")
    if not isinstance(node, int) or isinstance(node, bool) or "direction" not in data:
        raise InputError(f"{where}: give node (a number) and direction (+x, ... or a vector)")
    direction = _direction(data["direction"], where)
    if runs == "groups":
        groups = data.get("groups")
        if (not isinstance(groups, list) or not groups
                or not all(isinstance(g, str) for g in groups)):
            raise InputError(f"{where}: give groups = [\"group name\", ...]: the runs excited "
                             "there")
        return ExcitationSpec(node, direction, groups=tuple(groups))
    point = data.get("point")
    if not isinstance(point, int) or isinstance(point, bool) or point == 0:
        raise InputError(f"{where}: give point = N (the point channel's value during its "
                         "runs, not 0)")
    return ExcitationSpec(node, direction, point=point)


def read_channel_map(path: str | Path) -> ChannelMap:
    """The channel map at ``path``, checked whole (``docs/time-files.md``).

    Raises
    ------
    InputError
        One line naming the map and the problem: a missing or unparsable file, a missing or
        unknown key, a unit or sensitivity it cannot convert, a node without coordinates, a
        channel mapped twice, a group excited at two places.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"channel map {p} not found: give --channels MAP.toml (its format: "
                         "docs/time-files.md)")
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise InputError(f"channel map {p.name} is not valid TOML ({err}): fix it") from err
    except OSError as err:
        raise InputError(f"channel map {p}: {err.strerror}: check the path") from err
    where = p.name
    _only(data, ["version", "layout", "force", "response", "excitation", "nodes", "geometry"],
          where)
    if data.get("version", 1) != 1:
        raise InputError(f"{where}: version {data['version']!r}: this insitu reads version 1")
    layout = _table(data, "layout", where)
    _only(layout, ["runs", "groups", "point_channel"], f"{where} [layout]")
    runs = layout.get("runs", "groups")
    if runs not in ("groups", "point-channel"):
        raise InputError(f"{where} [layout]: runs = {runs!r}: use \"groups\" (a group a run) "
                         "or \"point-channel\"")
    groups = layout.get("groups", [])
    if not isinstance(groups, list) or not all(isinstance(g, str) for g in groups):
        raise InputError(f"{where} [layout]: groups must be a list of group names")
    point_channel = layout.get("point_channel", "")
    if runs == "point-channel" and not (isinstance(point_channel, str) and point_channel):
        raise InputError(f"{where} [layout]: runs = \"point-channel\" needs point_channel = "
                         "\"name\"")
    force = _channel(_table(data, "force", where), "force", f"{where} [force]")
    resp_data = data.get("response")
    if not isinstance(resp_data, list) or not resp_data:
        raise InputError(f"{where}: no [[response]] table: map at least one accelerometer "
                         "channel")
    responses = tuple(_channel(r, "acceleration", f"{where} [[response]] {i + 1}")
                      for i, r in enumerate(resp_data))
    names = [force.name, *(r.name for r in responses)] + (
        [point_channel] if runs == "point-channel" else [])
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"{where}: channel {twice[0]!r} is mapped twice: map each channel once")
    dofs = [(r.node, np.round(r.direction, 9).tobytes()) for r in responses]
    if len(set(dofs)) != len(dofs):
        raise InputError(f"{where}: two responses measure the same node and direction: fix "
                         "their node or direction")
    exc_data = data.get("excitation")
    if not isinstance(exc_data, list) or not exc_data:
        raise InputError(f"{where}: no [[excitation]] table: say where each run's force acted")
    excitations = tuple(_excitation(e, runs, f"{where} [[excitation]] {i + 1}")
                        for i, e in enumerate(exc_data))
    keys = ([g for e in excitations for g in e.groups] if runs == "groups"
            else [str(e.point) for e in excitations])
    again = sorted({k for k in keys if keys.count(k) > 1})
    if again:
        raise InputError(f"{where}: {'group' if runs == 'groups' else 'point'} {again[0]!r} is "
                         "excited at two places: list it under one [[excitation]]")
    geometry = _geometry(data, p)
    used = np.array([*(r.node for r in responses), *(e.node for e in excitations)])
    geometry.coordinates(used, f"{where}: mapped")
    return ChannelMap(p, runs, tuple(groups), point_channel, force, responses, excitations,
                      geometry)


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _vector(v: Sequence[float]) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def map_text(source: str, force: str, responses: Sequence[tuple[str, int, Sequence[float]]],
             excitations: Sequence[tuple[int, Sequence[float], Sequence[str]]],
             geometry: Geometry) -> str:
    """The channel map (TOML) of a file written in SI units, a group a run: ``force`` the
    force channel's name, ``responses`` (name, node, direction) and ``excitations`` (node,
    direction, group names); floats written to their last bit."""
    lines = [f"# channel map of the time records exported from {source} (docs/time-files.md)",
             "version = 1", "", "[layout]", 'runs = "groups"', "",
             "[force]", f"channel = {_toml_str(force)}", 'unit = "N"', ""]
    for name, node, d in responses:
        lines += ["[[response]]", f"channel = {_toml_str(name)}", f"node = {int(node)}",
                  f"direction = {_vector(d)}", 'unit = "m/s^2"', ""]
    for node, d, groups in excitations:
        lines += ["[[excitation]]", f"node = {int(node)}", f"direction = {_vector(d)}",
                  "groups = [" + ", ".join(_toml_str(g) for g in groups) + "]", ""]
    lines += ["[nodes]  # m"]
    lines += [f"{int(n)} = {_vector(x)}" for n, x in zip(geometry.node_ids, geometry.xyz,
                                                          strict=True)]
    return "\n".join(lines) + "\n"
