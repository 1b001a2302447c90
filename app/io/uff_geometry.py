"""UFF geometry: nodes (datasets 15, 2411) and coordinate systems (dataset 2420).

Convention of dataset 2420 (as I-DEAS, Simcenter Testlab and SDynPy use it; pyuff
stores the 4 x 3 matrix of records 5-8 unchanged in ``CS_matrices``): rows 1-3 are
the unit vectors of the local x, y, z axes in global components, row 4 is the origin
in global coordinates (file length unit). So, with ``M`` that matrix,

    global point     = M[:3].T @ local point + M[3]
    global direction = M[:3].T @ local direction

A node's ``def_cs`` names the system its coordinates are given in, its ``disp_cs``
the system of its direction codes +-1, +-2, +-3. Label 0 is the global system; so is
label 1 when the file does not define it (I-DEAS numbers the global system 1).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from app.io._uff_common import Dataset, as_list, load_sets, read_units
from processing.data import Geometry, InputError

__all__ = ["assign_node_frames", "read_geometry", "read_geometry_uff"]

log = logging.getLogger(__name__)

#: datasets that carry units and geometry
GEOMETRY_SETS = (164, 15, 2411, 2420)
#: directions closer than this (per component) to a global axis are taken as that axis;
#: directions at one node must be parallel or perpendicular within it
DIRECTION_TOL = 1e-9


def _coordinate_systems(datasets: list[Dataset]) -> dict[int, tuple[int, NDArray[np.float64]]]:
    """CS label -> (type, 4 x 3 matrix) from every dataset 2420."""
    out: dict[int, tuple[int, NDArray[np.float64]]] = {}
    for ds in datasets:
        if int(ds.get("type", -1)) != 2420:
            continue
        try:
            labels = [int(v) for v in ds["CS_sys_labels"]]
            types = [int(v) for v in ds["CS_types"]]
            mats = [np.asarray(m, dtype=float).reshape(4, 3) for m in ds["CS_matrices"]]
        except (KeyError, TypeError, ValueError) as err:
            raise InputError(
                f"dataset 2420 (coordinate systems) is malformed ({err}): re-export the file"
            ) from err
        if not (len(labels) == len(types) == len(mats)):
            raise InputError("dataset 2420 (coordinate systems) is truncated: re-export the file")
        for label, kind, m in zip(labels, types, mats, strict=True):
            if label in out and not (out[label][0] == kind and np.array_equal(out[label][1], m)):
                raise InputError(f"coordinate system {label} is defined twice, differently")
            out[label] = (kind, m)
    return out


def _cs_transform(
    label: int,
    systems: dict[int, tuple[int, NDArray[np.float64]]],
    node: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """(R, origin) of a CS: R columns = local axes in global; None for the global system."""
    if label == 0 or (label == 1 and label not in systems):
        return None
    if label not in systems:
        raise InputError(
            f"node {node} refers to coordinate system {label}, which the file does not define: "
            "export the coordinate systems (dataset 2420) with the nodes"
        )
    kind, m = systems[label]
    if kind != 0:
        name = {1: "cylindrical", 2: "spherical"}.get(kind, f"type {kind}")
        raise InputError(
            f"coordinate system {label} (used by node {node}) is {name}; only Cartesian "
            "systems are supported: export the nodes in Cartesian coordinates"
        )
    R = m[:3].T
    if not np.all(np.isfinite(m)) or not np.allclose(R.T @ R, np.eye(3), atol=1e-6):
        raise InputError(
            f"coordinate system {label} (used by node {node}) has a transformation matrix "
            "whose first three rows are not orthonormal unit vectors: fix dataset 2420"
        )
    return R, m[3]


def _node_table(datasets: list[Dataset]) -> tuple[
    NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]
]:
    """Node ids, file coordinates, def_cs and disp_cs of every dataset 15 / 2411."""
    ids, xyz, dcs, pcs = [], [], [], []
    for ds in datasets:
        if int(ds.get("type", -1)) not in (15, 2411):
            continue
        try:
            n = np.asarray(ds["node_nums"], dtype=float).ravel()
            p = np.column_stack([np.asarray(ds[k], dtype=float).ravel() for k in "xyz"])
            size = n.size
            d = np.asarray(ds.get("def_cs", np.zeros(size)), dtype=float).ravel()
            q = np.asarray(ds.get("disp_cs", np.zeros(size)), dtype=float).ravel()
        except (KeyError, TypeError, ValueError) as err:
            raise InputError(
                f"dataset {ds.get('type')} (nodes) is malformed ({err}): re-export the geometry"
            ) from err
        if not (p.shape[0] == d.size == q.size == size):
            raise InputError(
                f"dataset {ds.get('type')} (nodes) is truncated: re-export the geometry"
            )
        ids.append(n)
        xyz.append(p)
        dcs.append(d)
        pcs.append(q)
    if not ids:
        raise InputError(
            "the file has no node coordinates (dataset 15 or 2411): "
            "export the geometry together with the functions"
        )
    all_ids = np.concatenate(ids)
    if not np.all(all_ids == np.round(all_ids)):
        raise InputError("node labels in dataset 15/2411 are not integers: re-export the geometry")
    return (
        all_ids.astype(np.int64),
        np.concatenate(xyz),
        np.concatenate(dcs).astype(np.int64),
        np.concatenate(pcs).astype(np.int64),
    )


def read_geometry(
    datasets: Sequence[Dataset] | Dataset,
) -> tuple[Geometry, dict[int, NDArray[np.float64]]]:
    """Node coordinates in the global frame (m) and each node's displacement frame.

    Parameters
    ----------
    datasets : the list of dicts ``pyuff.UFF(path).read_sets()`` returns (or one dict).
        Datasets 15 and 2411 give nodes, 2420 coordinate systems, 164 units.

    Returns
    -------
    geometry : Geometry
        Node ids in file order, coordinates in metres, global frame.
    rotations : dict[int, ndarray (3, 3)]
        For every node, the rotation from its displacement coordinate system to
        global: column k is the unit vector of local axis k, so direction code ``+-(k+1)``
        means ``+-rotations[node][:, k]``. Identity for nodes in the global system.

    Raises
    ------
    InputError
        No node dataset; a node defined twice differently; a node referring to a
        coordinate system that is missing, not Cartesian or not orthonormal.

    Examples
    --------
    >>> import pyuff  # doctest: +SKIP
    >>> geometry, rotations = read_geometry(pyuff.UFF("frf.uff").read_sets())  # doctest: +SKIP
    """
    sets = as_list(datasets)
    units = read_units(sets)
    systems = _coordinate_systems(sets)
    ids, xyz_file, def_cs, disp_cs = _node_table(sets)
    xyz = np.empty_like(xyz_file)
    rotations: dict[int, NDArray[np.float64]] = {}
    for k, node in enumerate(ids.tolist()):
        t = _cs_transform(int(def_cs[k]), systems, node)
        p = xyz_file[k] if t is None else t[0] @ xyz_file[k] + t[1]
        xyz[k] = p / units.length
        r = _cs_transform(int(disp_cs[k]), systems, node)
        R = np.eye(3) if r is None else r[0]
        if node in rotations:
            first = int(np.flatnonzero(ids == node)[0])
            if not (np.array_equal(xyz[first], xyz[k]) and np.array_equal(rotations[node], R)):
                raise InputError(
                    f"node {node} is defined twice with different coordinates or coordinate "
                    "systems: keep one definition"
                )
        rotations[node] = R
    keep = np.sort(np.unique(ids, return_index=True)[1])
    return Geometry(ids[keep], xyz[keep]), rotations


def read_geometry_uff(path: str | Path) -> tuple[Geometry, dict[int, NDArray[np.float64]]]:
    """:func:`read_geometry` of a file, reading only its unit and geometry datasets.

    Cheap on large time-data files: the dataset 58 records are skipped unread.
    """
    return read_geometry(load_sets(path, only=GEOMETRY_SETS))


# --- writing: give each node a displacement frame its directions lie along -------------------


def _global_axis_codes(D: NDArray[np.float64]) -> NDArray[np.int64] | None:
    """Signed codes when every direction is a +-global axis, else None."""
    k = np.argmax(np.abs(D), axis=1)
    s = np.sign(D[np.arange(D.shape[0]), k])
    target = np.zeros_like(D)
    target[np.arange(D.shape[0]), k] = s
    if np.all(np.abs(D - target) < DIRECTION_TOL):
        return (s * (k + 1)).astype(np.int64)
    return None


def _frame(node: int, D: NDArray[np.float64]) -> NDArray[np.float64]:
    """Right-handed frame (columns) whose axes carry every direction of D up to sign."""
    axes: list[NDArray[np.float64]] = []
    for d in D:
        for a in axes:
            c = float(d @ a)
            if abs(abs(c) - 1.0) < DIRECTION_TOL:
                break
            if abs(c) > DIRECTION_TOL:
                angle = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
                raise InputError(
                    f"node {node} has directions {np.round(a, 6).tolist()} and "
                    f"{np.round(d, 6).tolist()} at {angle:.4g} deg, neither parallel nor "
                    "perpendicular: UFF gives a node one displacement coordinate system, so "
                    "its directions must lie along the axes of one orthonormal frame; "
                    "put the non-orthogonal DOFs on separate nodes"
                )
        else:
            axes.append(d)
    if len(axes) == 1:
        a = axes[0]
        e = np.eye(3)[int(np.argmin(np.abs(a)))]
        b = e - (e @ a) * a
        axes.append(b / np.linalg.norm(b))
    if len(axes) == 2:
        axes.append(np.cross(axes[0], axes[1]))
    R = np.column_stack(axes)
    if np.linalg.det(R) < 0:
        R[:, 2] = -R[:, 2]
    return R


def assign_node_frames(
    nodes: NDArray[np.int64], dirs: NDArray[np.float64]
) -> tuple[dict[int, NDArray[np.float64]], NDArray[np.int64]]:
    """Displacement frames and UFF direction codes for DOFs (node, unit direction).

    A node whose directions are all +-global axes stays in the global system. Any
    other node gets a right-handed frame whose axes are its directions (the first
    direction seen along each axis keeps its sign); a triaxial sensor measuring along
    three orthonormal directions gets codes +1, +2, +3.

    Parameters
    ----------
    nodes : (n,) node id of each DOF
    dirs : (n, 3) direction of each DOF, global frame (normalised here)

    Returns
    -------
    frames : dict node -> (3, 3) frame, columns = local axes in global (non-global nodes only)
    codes : (n,) signed UFF direction codes in each node's frame

    Raises
    ------
    InputError
        Directions at one node that are neither parallel nor perpendicular (within 1e-9).
    """
    nodes = np.asarray(nodes, dtype=np.int64).ravel()
    D = np.asarray(dirs, dtype=float).reshape(-1, 3)
    norm = np.linalg.norm(D, axis=1, keepdims=True)
    if not np.all(np.isfinite(D)) or np.any(norm < 1e-12):
        raise InputError("a DOF direction is zero or not finite: give unit direction vectors")
    D = D / norm
    codes = np.zeros(nodes.size, dtype=np.int64)
    frames: dict[int, NDArray[np.float64]] = {}
    _, first = np.unique(nodes, return_index=True)
    for node in nodes[np.sort(first)].tolist():
        idx = np.flatnonzero(nodes == node)
        g = _global_axis_codes(D[idx])
        if g is not None:
            codes[idx] = g
            continue
        R = _frame(node, D[idx])
        frames[node] = R
        local = D[idx] @ R  # components along the frame axes
        k = np.argmax(np.abs(local), axis=1)
        codes[idx] = np.sign(local[np.arange(idx.size), k]).astype(np.int64) * (k + 1)
    return frames, codes
