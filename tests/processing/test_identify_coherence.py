"""The identification says how many coherence-gated lines it dropped and where."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hardware_mocks.benches import get_bench
from processing.identify import IdentifyOptions, identify


@pytest.fixture(scope="module")
def bench_frf():
    b = get_bench("engine-rigid")
    return b, b.frfset(noise=0.005)


def test_dropped_ranges_are_the_gated_lines_inside_the_bands(bench_frf) -> None:
    b, frf = bench_frf
    (mlo, mhi), (slo, shi) = b.article_bands
    f = frf.freq
    coh = np.ones(frf.H.shape)
    in_mass = np.flatnonzero((f >= mlo) & (f <= mhi))
    in_stiff = np.flatnonzero((f >= slo) & (f <= shi))
    a, s = in_mass[10:13], in_stiff[3:5]
    coh[1, 2, a] = 0.6  # three lines of one FRF in the mass band
    coh[4, 7, s] = 0.7  # two lines of another in the stiffness band
    coh[4, 8, s[1]] = 0.7  # the same line in a second excitation column
    outside = np.flatnonzero(f > max(mhi, shi))[:4]
    coh[0, 0, outside] = 0.1  # outside both bands: not reported
    opt = IdentifyOptions(mass_band=(mlo, mhi), stiffness_band=(slo, shi))
    res = identify(replace(frf, coherence=coh), opt)
    c = res.checks()["coherence"]
    expected = sorted([[float(f[a[0]]), float(f[a[-1]])], [float(f[s[0]]), float(f[s[-1]])]])
    assert sorted(c["dropped_ranges_hz"]) == expected
    assert c["dropped_lines"] == 3 + 2 + 1  # (excitation column, line) values
    assert not c["pass"] and c["threshold"] == 0.8
    # the threshold of the options is the one applied and reported
    lax = identify(replace(frf, coherence=coh), replace(opt, coherence_threshold=0.65))
    c = lax.checks()["coherence"]
    assert c["threshold"] == 0.65 and c["dropped_lines"] == 3
    assert c["dropped_ranges_hz"] == [[float(f[a[0]]), float(f[a[-1]])]]

def test_no_coherence_means_nothing_dropped(bench_frf) -> None:
    b, frf = bench_frf
    (mlo, mhi), (slo, shi) = b.article_bands
    res = identify(frf, IdentifyOptions(mass_band=(mlo, mhi), stiffness_band=(slo, shi)))
    c = res.checks()["coherence"]
    assert c["dropped_ranges_hz"] == [] and c["dropped_lines"] == 0 and not c["checked"]
