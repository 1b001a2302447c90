"""Hammer FRFs from time records with default options against the exact accelerances of the
independent reference model (``hardware_mocks/reference/timedata.py``): the record length and
pre-trigger read from the data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.testing import assert_array_less

from app.pipeline import Settings, load
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import HammerSpec, hammer_test, write_uff
from processing.impact import TAIL_FACTOR, impact_defaults


def _column_errors(tmp_path: Path, seed: int, damping: float,
                   ) -> tuple[np.ndarray, np.ndarray, list[str], float]:
    """Each column's error (norm over the responses of H - H_exact over H_exact's), by line;
    the frequency lines (Hz), the default lines printed and the file's median decay (s)."""
    sc = build_scenario(ScenarioSpec(seed=seed, n_forces=6, n_sensors=3, elastic_ratio=None))
    t = hammer_test(sc, HammerSpec(seed=seed, hits=4, spacing=3.5, damping=damping))
    src = tmp_path / "time.uff"
    write_uff(t, src)
    m = load(src, Settings())
    frf, reports = m.frf, m.provenance.reports
    exact = t.exact_frf(frf.freq)
    err = np.linalg.norm(frf.H - exact, axis=0) / np.linalg.norm(exact, axis=0)
    decay = float(np.median([impact_defaults(r.forces[0], r.responses, t.fs).decay
                             for r in t.runs]))
    return err, frf.freq, [r.message for r in reports], decay


def test_record_follows_the_tail_under_the_noise(tmp_path: Path) -> None:
    """Heavily damped mounts (x1.5), hits 2.8-4.2 s apart: the responses fall to three noise
    standard deviations in 1.3 s, but the mount modes' tails under the broadband noise still
    stand out on their own lines. The default record holds twice that decay (2.67 s; the
    decay plus the pre-trigger gave 2 s): measured, the lines 0.5-3 Hz 7.5 % off (28 %
    with 2 s), 3-10 Hz 0.29 % (0.51 %), every column's median within 0.36 % (1.2 %)."""
    err, f, lines, decay = _column_errors(tmp_path, 5, 1.5)
    record = float(next(ln for ln in lines if ln.startswith("record ")).split()[1])
    pre = float(next(ln for ln in lines if ln.startswith("pre-trigger ")).split()[1])
    assert record >= min(TAIL_FACTOR * decay + pre, 0.95 * 2.8) - 0.01
    low, mid = (f >= 0.5) & (f < 3.0), (f >= 3.0) & (f < 10.0)
    assert_array_less(np.median(err[:, low]), 0.15)
    assert_array_less(np.median(err[:, mid]), 0.004)
    assert_array_less(np.median(err[:, mid], axis=1), 0.006)
    assert_array_less(np.median(err[:, f >= 10.0]), 0.005)


def test_lighter_damping_record_and_pretrigger(tmp_path: Path) -> None:
    """Mount damping x0.7: the default record (2.72 s) and pre-trigger (twice the force's
    ringing before a pulse) give the lines 3-10 Hz within 0.36 % (0.67 % with the decay
    plus a pre-trigger of 0.01 s, 2.4 s)."""
    err, f, lines, _ = _column_errors(tmp_path, 4, 0.7)
    assert any(ln.startswith("pre-trigger ") and "twice that" in ln for ln in lines)
    mid = (f >= 3.0) & (f < 10.0)
    assert_array_less(np.median(err[:, mid]), 0.0045)
    assert_array_less(np.median(err[:, f >= 10.0]), 0.004)
