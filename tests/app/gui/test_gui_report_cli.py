"""``insitu report`` on a UFF file, and its one-line errors."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from app.cli.main import main
from app.io.uff import write_frf_uff
from hardware_mocks.benches import get_bench


def test_report_from_uff(tmp_path: Path, qapp, capsys: pytest.CaptureFixture[str]) -> None:
    uff = tmp_path / "block.uff"
    write_frf_uff(uff, get_bench("block-rigid").frfset())
    assert main(["report", str(uff)]) == 0
    html = (tmp_path / "block.html").read_text()
    assert len(re.findall(r"data:image/png;base64,", html)) == 6
    mass = re.search(r"<td class=\"l\">mass m</td><td class=\"l\">kg</td>"
                     r"<td>([0-9.]+)(?: ± [^<]*)?</td>", html)
    assert mass is not None and float(mass.group(1)) == pytest.approx(160.6, abs=1e-3)
    assert "identified mass 160.60 kg" in capsys.readouterr().out


@pytest.mark.parametrize(("name", "content", "expect"), [
    ("missing.uff", None, "no such file"),
    ("notes.txt", "hello", "unknown file type"),
    ("bad.h5", "not hdf5", "not a readable HDF5 run file"),
])
def test_report_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    name: str, content: str | None, expect: str) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    assert main(["report", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expect in err and err.startswith("insitu report: error:")
