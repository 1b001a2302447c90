"""NaN or infinite FRF values: named by the pipeline's one load, whatever the view."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from app.cli.main import main
from app.io.frf_h5 import write_frf_h5
from app.io.uff import read_frf_uff, write_frf_uff
from app.pipeline import OpenError, load
from app.report.sources import open_source
from hardware_mocks.benches import get_bench
from processing.data import FRFSet


@pytest.fixture(scope="module")
def bench() -> FRFSet:
    return get_bench("engine-rigid").frfset(0.01, seed=2)


def _with_nan(bench: FRFSet, path: Path) -> Path:
    """FRF file of the bench with 5 lines of one FRF NaN and one value of another infinite,
    and NaN coherence on 3 lines of a third."""
    H = bench.H.copy()
    H[2, 3, 100:105] = np.nan
    H[5, 3, 300] = np.inf
    coh = np.ones(H.shape)
    coh[1, 1, 200:203] = np.nan
    write_frf_h5(path, dataclasses.replace(bench, H=H, coherence=coh))
    return path


def test_a_few_nan_lines_are_named_and_left_out(bench: FRFSet, tmp_path: Path) -> None:
    m = load(_with_nan(bench, tmp_path / "nan.h5"))
    lost = np.r_[100:105, 300]
    keep = np.setdiff1d(np.arange(bench.freq.size), lost)
    assert_array_equal(m.frf.freq, bench.freq[keep])
    assert_array_equal(m.frf.H, bench.H[..., keep])
    assert m.frf.coherence is not None and np.isfinite(m.frf.coherence).all()
    assert np.count_nonzero(m.frf.coherence == 0) == 3
    f = bench.freq
    assert [r.message for r in m.provenance.reports] == [
        f"nan.h5: NaN or infinite values in FRFs 1+Z/104-X, 2+Z/104-X (response/excitation) "
        f"on 6 lines ({f[100]:g}-{f[104]:g}, {f[300]:g} Hz): those lines are left out of every "
        "FRF",
        f"nan.h5: NaN or infinite coherence in FRF 1+Y/102+Y (response/excitation) on 3 lines "
        f"({f[200]:g}-{f[202]:g} Hz): those values count as coherence 0 (next to no weight in "
        "the fit)"]
    assert m.provenance.skipped == 0
    assert open_source(tmp_path / "nan.h5")[0].provenance.reports == m.provenance.reports


def test_identify_names_them_and_fits_the_other_lines(
        bench: FRFSet, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _with_nan(bench, tmp_path / "nan.h5")
    assert main(["identify", str(path), "--no-uncertainty"]) == 0
    out = capsys.readouterr().out
    assert "nan.h5: NaN or infinite values in FRFs 1+Z/104-X, 2+Z/104-X" in out
    assert "nan.h5: NaN or infinite coherence in FRF 1+Y/102+Y" in out
    assert f"{bench.H.shape[0]} response DOFs x {bench.H.shape[1]} excitations, " \
           f"{bench.freq.size - 6} lines" in out


def test_an_frf_undefined_on_many_lines_or_all_nan_is_refused(
        bench: FRFSet, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    H = bench.H.copy()
    H[4, 0] = np.nan  # a dead channel on one excitation
    write_frf_h5(tmp_path / "dead.h5", dataclasses.replace(bench, H=H))
    n = bench.freq.size
    with pytest.raises(OpenError, match=r"^dead\.h5: NaN or infinite values in FRF 2\+Y/101\+X "
                                        rf"\(response/excitation\) on {n} of {n} lines "):
        load(tmp_path / "dead.h5")
    write_frf_h5(tmp_path / "all.h5", dataclasses.replace(bench, H=H * np.nan))
    assert main(["identify", str(tmp_path / "all.h5")]) == 2
    assert capsys.readouterr().err.strip() == ("insitu identify: error: all.h5: every FRF value "
                                               "is NaN or infinite: re-export the FRFs")


def test_a_uff_file_with_a_nan_line_is_read_and_named(bench: FRFSet, tmp_path: Path) -> None:
    """pyFRF's accelerance at 0 Hz is NaN: such a file opens, the line named and left out."""
    path = tmp_path / "zero.uff"
    write_frf_uff(path, bench, binary=True)
    text = path.read_bytes()
    first = np.float64(bench.H[0, 0, 0].real).tobytes()
    assert text.count(first) == 1
    path.write_bytes(text.replace(first, np.float64(np.nan).tobytes()))
    assert np.isnan(read_frf_uff(path).H[0, 0, 0])
    m = load(path)
    assert_array_equal(m.frf.freq, bench.freq[1:])
    assert [r.message for r in m.provenance.reports] == [
        f"zero.uff: NaN or infinite values in FRF 1+X/101+X (response/excitation) on 1 line "
        f"({bench.freq[0]:g} Hz): those lines are left out of every FRF"]
