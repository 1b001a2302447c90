"""UFF FRF and time-data files: round trips, files written by pyuff, every error path.

Tolerances (measured values in brackets):
- binary 58b: FRF values rtol 1e-13 [0 in m, 2.2e-16 in mm];
- ASCII 58: FRF values rtol 1e-11 [5.0e-12: E20.12 fields hold 12 significant digits];
- coordinates atol 1e-15 m (17 digits in 2411), directions atol 1e-12.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import pyuff
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from app.io import (
    TimeRun,
    read_frf_measurement_uff,
    read_frf_uff,
    read_geometry,
    read_geometry_uff,
    read_time_uff,
    read_units,
    write_frf_uff,
    write_time_uff,
)
from app.io._uff_write import AxisInfo, open_for_writing
from app.io.uff_geometry import assign_node_frames
from app.pipeline import FRF_UFF, load
from hardware_mocks.benches import get_bench
from processing.data import FRFSet, Geometry, InputError

RTOL_ASCII = 1e-11
RTOL_BINARY = 1e-13


# --- helpers ----------------------------------------------------------------------------------


def pyuff_write(path: Path, sets: list[dict[str, Any]]) -> Path:
    """Write datasets with pyuff itself (its 58b writer leaks a file handle: silence that)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    return path


def units164(length: float = 1.0) -> dict[str, Any]:
    return pyuff.prepare_164(units_code=1 if length == 1.0 else 9, units_description="test",
                             temp_mode=1, length=float(length), force=1.0, temp=1.0,
                             temp_offset=273.15)


def nodes2411(ids: list[int], xyz: np.ndarray, def_cs: list[int] | None = None,
              disp_cs: list[int] | None = None) -> dict[str, Any]:
    n = len(ids)
    return pyuff.prepare_2411(node_nums=list(ids), def_cs=def_cs or [0] * n,
                              disp_cs=disp_cs or [0] * n, color=[1] * n,
                              x=np.asarray(xyz)[:, 0].astype(float),
                              y=np.asarray(xyz)[:, 1].astype(float),
                              z=np.asarray(xyz)[:, 2].astype(float))


def rec58(rsp: tuple[int, int], ref: tuple[int, int], freq: np.ndarray, data: np.ndarray, *,
          binary: bool = False, ordinate: int = 12, denominator: int = 13, func_type: int = 4,
          ord_len_exp: int = 0, load_case: int = 0, abscissa: int = 18) -> dict[str, Any]:
    return pyuff.prepare_58(
        binary=int(binary), func_type=func_type, rsp_node=rsp[0], rsp_dir=rsp[1],
        ref_node=ref[0], ref_dir=ref[1], load_case_id=load_case, data=data, x=freq,
        abscissa_spacing=1, abscissa_spec_data_type=abscissa,
        ordinate_spec_data_type=ordinate, ordinate_len_unit_exp=ord_len_exp,
        orddenom_spec_data_type=denominator, id1="test")


def one_line_error(excinfo: pytest.ExceptionInfo[InputError], *fragments: str) -> str:
    msg = str(excinfo.value)
    assert "\n" not in msg
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"
    return msg


@pytest.fixture(scope="module")
def engine() -> FRFSet:
    fs = get_bench("engine").frfset(noise=0.01)
    coh = 1.0 - 0.05 * np.random.default_rng(3).random(fs.H.shape)
    return replace(fs, coherence=coh)


@pytest.fixture(scope="module")
def block() -> FRFSet:
    return get_bench("block").frfset(noise=0.01)


@pytest.fixture(scope="module")
def small() -> FRFSet:
    """Block bench reduced to 2 sensors (node 3 skewed) x 3 forces (108 skewed), 24 lines."""
    fs = get_bench("block").frfset()
    r, e = np.arange(3, 9), np.array([0, 7, 8])
    return replace(fs, freq=fs.freq[:24], H=fs.H[np.ix_(r, e)][:, :, :24],
                   resp_nodes=fs.resp_nodes[r], resp_dirs=fs.resp_dirs[r],
                   exc_nodes=fs.exc_nodes[e], exc_dirs=fs.exc_dirs[e])


def small_file(tmp_path: Path, records: list[dict[str, Any]], *, length: float = 1000.0,
               nodes: dict[str, Any] | None = None) -> Path:
    xyz = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]) * length
    return pyuff_write(tmp_path / "f.uff",
                       [units164(length), nodes or nodes2411([1, 2], xyz), *records])


FREQ = np.arange(1.0, 9.0)
DATA = (1.0 + 2.0j) * np.arange(1.0, 9.0)


# --- round trips of the bench FRFs ------------------------------------------------------------


@pytest.mark.parametrize("length_unit", ["m", "mm"])
@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
@pytest.mark.parametrize("bench", ["engine", "block"])
def test_round_trip_bench(tmp_path: Path, request: pytest.FixtureRequest, bench: str,
                          binary: bool, length_unit: str) -> None:
    fs: FRFSet = request.getfixturevalue(bench)
    path = tmp_path / "frf.uff"
    write_frf_uff(path, fs, binary=binary, length_unit=length_unit)  # type: ignore[arg-type]
    m = read_frf_measurement_uff(path)
    back, notes = m.frf, m.provenance.notes
    rtol = RTOL_BINARY if binary else RTOL_ASCII
    assert_allclose(back.freq, fs.freq, rtol=1e-15)
    assert back.H.shape == fs.H.shape
    assert_allclose(back.H, fs.H, rtol=rtol, atol=0)
    assert_array_equal(back.resp_nodes, fs.resp_nodes)
    assert_array_equal(back.exc_nodes, fs.exc_nodes)
    assert_allclose(back.resp_dirs, fs.resp_dirs, atol=1e-12)
    assert_allclose(back.exc_dirs, fs.exc_dirs, atol=1e-12)
    assert_array_equal(back.geometry.node_ids, fs.geometry.node_ids)
    assert_allclose(back.geometry.xyz, fs.geometry.xyz, rtol=0, atol=1e-15)
    if fs.coherence is None:
        assert back.coherence is None and "coherence: absent" in notes
    else:
        assert back.coherence is not None and "coherence: complete" in notes
        assert_allclose(back.coherence, fs.coherence, rtol=0, atol=1e-11 if not binary else 0)
    assert ("lengths x 0.001, forces x 1 to SI" in notes[0] if length_unit == "mm"
            else notes[0] == "units: SI")
    assert m.source == "frf.uff" and not m.provenance.estimated
    assert "ordinates: acceleration" in notes


def test_written_file_layout(tmp_path: Path, engine: FRFSet, block: FRFSet) -> None:
    """Skewed triaxial sensor: own CS as disp_cs, codes +1 +2 +3; skewed forces too."""
    write_frf_uff(tmp_path / "e.uff", engine, length_unit="mm", coherence=False, binary=True)
    sets = pyuff.UFF(str(tmp_path / "e.uff")).read_sets()
    nodes = next(s for s in sets if s["type"] == 2411)
    cs = next(s for s in sets if s["type"] == 2420)
    disp = dict(zip(nodes["node_nums"].astype(int), nodes["disp_cs"].astype(int), strict=True))
    assert disp[3] != 0 and all(disp[n] == 0 for n in (1, 2, 4, *range(101, 119)))
    k = cs["CS_sys_labels"].index(disp[3])
    R_skew = Rotation.from_euler("zyx", (-35.0, 15.0, 25.0), degrees=True).as_matrix()
    assert_allclose(cs["CS_matrices"][k][:3], R_skew.T, atol=1e-15)  # rows = local axes
    frf = [s for s in sets if s["type"] == 58]
    assert len(frf) == 12 * 18 and {s["func_type"] for s in frf} == {4}
    assert sorted({s["rsp_dir"] for s in frf if s["rsp_node"] == 3}) == [1, 2, 3]
    assert_allclose(nodes["x"][list(nodes["node_nums"]).index(1)], 200.0, rtol=1e-15)  # mm

    write_frf_uff(tmp_path / "b.uff", block)
    sets = pyuff.UFF(str(tmp_path / "b.uff")).read_sets()
    nodes = next(s for s in sets if s["type"] == 2411)
    with_cs = {int(n) for n, c in zip(nodes["node_nums"], nodes["disp_cs"], strict=True) if c}
    assert with_cs == {3, 108, 109}
    assert {s["ref_dir"] for s in sets if s["type"] == 58 and s["ref_node"] == 108} == {1}


def test_round_trip_reordered_and_negative_directions(tmp_path: Path, small: FRFSet) -> None:
    order = np.array([5, 0, 3, 1, 4, 2])
    fs = replace(small, H=small.H[order][:, ::-1], resp_nodes=small.resp_nodes[order],
                 resp_dirs=-small.resp_dirs[order], exc_nodes=small.exc_nodes[::-1],
                 exc_dirs=small.exc_dirs[::-1])
    write_frf_uff(tmp_path / "r.uff", fs, binary=True)
    back = read_frf_uff(tmp_path / "r.uff")
    assert_array_equal(back.resp_nodes, fs.resp_nodes)
    assert_allclose(back.resp_dirs, fs.resp_dirs, atol=1e-12)
    assert_allclose(back.exc_dirs, fs.exc_dirs, atol=1e-12)
    assert_allclose(back.H, fs.H, rtol=RTOL_BINARY)


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_frequency_axis_without_short_decimal(tmp_path: Path, small: FRFSet, binary: bool) -> None:
    """1/3 Hz spacing: binary stores every line (exact); ASCII keeps 6 digits (E13.5)."""
    freq = np.arange(1, 25) / 3.0
    write_frf_uff(tmp_path / "f.uff", replace(small, freq=freq), binary=binary)
    back = read_frf_uff(tmp_path / "f.uff")
    assert_allclose(back.freq, freq, rtol=1e-15 if binary else 5e-6)
    if not binary:
        assert not np.array_equal(back.freq, freq)  # the 6-digit limit is real


# --- files written by pyuff -------------------------------------------------------------------


@pytest.mark.parametrize("explicit_exponent", [True, False], ids=["exp-field", "implied"])
@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_pyuff_file_in_mm(tmp_path: Path, small: FRFSet, binary: bool,
                          explicit_exponent: bool) -> None:
    """Accelerance in (mm/s^2)/N, coordinates in mm; exponents given or implied by type 12."""
    geo = small.geometry
    nodes = np.unique(np.r_[small.resp_nodes, small.exc_nodes])
    xyz = geo.coordinates(nodes)
    frames, codes = assign_node_frames(np.r_[small.resp_nodes, small.exc_nodes],
                                       np.r_[small.resp_dirs, small.exc_dirs])
    labels = {3: 7, 108: 9, 109: 11}
    assert set(frames) == set(labels)
    cs = pyuff.prepare_2420(Part_UID=1, Part_Name="p", CS_sys_labels=list(labels.values()),
                            CS_types=[0] * 3, CS_colors=[1] * 3, CS_names=["a", "b", "c"],
                            CS_matrices=[np.vstack([frames[n].T, np.zeros(3)]) for n in labels])
    node_set = nodes2411(nodes.tolist(), xyz * 1000, disp_cs=[labels.get(n, 0) for n in nodes])
    recs = []
    n_r = small.resp_nodes.size
    for j in range(small.exc_nodes.size):
        for i in range(n_r):
            recs.append(rec58((int(small.resp_nodes[i]), int(codes[i])),
                              (int(small.exc_nodes[j]), int(codes[n_r + j])), small.freq,
                              small.H[i, j] * 1000, binary=binary,
                              ord_len_exp=1 if explicit_exponent else 0))
    path = pyuff_write(tmp_path / "p.uff", [units164(1000.0), cs, node_set, *recs])
    back = read_frf_uff(path)
    assert_allclose(back.H, small.H, rtol=RTOL_BINARY if binary else RTOL_ASCII, atol=0)
    assert_allclose(back.resp_dirs, small.resp_dirs, atol=1e-12)
    assert_allclose(back.exc_dirs, small.exc_dirs, atol=1e-12)
    assert_allclose(back.geometry.coordinates(nodes), xyz, rtol=1e-15, atol=1e-15)
    assert back.coherence is None


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_velocity_and_displacement_frfs(tmp_path: Path, small: FRFSet, binary: bool) -> None:
    """Mobility (x j w) and receptance (x -w^2), in mm, against the exact accelerance."""
    w = 2 * np.pi * small.freq
    xyz = small.geometry.coordinates(np.unique(np.r_[small.resp_nodes, small.exc_nodes]))
    resp_ids = [1, 2, 3]  # three global-axis responses at node 1 and 2 (x, y, z)
    recs = []
    for j, kind in enumerate([11, 8, 12]):  # velocity, displacement, acceleration per reference
        for i in range(3):
            H = small.H[i, j]
            data = {11: H / (1j * w), 8: -H / w**2, 12: H}[kind] * 1000.0
            recs.append(rec58((1, resp_ids[i]), (2, j + 1), small.freq, data, binary=binary,
                              ordinate=kind))
    path = small_file(tmp_path, recs, nodes=nodes2411([1, 2], xyz[:2] * 1000))
    m = read_frf_measurement_uff(path)
    back = m.frf
    assert_allclose(back.H, small.H[:3, :3], rtol=RTOL_BINARY if binary else RTOL_ASCII, atol=0)
    assert_allclose(back.resp_dirs, np.eye(3), atol=0)
    assert "ordinates: acceleration, displacement, velocity" in m.provenance.notes


def test_coordinate_system_2420_rotated_and_translated(tmp_path: Path) -> None:
    """CS 5: local x = global +Y, local y = global -X, origin (100, 200, 300) mm."""
    M5 = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [100.0, 200.0, 300.0]])
    R6 = Rotation.from_euler("zyx", (30.0, -20.0, 10.0), degrees=True).as_matrix()
    M6 = np.vstack([R6.T, [-50.0, 0.0, 25.0]])
    cs = pyuff.prepare_2420(Part_UID=1, Part_Name="p", CS_sys_labels=[5, 6], CS_types=[0, 0],
                            CS_colors=[1, 1], CS_names=["rot z", "skew"], CS_matrices=[M5, M6])
    nodes = nodes2411([7, 8, 9], np.array([[10.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 2.0, 3.0]]),
                      def_cs=[5, 0, 6], disp_cs=[5, 0, 6])
    recs = [rec58((7, d), (8, 3), FREQ, DATA) for d in (1, -2, 3)]
    recs += [rec58((9, d), (8, 3), FREQ, DATA) for d in (1, 2, -3)]
    path = pyuff_write(tmp_path / "cs.uff", [units164(1000.0), cs, nodes, *recs])
    geometry, rotations = read_geometry(pyuff.UFF(str(path)).read_sets())
    assert_allclose(geometry.coordinates(np.array([7, 8])),
                    np.array([[0.1, 0.21, 0.3], [0.0, 0.0, 0.0]]), atol=1e-15)
    assert_allclose(geometry.coordinates(np.array([9]))[0],
                    (R6 @ [1.0, 2.0, 3.0] + [-50.0, 0.0, 25.0]) / 1000, atol=1e-15)
    assert_allclose(rotations[7], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=0)
    assert_allclose(rotations[8], np.eye(3), atol=0)
    back = read_frf_uff(path)
    expected = np.array([[0, 1, 0], [1, 0, 0], [0, 0, 1], *R6[:, 0:2].T, -R6[:, 2]])
    assert_allclose(back.resp_dirs, expected, atol=1e-15)
    assert_allclose(back.exc_dirs, [[0, 0, 1]], atol=0)
    assert_allclose(back.H[:, 0, :], np.tile(DATA / 1000, (6, 1)), rtol=RTOL_ASCII)  # mm -> m
    assert_allclose(read_geometry_uff(path)[0].xyz, geometry.xyz, atol=0)


def test_dataset_15_nodes(tmp_path: Path) -> None:
    nodes = pyuff.prepare_15(node_nums=[1, 2], def_cs=[0, 0], disp_cs=[0, 0], color=[1, 1],
                             x=[123.456789, 0.0], y=[0.0, -5.0], z=[7.25, 0.0])
    path = pyuff_write(tmp_path / "n15.uff", [units164(1000.0), nodes,
                                               rec58((1, 1), (2, -3), FREQ, DATA)])
    back = read_frf_uff(path)
    assert_allclose(back.geometry.xyz, [[0.123457, 0.0, 0.00725], [0.0, -0.005, 0.0]],
                    rtol=1e-12, atol=1e-15)  # E13.5: 6 significant digits
    assert_allclose(back.exc_dirs, [[0, 0, -1]], atol=0)


def test_write_dataset_15(tmp_path: Path, small: FRFSet) -> None:
    write_frf_uff(tmp_path / "n15.uff", small, node_dataset=15, length_unit="mm")
    assert {s["type"] for s in pyuff.UFF(str(tmp_path / "n15.uff")).read_sets()} == {
        164, 2420, 15, 58}
    back = read_frf_uff(tmp_path / "n15.uff")
    assert_allclose(back.geometry.xyz, small.geometry.xyz, rtol=5e-6, atol=1e-15)
    assert_allclose(back.H, small.H, rtol=RTOL_ASCII)


def test_duplicate_opposite_sign_is_one_dof(tmp_path: Path) -> None:
    """Response 1:+1 for reference 2:+1 and 1:-1 for 2:+2 are the same DOF, data negated."""
    path = small_file(tmp_path, [rec58((1, 1), (2, 1), FREQ, DATA),
                                 rec58((1, -1), (2, 2), FREQ, 2 * DATA)], length=1.0)
    back = read_frf_uff(path)
    assert_allclose(back.resp_dirs, [[1, 0, 0]])
    assert_allclose(back.H[0], [DATA, -2 * DATA], rtol=RTOL_ASCII)


def test_coherence_incomplete_is_none(tmp_path: Path) -> None:
    recs = [rec58((1, 1), (2, d), FREQ, DATA) for d in (1, 2)]
    recs.append(rec58((1, 1), (2, 1), FREQ, np.full(8, 0.9), func_type=6, ordinate=1,
                      denominator=0))
    m = read_frf_measurement_uff(small_file(tmp_path, recs))
    assert m.frf.coherence is None
    assert "coherence: incomplete (1 of 2 pairs)" in m.provenance.notes


def test_read_units() -> None:
    assert read_units([]).length == 1.0
    u = read_units(units164(1000.0))
    assert (u.length, u.force, u.to_si(1, 0)) == (1000.0, 1.0, 1e-3)
    with pytest.raises(InputError) as excinfo:
        read_units([units164(1000.0), units164(1.0)])
    one_line_error(excinfo, "different unit systems")


# --- errors -----------------------------------------------------------------------------------


def test_missing_and_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(tmp_path / "nope.uff")
    one_line_error(excinfo, "not found", "nope.uff")
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(tmp_path)
    one_line_error(excinfo, "is not a file")
    (tmp_path / "text.uff").write_text("hello\nworld\n")
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(tmp_path / "text.uff")
    one_line_error(excinfo, "no UFF datasets", "text.uff")
    (tmp_path / "bad.uff").write_text("    -1\n    58\nNONE\n    -1\n")
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(tmp_path / "bad.uff")
    one_line_error(excinfo, "cannot read UFF file bad.uff")
    assert excinfo.value.__cause__ is not None


def test_no_geometry(tmp_path: Path) -> None:
    path = pyuff_write(tmp_path / "g.uff", [rec58((1, 1), (2, 1), FREQ, DATA)])
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(path)
    one_line_error(excinfo, "no node coordinates", "15 or 2411")


def test_frf_node_without_coordinates(tmp_path: Path) -> None:
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, [rec58((1, 1), (42, 1), FREQ, DATA)]))
    one_line_error(excinfo, "excitation node(s) 42 have no coordinates")


def test_no_frf_records(tmp_path: Path) -> None:
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, [rec58((1, 1), (2, 1), FREQ, DATA.real, func_type=1,
                                                 abscissa=17)]))
    one_line_error(excinfo, "no FRF records", "function type 4")


def test_duplicate_pair(tmp_path: Path) -> None:
    recs = [rec58((1, 1), (2, 1), FREQ, DATA), rec58((1, -1), (2, 1), FREQ, DATA)]
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, recs))
    one_line_error(excinfo, "response 1:+1 and reference 2:+1 is given twice", "#3 and #4")


def test_missing_pair(tmp_path: Path) -> None:
    recs = [rec58((1, 1), (2, 1), FREQ, DATA), rec58((1, 2), (2, 3), FREQ, DATA)]
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, recs))
    one_line_error(excinfo, "lacks the FRF of 2 of 4", "response 1:+1 with reference 2:+3")


def raw_file(path: Path, records: list[tuple[int, int, np.ndarray]], binary: bool) -> Path:
    """Nodes 1, 2 and records (func_type, ordinate type, data) written without any checks.

    pyuff cannot write NaN (it replaces them by 0), other tools do (pyFRF's 0 Hz line).
    """
    with open_for_writing(path) as w:
        w.nodes(2411, np.array([1, 2]), np.zeros((2, 3)), np.zeros(2, dtype=np.int64))
        for func_type, kind, data in records:
            w.function(func_type=func_type, func_id=1, load_case=1, response=(1, 1),
                       reference=(2, 1), x=np.arange(data.size, dtype=float), data=data,
                       abscissa=AxisInfo(), ordinate=AxisInfo(kind), denominator=AxisInfo(13),
                       ids=[], binary=binary)
    return path


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_or_infinite_values(tmp_path: Path, bad: float, binary: bool) -> None:
    data = DATA.copy()
    data[2] = bad
    path = raw_file(tmp_path / "n.uff", [(4, 12, data)], binary)
    held = read_frf_uff(path).H[0, 0]  # the reader gives what the file holds...
    assert not np.isfinite(held[2]) and np.isfinite(np.delete(held, 2)).all()
    with pytest.raises(InputError) as excinfo:  # ...the pipeline's load names it
        load(path, fmt=FRF_UFF)
    one_line_error(excinfo, "n.uff: NaN or infinite values in FRF 1+X/2+X (response/excitation) "
                            "on 1 of 8 lines (2 Hz): more than 10% of the lines")
    force = np.ones(8)
    with pytest.raises(InputError) as excinfo:
        read_time_uff(raw_file(tmp_path / "t.uff", [(1, 13, force), (1, 12, data.real)], binary))
    one_line_error(excinfo, "load case 1: dataset #3", "1 NaN or infinite sample(s)")


@pytest.mark.parametrize(
    ("kwargs", "fragments"),
    [
        ({"ordinate": 0}, ("unknown FRF ordinate type 0 (unknown)", "12 (acceleration)")),
        ({"ordinate": 2}, ("unknown FRF ordinate type 2",)),
        ({"denominator": 9}, ("denominator type 9", "force (13)")),
        ({"abscissa": 19}, ("abscissa type 19 is not frequency",)),
    ],
)
def test_unsupported_types(tmp_path: Path, kwargs: dict[str, Any],
                           fragments: tuple[str, ...]) -> None:
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, [rec58((1, 1), (2, 1), FREQ, DATA, **kwargs)]))
    one_line_error(excinfo, "dataset #3 (response 1:+1, reference 2:+1)", *fragments)


def test_real_frf_values_and_rotation_codes(tmp_path: Path) -> None:
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, [rec58((1, 1), (2, 1), FREQ, DATA.real)]))
    one_line_error(excinfo, "FRF values are real")
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, [rec58((1, 5), (2, 1), FREQ, DATA)]))
    one_line_error(excinfo, "response direction code 5 is a rotation")


def test_different_frequency_axes(tmp_path: Path) -> None:
    recs = [rec58((1, 1), (2, 1), FREQ, DATA), rec58((1, 1), (2, 2), FREQ * 2, DATA)]
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, recs))
    one_line_error(excinfo, "8 lines from 2 to 16 Hz", "one frequency axis")


def test_bad_coordinate_systems(tmp_path: Path) -> None:
    xyz = np.zeros((2, 3))
    undefined = nodes2411([1, 2], xyz, disp_cs=[3, 0])
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, [rec58((1, 1), (2, 1), FREQ, DATA)], nodes=undefined))
    one_line_error(excinfo, "node 1 refers to coordinate system 3", "2420")
    cyl = pyuff.prepare_2420(Part_UID=1, Part_Name="p", CS_sys_labels=[3], CS_types=[1],
                             CS_colors=[1], CS_names=["c"],
                             CS_matrices=[np.vstack([np.eye(3), np.zeros(3)])])
    with pytest.raises(InputError) as excinfo:
        read_frf_uff(small_file(tmp_path, [cyl, rec58((1, 1), (2, 1), FREQ, DATA)],
                                nodes=undefined))
    one_line_error(excinfo, "coordinate system 3 (used by node 1) is cylindrical")


def test_write_errors(tmp_path: Path, small: FRFSet) -> None:
    skew = small.resp_dirs.copy()
    skew[4] = (skew[3] + skew[4]) / np.sqrt(2)  # 45 deg from the first axis of skewed node 3
    with pytest.raises(InputError) as excinfo:
        write_frf_uff(tmp_path / "w.uff", replace(small, resp_dirs=skew))
    one_line_error(excinfo, "node 3 has directions", "at 45 deg", "one orthonormal frame")
    H = small.H.copy()
    H[0, 0, 3] = np.nan
    with pytest.raises(InputError, match="NaN or infinite"):
        write_frf_uff(tmp_path / "w.uff", replace(small, H=H))
    with pytest.raises(InputError, match="at least 2"):
        write_frf_uff(tmp_path / "w.uff", replace(small, freq=small.freq[:1], H=small.H[..., :1]))
    with pytest.raises(InputError, match="length_unit"):
        write_frf_uff(tmp_path / "w.uff", small, length_unit="inch")  # type: ignore[arg-type]
    dup = replace(small, resp_dirs=np.r_[small.resp_dirs[:1], -small.resp_dirs[:1],
                                         small.resp_dirs[2:]])
    with pytest.raises(InputError, match="response DOF at node 2 along axis 1"):
        write_frf_uff(tmp_path / "w.uff", dup)
    assert not list(tmp_path.iterdir())  # nothing written, no temporary left behind


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 3), st.permutations([0, 1, 2]),
       st.lists(st.sampled_from([-1.0, 1.0]), min_size=3, max_size=3))
def test_assign_node_frames_recovers_directions(seed: int, n_dirs: int, order: list[int],
                                                signs: list[float]) -> None:
    R = Rotation.random(random_state=seed).as_matrix()
    dirs = (R[:, order] * signs)[:, :n_dirs].T
    frames, codes = assign_node_frames(np.full(n_dirs, 5), dirs)
    F = frames[5]
    assert_allclose(F.T @ F, np.eye(3), atol=1e-12)
    assert np.linalg.det(F) > 0
    assert_allclose(np.sign(codes)[:, None] * F[:, np.abs(codes) - 1].T, dirs, atol=1e-15)
    if n_dirs == 3 and np.linalg.det(dirs.T) > 0:
        assert_array_equal(codes, [1, 2, 3])


# --- time records -----------------------------------------------------------------------------


def engine_runs(fs: float, n: int = 256) -> tuple[list[TimeRun], Geometry]:
    bench = get_bench("engine")
    rng = np.random.default_rng(7)
    runs = [
        TimeRun(load_case=lc, fs=fs, force=rng.standard_normal(n), exc_node=int(bench.exc_nodes[k]),
                exc_dir=bench.exc_dirs[k], responses=rng.standard_normal((12, n)),
                resp_nodes=bench.resp_nodes, resp_dirs=bench.resp_dirs)
        for lc, k in ((1, 0), (2, 4), (7, 17))
    ]
    return runs, bench.geometry


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
@pytest.mark.parametrize("fs", [2048.0, 1000.0 / 3.0])
def test_time_round_trip(tmp_path: Path, binary: bool, fs: float) -> None:
    runs, geometry = engine_runs(fs)
    write_time_uff(tmp_path / "t.uff", runs, geometry, binary=binary)
    back = read_time_uff(tmp_path / "t.uff")
    assert [r.load_case for r in back] == [1, 2, 7]
    exact = binary or fs == 2048.0  # integer rates snap back exactly; 1000/3 Hz keeps 6 digits
    rtol = RTOL_BINARY if binary else RTOL_ASCII
    for a, b in zip(back, runs, strict=True):
        assert a.fs == fs if exact else abs(a.fs / fs - 1) < 5e-6
        assert a.exc_node == b.exc_node
        assert_allclose(a.exc_dir, b.exc_dir, atol=1e-12)
        assert_allclose(a.force, b.force, rtol=rtol)
        assert_allclose(a.responses, b.responses, rtol=rtol)
        assert_array_equal(a.resp_nodes, b.resp_nodes)
        assert_allclose(a.resp_dirs, b.resp_dirs, atol=1e-12)
    geo, rot = read_geometry_uff(tmp_path / "t.uff")
    assert_allclose(geo.xyz, geometry.xyz, atol=1e-15)
    assert not np.allclose(rot[3], np.eye(3))


def time_rec(node: int, direction: int, lc: int, data: np.ndarray, *, kind: int = 12,
             dt: float = 1 / 1024, binary: bool = False) -> dict[str, Any]:
    return rec58((node, direction), (2, 3), np.arange(data.size) * dt, data, binary=binary,
                 ordinate=kind, denominator=0, func_type=1, load_case=lc, abscissa=17)


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_time_file_from_pyuff_with_bad_runs(tmp_path: Path, binary: bool) -> None:
    rng = np.random.default_rng(0)
    f, a = rng.standard_normal(64), rng.standard_normal(64)
    recs = [
        time_rec(2, 3, 1, f, kind=13, binary=binary), time_rec(1, 1, 1, a * 1000, binary=binary),
        time_rec(1, 2, 1, a * 2000, binary=binary),
        time_rec(1, 1, 2, a, binary=binary),  # no force
        time_rec(2, 3, 3, f, kind=13, binary=binary),
        time_rec(1, 1, 3, a, dt=1 / 2048, binary=binary),  # other rate
        time_rec(2, 3, 4, f, kind=13, binary=binary), time_rec(1, 1, 4, a[:32], binary=binary),
        time_rec(2, 3, 5, f, kind=13, binary=binary), time_rec(2, 3, 5, f, kind=13, binary=binary),
        time_rec(2, 3, 6, f, kind=13, binary=binary), time_rec(1, 1, 6, a, kind=11, binary=binary),
    ]
    path = small_file(tmp_path, recs)
    with pytest.raises(InputError) as excinfo:
        read_time_uff(path)
    one_line_error(excinfo, "load case 2: no force record", "(4 more run(s) with problems)")
    runs, problems = read_time_uff(path, strict=False)
    assert len(runs) == 1
    run = runs[0]
    assert (run.load_case, run.fs, run.exc_node) == (1, 1024.0, 2)
    assert_allclose(run.exc_dir, [0, 0, 1])
    assert_allclose(run.force, f, rtol=RTOL_ASCII)
    assert_allclose(run.responses, [a, 2 * a], rtol=RTOL_ASCII)  # mm/s^2 -> m/s^2
    assert_allclose(run.resp_dirs, [[1, 0, 0], [0, 1, 0]])
    assert [lc for lc, _ in problems] == [2, 3, 4, 5, 6]
    messages = dict(problems)
    assert "no force record (ordinate type 13)" in messages[2]
    assert "different sample rates (1024, 2048 Hz)" in messages[3]
    assert "different lengths (32, 64 samples)" in messages[4]
    assert "2 force records (datasets #11, #12)" in messages[5]
    assert "ordinate type 11 (velocity)" in messages[6]
    assert all(m.startswith(f"load case {lc}:") and "\n" not in m for lc, m in problems)


def test_time_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError) as excinfo:
        read_time_uff(small_file(tmp_path, [rec58((1, 1), (2, 1), FREQ, DATA)]))
    one_line_error(excinfo, "no time records", "function type 1")
    runs, geometry = engine_runs(1024.0, n=16)
    with pytest.raises(InputError, match="load case numbers repeat"):
        write_time_uff(tmp_path / "t.uff", [runs[0], runs[0]], geometry)
    with pytest.raises(InputError, match="time record node"):
        write_time_uff(tmp_path / "t.uff", runs, Geometry(np.array([1]), np.zeros((1, 3))))
    with pytest.raises(InputError, match="1 response channels but 2 nodes"):
        TimeRun(1, 100.0, np.zeros(4), 1, np.array([1.0, 0, 0]), np.zeros((1, 4)),
                np.array([1, 2]), np.eye(3)[:2])
