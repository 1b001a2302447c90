"""``insitu frf`` and ``insitu identify`` on generated time records with default options: the
defaults read from the data, printed, and an answer close to the reference model's truth."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from app.io.uff import read_frf_uff
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import (
    HammerSpec,
    ShakerSpec,
    TimeTest,
    hammer_test,
    shaker_test,
    write_uff,
)


@cache
def _printed(text: str, prefix: str) -> str:
    """The first line of ``text`` that starts with ``prefix`` (a default's printed line)."""
    return next(ln for ln in text.splitlines() if ln.startswith(prefix))


def _hammer(seed: int) -> TimeTest:
    sc = build_scenario(ScenarioSpec(seed=seed, n_forces=9, n_sensors=4, elastic_ratio=None))
    return hammer_test(sc, HammerSpec(seed=seed, hits=4, spacing=3.0, n_double=1, n_clipped=1))


@pytest.mark.parametrize("seed", [2, 3])
def test_frf_then_identify_hammer_defaults(seed: int, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Measured over seeds 1-4 (rigid bodies): mass within 0.16 %, CoG within 0.34 mm."""
    t = _hammer(seed)
    src, frf, out = tmp_path / "time.uff", tmp_path / "frf.uff", tmp_path / "r.json"
    write_uff(t, src)
    assert main(["frf", str(src), "--out", str(frf)]) == 0
    text = capsys.readouterr().out
    assert "excitation impact (force impulsive in 9 of 9 runs" in text
    assert "trigger level " in text and "force window: " in text
    assert text.count("rejected: hit") == 2  # the double hit and the clipped one
    assert "double hit" in text and "clipped" in text
    line = _printed(text, "record ")
    record = float(line.split()[1])
    pre = float(_printed(text, "pre-trigger ").split()[1])
    gaps = [np.diff([h.time for h in r.hits]).min() for r in t.runs]
    # 95 % of the spacing the triggers give (a sample or a few off the pulses' true starts):
    # every record ends well before the next hit
    assert record - pre <= min(gaps) - 0.05
    assert main(["identify", str(frf), "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert abs(r["mass"] - t.truth.mass) / t.truth.mass < 5e-3
    assert np.linalg.norm(np.asarray(r["cog"]) - t.truth.cog) < 1e-3


def test_identify_time_uff_directly_and_hammer_option_means_impact(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    t = _hammer(2)
    src, out = tmp_path / "time.uff", tmp_path / "r.json"
    write_uff(t, src)
    assert main(["identify", str(src), "--out", str(out)]) == 0
    assert "settings from the data" in capsys.readouterr().out
    assert abs(json.loads(out.read_text())["mass"] - t.truth.mass) / t.truth.mass < 5e-3
    assert main(["frf", str(src), "--exp-tau", "1", "--record", "2",
                 "--out", str(tmp_path / "f.uff")]) == 0
    text = capsys.readouterr().out
    assert "excitation impact (a hammer option is given" in text
    assert "record " not in text.split("force window")[0].split("\n", 1)[1]  # both given


def test_force_ring_printed_and_given(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The force's ringing after a pulse is read from the data and printed with the force
    window; --force-ring keeps that many samples (and means a hammer test); a negative
    --force-ring is one line, exit status 2."""
    src = tmp_path / "time.uff"
    write_uff(_hammer(2), src)
    assert main(["frf", str(src), "--out", str(tmp_path / "a.uff")]) == 0
    text = capsys.readouterr().out
    fw = _printed(text, "force window: ")
    assert "and 0 samples (--force-ring; the force rings above its noise " in fw
    assert int(fw.split("its noise ")[1].split()[0]) >= 1
    assert main(["frf", str(src), "--force-ring", "5", "--out", str(tmp_path / "b.uff")]) == 0
    text = capsys.readouterr().out
    assert "excitation impact (a hammer option is given" in text
    assert "and 5 samples (--force-ring;" in text
    assert main(["frf", str(src), "--force-ring", "-1", "--out", str(tmp_path / "c.uff")]) == 2
    assert "--force-ring must be a whole number of samples, at least 0" in \
        capsys.readouterr().err


@cache
def _light_hammer() -> TimeTest:
    """Mounts damped 0.2x: each hit still rings when the next comes, 3 s later."""
    sc = build_scenario(ScenarioSpec(seed=2, n_forces=9, n_sensors=4, elastic_ratio=None))
    return hammer_test(sc, HammerSpec(seed=2, hits=4, spacing=3.0, damping=0.2))


def test_carryover_read_from_the_data_and_given(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The earlier hits' ringing at the next hit is printed; a light damping turns the
    correction on by default, a well-damped test leaves the records as they are;
    --carryover on/off overrides (the force still says it is a hammer test)."""
    src, light = tmp_path / "time.uff", tmp_path / "light.uff"
    write_uff(_hammer(2), src)
    write_uff(_light_hammer(), light)
    assert main(["frf", str(src), "--out", str(tmp_path / "a.uff")]) == 0
    line = _printed(capsys.readouterr().out, "earlier hits' ringing: ")
    assert "records used as they are (--carryover on to change)" in line
    assert main(["frf", str(light), "--out", str(tmp_path / "b.uff")]) == 0
    line = _printed(capsys.readouterr().out, "earlier hits' ringing: ")
    assert float(line.split()[3]) >= 3
    assert "less the free decay fitted before it (--carryover off to change)" in line
    assert main(["frf", str(light), "--carryover", "off", "--out", str(tmp_path / "c.uff")]) == 0
    text = capsys.readouterr().out
    assert "excitation impact (force impulsive in 9 of 9 runs" in text
    assert "earlier hits' ringing" not in text
    on, off = (read_frf_uff(tmp_path / f) for f in ("b.uff", "c.uff"))
    assert not np.allclose(on.H, off.H)


def test_shaker_data_is_processed_as_random(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    sc = build_scenario(ScenarioSpec(seed=2, n_forces=6, n_sensors=3, elastic_ratio=None))
    t = shaker_test(sc, ShakerSpec(seed=2, kind="burst", duration=20.0))
    src = tmp_path / "time.uff"
    write_uff(t, src)
    assert main(["frf", str(src), "--out", str(tmp_path / "f.uff")]) == 0
    text = capsys.readouterr().out
    assert "excitation random (force not impulsive in 6 of 6 runs" in text
    assert "averages" in text and "trigger level" not in text


@pytest.mark.parametrize(("kind", "line"), [
    ("chirp", "shaker force periodic in 6 of 6 runs (period 2 s"),
    ("burst", "shaker force in bursts in 6 of 6 runs (every"),
    ("random", "shaker force continuous in 6 of 6 runs: Welch segments of 2048 samples"),
])
def test_shaker_records_read_from_the_force(kind: str, line: str, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Periodic chirp: one record a period (rectangular window) once the responses repeat;
    burst random: one record from each burst's onset; continuous: Welch. Given Welch options
    are used as given."""
    sc = build_scenario(ScenarioSpec(seed=2, n_forces=6, n_sensors=3, elastic_ratio=None))
    t = shaker_test(sc, ShakerSpec(seed=2, kind=kind, duration=20.0, period=2.0))  # type: ignore[arg-type]
    src = tmp_path / "time.uff"
    write_uff(t, src)
    assert main(["frf", str(src), "--out", str(tmp_path / "f.uff")]) == 0
    text = capsys.readouterr().out
    assert line in text
    n_avg = int(text.split("excitation node ")[1].split(": ")[1].split()[0])
    # chirp: the first period skipped; burst: the first record (the sensors settling)
    assert n_avg == {"chirp": 9, "burst": 9, "random": 4}[kind]
    assert main(["frf", str(src), "--nperseg", "512", "--out", str(tmp_path / "g.uff")]) == 0
    text = capsys.readouterr().out
    assert "shaker force" not in text and "excitation node" in text


@cache
def _light_bursts() -> TimeTest:
    """Burst random on lightly damped mounts (0.2x): the responses still ring when each
    burst record ends and the next begins."""
    sc = build_scenario(ScenarioSpec(seed=2, n_forces=6, n_sensors=3, elastic_ratio=None))
    return shaker_test(sc, ShakerSpec(seed=2, kind="burst", duration=40.0, damping=0.2))


def test_burst_records_completed_by_default_when_they_ring(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The ringing at the burst records' ends is printed and turns the completion on
    (--carryover off leaves the records as cut, a shaker test still); the completed FRFs
    are closer to the exact accelerances (median relative error at 2-20 Hz, measured: 3.9 %
    against 5.7 %; the rest is the noise of 9 averages)."""
    t = _light_bursts()
    src = tmp_path / "time.uff"
    write_uff(t, src)
    assert main(["frf", str(src), "--out", str(tmp_path / "a.uff")]) == 0
    line = _printed(capsys.readouterr().out, "earlier bursts' ringing: ")
    assert float(line.split()[3]) >= 3
    assert "its own continued past its end and put back at its start" in line
    assert main(["frf", str(src), "--carryover", "off", "--out", str(tmp_path / "b.uff")]) == 0
    text = capsys.readouterr().out
    assert "excitation random (force not impulsive" in text
    assert "earlier bursts' ringing" not in text
    errs = []
    for name in ("a.uff", "b.uff"):
        f = read_frf_uff(tmp_path / name)
        fc = t.scenario.forces
        cols = [int(np.flatnonzero((fc.ids == n) & np.all(np.isclose(fc.reported_dirs, d),
                                                            axis=1))[0])
                for n, d in zip(f.exc_nodes, f.exc_dirs, strict=True)]
        band = (f.freq > 2) & (f.freq < 20)
        ref = t.exact_frf(f.freq[band])[:, cols]
        errs.append(float(np.median(np.abs(f.H[..., band] - ref) / np.abs(ref))))
    assert errs[0] < 0.8 * errs[1]


def test_record_tails_printed_and_given(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A hammer test without an exponential window gets its records' tails put back (a line
    says so); --tail on with an exponential window is one line, exit status 2; --carryover
    on a continuous random test says it is not used."""
    src = tmp_path / "time.uff"
    write_uff(_hammer(2), src)
    assert main(["frf", str(src), "--out", str(tmp_path / "a.uff")]) == 0
    line = _printed(capsys.readouterr().out, "record tails: ")
    assert "folded back onto it: no leakage (--tail off to change)" in line
    assert main(["frf", str(src), "--tail", "on", "--exp-tau", "0.5",
                 "--out", str(tmp_path / "b.uff")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "give --exp-tau 0 or --tail off" in err[0]
    sc = build_scenario(ScenarioSpec(seed=2, n_forces=6, n_sensors=3, elastic_ratio=None))
    shaker = tmp_path / "random.uff"
    write_uff(shaker_test(sc, ShakerSpec(seed=2, kind="random", duration=20.0)), shaker)
    assert main(["frf", str(shaker), "--carryover", "on", "--out", str(tmp_path / "c.uff")]) == 0
    assert "--carryover is for hammer hits and burst records, not welch records: not used" in \
        capsys.readouterr().out


def test_stated_uncertainties_with_an_exponential_window(tmp_path: Path) -> None:
    """A hammer test whose responses ring is windowed (here the window is given): the
    Monte Carlo of the stated test uncertainties runs on it too (it used to refuse), and
    the stated geometry adds to the fit's own uncertainty."""
    t = _hammer(2)
    src, out = tmp_path / "time.uff", tmp_path / "r.json"
    write_uff(t, src)
    assert main(["identify", str(src), "--exp-tau", "0.5", "--out", str(out)]) == 0
    alone = json.loads(out.read_text())
    assert main(["identify", str(src), "--exp-tau", "0.5", "--location-uncertainty", "2mm",
                 "--angle-uncertainty", "1deg", "--gain-uncertainty", "1%", "--draws", "200",
                 "--out", str(out)]) == 0
    stated = json.loads(out.read_text())
    assert stated["theta"] == alone["theta"]  # the estimates are the fit's
    assert any("Monte Carlo" in s for s in stated["uncertainty"]["sources"])
    assert np.all(np.asarray(stated["std"]["cog"]) > np.asarray(alone["std"]["cog"]))


@pytest.mark.parametrize("forces", [6, 9])
def test_a_points_only_double_hit_is_used_when_the_excitations_need_it(
        forces: int, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One hit a point, one of them double. Of six excitations none can be spared: the double
    hit is used (before, the file was refused: "excitation geometry has rank 5 < 6"); of nine
    the point is left out as before, its double hit rejected."""
    sc = build_scenario(ScenarioSpec(seed=11, n_forces=forces, n_sensors=4, elastic_ratio=None))
    t = hammer_test(sc, HammerSpec(seed=11, hits=1, spacing=3.0, n_double=1))
    src, frf, out = tmp_path / "time.uff", tmp_path / "frf.uff", tmp_path / "r.json"
    write_uff(t, src)
    assert main(["frf", str(src), "--out", str(frf)]) == (0 if forces == 6 else 2)
    text = capsys.readouterr()
    used = "1 hits accepted (double hits, the point's only hits: without them the excitations"
    assert (used in text.out + text.err) is (forces == 6)
    assert ("every hit rejected (hit 1: double hit" in text.err) is (forces == 9)
    assert read_frf_uff(frf).H.shape[1] == (6 if forces == 6 else 8)
    assert main(["identify", str(src), "--out", str(out)]) in (0, 2)
    r = json.loads(out.read_text())
    assert abs(r["mass"] - t.truth.mass) / t.truth.mass < 5e-3  # measured: 0.017 % (six)
    assert np.linalg.norm(np.asarray(r["cog"]) - t.truth.cog) < 1e-3  # 0.16 mm
