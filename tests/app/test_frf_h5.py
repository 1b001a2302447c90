"""HDF5 FRF files: round trip, layout, one-line errors, ``insitu identify FRF.h5``."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
from numpy.testing import assert_array_equal

from app.cli.main import main
from app.io.frf_h5 import (
    FRFFileError,
    h5_format,
    read_frf_h5,
    read_frf_measurement,
    write_frf_h5,
)
from hardware_mocks.benches import get_bench
from processing.measurement import Measurement, Provenance


@pytest.fixture(scope="module")
def engine() -> tuple[Measurement, tuple[float, float]]:
    """Engine-rigid FRFs (1 % noise) with coherence below 0.8 in one range of the mass band,
    estimated from hits under an exponential window (tau 0.5 s)."""
    b = get_bench("engine-rigid")
    frf = b.frfset(noise=0.01)
    coh = 1.0 - 0.05 * np.random.default_rng(3).random(frf.H.shape)
    lo, hi = b.article_bands[0]
    low = np.flatnonzero((frf.freq >= lo) & (frf.freq <= hi))[5:9]  # 4 lines in the mass band
    coh[2, 4, low] = 0.5
    coh[0, 0, -3:] = 0.1  # outside both bands: no effect on the identification
    prov = Provenance(origin="estimated", excitation="impact", exponential_tau=0.5,
                      n_averages=tuple(range(frf.H.shape[1])), run_state="finished",
                      notes=("units: SI",))
    return (Measurement(replace(frf, coherence=coh), prov),
            (float(frf.freq[low[0]]), float(frf.freq[low[-1]])))


def test_round_trip_and_layout(tmp_path: Path, engine: tuple[Measurement, object]) -> None:
    m, _ = engine
    frf = m.frf
    path = tmp_path / "frf.h5"
    write_frf_h5(path, m, source="time.uff")
    back = read_frf_h5(path)
    for name in ("freq", "H", "coherence", "resp_nodes", "resp_dirs", "exc_nodes", "exc_dirs"):
        assert_array_equal(getattr(back, name), getattr(frf, name), err_msg=name)
    assert_array_equal(back.geometry.node_ids, frf.geometry.node_ids)
    assert_array_equal(back.geometry.xyz, frf.geometry.xyz)
    kept = read_frf_measurement(path)
    assert kept.provenance == m.provenance and kept.provenance.exponential_tau == 0.5
    assert kept.source == "frf.h5"
    assert_array_equal(kept.frf.H, frf.H)
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "insitu-frf" and f.attrs["schema_version"] == 2
        assert f.attrs["source"] == "time.uff" and f.attrs["estimator"] == "H1"
        units: dict[str, str] = {}
        f.visititems(lambda n, o: units.update({n: o.attrs["units"]})
                     if isinstance(o, h5py.Dataset) else None)
    assert units == {"freq": "Hz", "H": "m/s^2/N", "coherence": "1", "resp_nodes": "1",
                     "resp_dirs": "1", "exc_nodes": "1", "exc_dirs": "1",
                     "geometry/node_ids": "1", "geometry/xyz": "m"}
    assert h5_format(path) == "insitu-frf"
    # without coherence, bare FRFs: given
    bare = replace(frf, coherence=None)
    write_frf_h5(path, bare)
    again = read_frf_h5(path)
    assert again.coherence is None
    assert read_frf_measurement(path).provenance == Provenance()  # FRFs given


def test_bad_files_are_one_line(tmp_path: Path, engine: tuple[Measurement, object]) -> None:
    frf = engine[0].frf
    with pytest.raises(FRFFileError, match="no such FRF file"):
        read_frf_h5(tmp_path / "missing.h5")
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(FRFFileError, match="not a readable HDF5 file"):
        read_frf_h5(tmp_path / "text.h5")
    assert h5_format(tmp_path / "text.h5") == ""
    with h5py.File(tmp_path / "run.h5", "w") as f:
        f.attrs["format"] = "insitu-run"
    with pytest.raises(FRFFileError, match="not an insitu FRF file"):
        read_frf_h5(tmp_path / "run.h5")
    path = tmp_path / "frf.h5"
    write_frf_h5(path, frf)
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = 7
    with pytest.raises(FRFFileError, match="schema version 7; this insitu reads versions 1, 2"):
        read_frf_h5(path)
    write_frf_h5(path, engine[0])
    with h5py.File(path, "a") as f:
        f["provenance"].attrs["exponential_tau"] = "abc"
    with pytest.raises(FRFFileError, match="damaged FRF file: provenance field exponential_tau"):
        read_frf_h5(path)
    write_frf_h5(path, frf)
    with h5py.File(path, "a") as f:
        del f["H"]
    with pytest.raises(FRFFileError, match="damaged FRF file") as excinfo:
        read_frf_h5(path)
    assert "\n" not in str(excinfo.value)


def test_identify_reads_frf_file_and_reports_low_coherence(
        tmp_path: Path, engine: tuple[Measurement, tuple[float, float]],
        capsys: pytest.CaptureFixture[str]) -> None:
    frf, (lo, hi) = engine
    b = get_bench("engine-rigid")
    path, out = tmp_path / "frf.h5", tmp_path / "result.json"
    write_frf_h5(path, frf)
    (mlo, mhi), (slo, shi) = b.article_bands
    assert main(["identify", str(path), "--out", str(out), "--mass-band", str(mlo), str(mhi),
                 "--stiffness-band", str(slo), str(shi)]) == 0
    text = " ".join(capsys.readouterr().out.split())  # rich wraps at the terminal's width
    res = json.loads(out.read_text())
    assert abs(res["mass"] - b.model.mass) / b.model.mass < 0.01
    coh = res["checks"]["coherence"]
    assert coh["low_ranges_hz"] == [[lo, hi]] and coh["low_values"] == 4
    assert coh["pass"] and coh["threshold"] == 0.8  # 4 values of the bands' thousands
    assert "4 of" in text and f"weighted by their noise, not dropped; at {lo:g}-{hi:g} Hz" in text


def test_a_version_1_file_keeps_its_provenance_in_meta(tmp_path: Path,
                                                       engine: tuple[Measurement, object],
                                                       ) -> None:
    """Files written before ``/provenance`` kept the numbers the fit reads in ``/meta``."""
    path = tmp_path / "old.h5"
    write_frf_h5(path, engine[0].frf)
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = 1
        del f["provenance"]
        f.create_dataset("meta", data=json.dumps({
            "estimator": "H1", "excitation": "impact", "exponential_tau": 0.5,
            "force_band_top": 180.0, "from_time_records": True, "n_averages": [3, 3]}))
    prov = read_frf_measurement(path).provenance
    assert prov.estimated and prov.exponential_tau == 0.5 and prov.force_band_top == 180.0
    assert prov.n_averages == (3, 3) and prov.excitation == "impact"
