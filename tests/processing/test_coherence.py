"""The coherence gate."""

from __future__ import annotations

import numpy as np
import pytest

from processing.coherence import coherence_gate


def test_gate_counts_and_locates_the_dropped_values():
    freq = np.arange(10.0)
    coh = np.full((3, 2, 10), 0.95)
    coh[0, 1, 2:4] = 0.5
    coh[2, 0, 7] = np.nan  # no signal: dropped
    coh[1, 1, 9] = 0.8  # exactly at the threshold: kept
    gate = coherence_gate(coh, freq)
    assert gate.threshold == 0.8
    assert gate.n_dropped == 3
    assert gate.n_lines_dropped == 3
    assert gate.ranges == ((2.0, 3.0), (7.0, 7.0))
    assert gate.frfs_affected == ((0, 1), (2, 0))
    assert gate.dropped_per_frf[0, 1] == 2
    assert not gate.mask[0, 1, 2] and gate.mask[0, 0, 2]
    assert gate.line_ok.tolist() == [True, True, False, False, True, True, True, False, True, True]
    assert "3 of 60 FRF values in 2 of 6 FRFs" in gate.summary()
    assert "2-3 Hz" in gate.summary()


def test_all_good_and_bad_input():
    gate = coherence_gate(np.ones((1, 1, 4)), np.arange(4.0), threshold=0.9)
    assert gate.n_dropped == 0 and gate.ranges == ()
    assert gate.summary() == "coherence >= 0.9 on every FRF value"
    with pytest.raises(ValueError, match="shape"):
        coherence_gate(np.ones((2, 4)), np.arange(4.0))
    with pytest.raises(ValueError, match="threshold"):
        coherence_gate(np.ones((1, 1, 4)), np.arange(4.0), threshold=1.5)
