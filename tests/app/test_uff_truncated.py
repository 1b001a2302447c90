"""A universal file cut short is called truncated, by the reader and by every verb that reads it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io import read_frf_uff, write_frf_uff
from hardware_mocks.benches import get_bench
from processing.data import InputError


@pytest.fixture(scope="module", params=[False, True], ids=["ascii", "binary"])
def whole(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> bytes:
    fs = get_bench("engine").frfset()
    fs = replace(fs, freq=fs.freq[:64], H=fs.H[..., :64])
    p = tmp_path_factory.mktemp("uff") / "whole.uff"
    write_frf_uff(p, fs, binary=request.param, coherence=False)
    return p.read_bytes()


def _cuts(data: bytes) -> dict[str, int]:
    boundary = data.index(b"    -1\n    -1\n", len(data) // 2)  # between two datasets
    return {"mid-record": len(data) // 3, "mid-last-record": len(data) - 40,
            "after-an-opening-delimiter": boundary + 14}


def test_whole_file_reads(whole: bytes, tmp_path: Path) -> None:
    p = tmp_path / "whole.uff"
    p.write_bytes(whole)
    assert read_frf_uff(p).H.shape == (12, 18, 64)


@pytest.mark.parametrize("cut", ["mid-record", "mid-last-record", "after-an-opening-delimiter"])
def test_truncated_file_is_named_truncated(whole: bytes, tmp_path: Path, cut: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "cut.uff"
    p.write_bytes(whole[: _cuts(whole)[cut]])
    with pytest.raises(InputError, match=r"cut\.uff is truncated"):
        read_frf_uff(p)
    for verb in (["identify", str(p)], ["report", str(p), "--out", str(tmp_path / "r.html")],
                 ["frf", str(p), "--out", str(tmp_path / "f.uff")]):
        assert main(verb) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "is truncated" in err[0] and "export the file again" in err[0]
    assert not (tmp_path / "r.html").exists() and not (tmp_path / "f.uff").exists()


def test_trailing_blank_lines_and_crlf_are_not_truncation(whole: bytes, tmp_path: Path) -> None:
    p = tmp_path / "crlf.uff"
    p.write_bytes(whole + b"\r\n\r\n  \n")
    assert np.isfinite(read_frf_uff(p).H).all()
