"""``insitu identify`` with the uncertainty options: units, one-line errors, the result JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff import write_frf_uff
from app.pipeline.settings import ANGLE_UNITS, LENGTH_UNITS, RELATIVE_UNITS, parse_quantity
from hardware_mocks.benches import get_bench
from processing.data import InputError


@pytest.mark.parametrize(("text", "units", "expected"), [
    ("3mm", LENGTH_UNITS, 0.003), ("0.5 cm", LENGTH_UNITS, 0.005), ("2e-3m", LENGTH_UNITS, 0.002),
    ("2deg", ANGLE_UNITS, math.radians(2)), ("10mrad", ANGLE_UNITS, 0.01),
    ("2%", RELATIVE_UNITS, 0.02), ("0.02", RELATIVE_UNITS, 0.02),
])
def test_quantities_in_user_units(text: str, units: dict[str, float], expected: float) -> None:
    assert parse_quantity("--x", text, units, "1", 1.0) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(("text", "message"), [
    ("3", "not a number with a unit"), ("3 parsec", "not a number with a unit"),
    ("2m", "from 0 to 0.5m"), ("inf mm", "not a number"),
])
def test_bad_quantities_named(text: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_quantity("--location-uncertainty", text, LENGTH_UNITS, "3mm", 0.5)


@pytest.fixture(scope="module")
def uff(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("unc") / "engine.uff"
    write_frf_uff(path, get_bench("engine-rigid").frfset(0.01, 0.002, seed=3), binary=True)
    return path


@pytest.mark.parametrize(("args", "message"), [
    (["--location-uncertainty", "3"], "--location-uncertainty '3' is not a number with a unit"),
    (["--angle-uncertainty", "45deg"], "--angle-uncertainty must be from 0 to 30deg"),
    (["--gain-uncertainty=-2%"], "--gain-uncertainty must be from 0"),
    (["--draws", "100"], "--draws needs --location-uncertainty"),
    (["--gain-uncertainty", "1%", "--draws", "1"], "--draws must be from 2"),
    (["--gain-uncertainty", "1%", "--no-uncertainty"], "--no-uncertainty contradicts"),
    (["--gain-uncertainty", "1%", "--method", "plain"], "improved method"),
])
def test_bad_options_one_line_exit_2(uff: Path, args: list[str], message: str,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", str(uff), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_std_by_default_and_monte_carlo_when_stated(uff: Path, tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    assert main(["identify", str(uff), "--out", str(out)]) == 0
    plain = json.loads(out.read_text())
    assert plain["std"]["mass"] > 0 and len(plain["uncertainty"]["sources"]) == 1
    assert main(["identify", str(uff), "--out", str(out), "--location-uncertainty", "2mm",
                 "--angle-uncertainty", "1deg", "--gain-uncertainty", "1%",
                 "--draws", "200"]) == 0
    r = json.loads(out.read_text())
    assert "Monte Carlo" in r["uncertainty"]["sources"][1]
    assert "200 draws" in r["uncertainty"]["sources"][1]
    # the stated geometry adds to the fit's own uncertainty
    assert np.all(np.asarray(r["std"]["cog"]) > np.asarray(plain["std"]["cog"]))
    sources = {c["source"] for c in r["uncertainty"]["contributions"]}
    assert any("location" in s for s in sources), sources
    assert main(["identify", str(uff), "--out", str(out), "--no-uncertainty"]) == 0
    assert "std" not in json.loads(out.read_text())
