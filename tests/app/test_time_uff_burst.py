"""Burst-random shaker records (app/pipeline/time_uff.py) against the exact FRFs of the
reference model (``hardware_mocks/reference/timedata.py``, independent of ``processing/``).

The generator's responses carry an IEPE sensor's settling (a decaying offset, 10 % of the
responses at most, 0.2-0.6 s) from the start of each recording: the first burst holds it,
and with a rectangular window it swamped the lowest lines (error 1.2-12x the FRF at 1-2 Hz,
measured on seeds 1-3 below). That burst starts with the recording, with no room before
it for its onset's margin: its record is not cut (a record that starts later with the
settling is left out, ``settled_records``). Measured on seeds 1 and 2: the lowest line
(0.25 Hz) within 0.68x and 0.54x, the median of 0.25-2 Hz 0.09x and 0.07x; with the
records completed (``--carryover on``; the ringing at their ends is 2.9x the noise here,
under the default's gate) 0.38x and 0.50x."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.pipeline import Settings, load
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from hardware_mocks.reference.timedata import ShakerSpec, shaker_test, write_uff


@pytest.mark.parametrize("seed", [1, 2])
def test_burst_records_leave_out_the_sensors_settling(seed: int, tmp_path: Path) -> None:
    sc = build_scenario(ScenarioSpec(seed=seed, n_forces=6, n_sensors=4, elastic_ratio=None))
    t = shaker_test(sc, ShakerSpec(seed=seed, kind="burst", duration=20.0))
    src = tmp_path / "time.uff"
    write_uff(t, src)
    m = load(src, Settings(coherence=0.0))
    frf = m.frf
    text = "\n".join(r.message for r in m.provenance.reports)
    assert "shaker force in bursts" in text
    assert "4 averages" in text  # the bursts at 4, 8, 12 and 16 s
    fc = sc.forces
    cols = [int(np.flatnonzero((fc.ids == n) & np.all(np.isclose(fc.reported_dirs, d),
                                                       axis=1))[0])
            for n, d in zip(frf.exc_nodes, frf.exc_dirs, strict=True)]
    exact = t.exact_frf(frf.freq)[:, cols]
    low = slice(1, 9)  # 0.5-4 Hz: accelerances falling as f^2, the settling's band
    err = (np.linalg.norm(frf.H[..., low] - exact[..., low], axis=(0, 1))
           / np.linalg.norm(exact[..., low], axis=(0, 1)))
    assert np.max(err) < 0.7 and np.median(err) < 0.2, err  # were 2-12 and 0.5-1.2
    done = load(src, Settings(coherence=0.0, carryover=True)).frf
    err = (np.linalg.norm(done.H[..., low] - exact[..., low], axis=(0, 1))
           / np.linalg.norm(exact[..., low], axis=(0, 1)))
    assert np.max(err) < 0.55 and np.median(err) < 0.15, err
