"""Coherence weighs the FRF values in the identification; low values are reported, not dropped."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hardware_mocks.benches import get_bench
from processing.identify import IdentifyOptions, identify


@pytest.fixture(scope="module")
def bench_frf():
    b = get_bench("engine-rigid")
    return b, b.frfset(noise=0.002)


def _options(b) -> IdentifyOptions:
    (mlo, mhi), (slo, shi) = b.article_bands
    return IdentifyOptions(mass_band=(mlo, mhi), stiffness_band=(slo, shi))


def _coherence_for(rel_noise: np.ndarray) -> np.ndarray:
    """The coherence an H1 estimate of that relative noise (std / |H|) has: var/|H|^2 = (1-g)/g."""
    return 1.0 / (1.0 + rel_noise**2)


def test_a_noisy_sensor_is_weighted_down(bench_frf) -> None:
    b, frf = bench_frf
    rng = np.random.default_rng(7)
    rel = np.full(frf.H.shape, 0.002)
    rel[2] = 0.6  # one accelerometer channel 60 % noisy on every FRF (coherence 0.74)
    z = (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2)
    noisy = replace(frf, H=frf.H + rel * np.abs(frf.H) * z)
    opt = _options(b)
    plain = identify(noisy, opt)  # no coherence: every value weighs the same
    weighted = identify(replace(noisy, coherence=_coherence_for(rel)), opt)
    m = b.model.mass
    err_plain = abs(plain.properties.mass / m - 1)
    err_weighted = abs(weighted.properties.mass / m - 1)
    # measured over seeds 0-3: 7.6-8.2 % unweighted (noise on X biases the fit), under
    # 0.004 % weighted; CoG 11-13 mm against under 0.01 mm
    assert err_weighted < 1e-3 and err_weighted < 0.01 * err_plain, (err_weighted, err_plain)
    cog = np.linalg.norm(weighted.properties.cog - b.model.cog)
    assert cog < 3e-4 and cog < np.linalg.norm(plain.properties.cog - b.model.cog) / 30
    c = weighted.checks()["coherence"]
    assert c["checked"] and not c["pass"]  # a twelfth of the values is below 0.8
    n_band = weighted.coherence_values // (frf.H.shape[0] * frf.H.shape[1])
    assert c["low_values"] == frf.H.shape[1] * n_band  # the noisy channel's, on every line
    assert len(weighted.mass_lines) == len(plain.mass_lines)  # nothing dropped for coherence


def test_low_values_reported_with_their_ranges(bench_frf) -> None:
    b, frf = bench_frf
    opt = _options(b)
    (mlo, mhi), _ = b.article_bands
    f = frf.freq
    coh = np.ones(frf.H.shape)
    a = np.flatnonzero((f >= mlo) & (f <= mhi))[10:13]
    coh[1, 2, a] = 0.6  # three values of one FRF in the mass band
    coh[0, 0, np.flatnonzero(f > mhi)[:4]] = 0.1  # outside the bands: not reported
    res = identify(replace(frf, coherence=coh), opt)
    c = res.checks()["coherence"]
    assert c["low_values"] == 3 and c["low_ranges_hz"] == [[float(f[a[0]]), float(f[a[-1]])]]
    assert c["pass"] and c["threshold"] == 0.8  # 3 of thousands of values
    lax = identify(replace(frf, coherence=coh), replace(opt, coherence_threshold=0.5))
    assert lax.checks()["coherence"]["low_values"] == 0


def test_equal_coherence_is_the_unweighted_fit(bench_frf) -> None:
    b, frf = bench_frf
    opt = _options(b)
    none = identify(frf, opt)
    c = none.checks()["coherence"]
    assert c["low_ranges_hz"] == [] and c["low_values"] == 0 and not c["checked"]
    same = identify(replace(frf, coherence=np.ones(frf.H.shape)), opt)
    np.testing.assert_allclose(same.theta, none.theta, rtol=1e-9)


def _problem(frf, coherence: np.ndarray, floor: float | None = None):
    from processing.problem import COHERENCE_NOISE_FLOOR, prepare

    return prepare(frf.freq, frf.H, frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
                   coherence=coherence, options=IdentifyOptions(), exponential_tau=None,
                   coherence_floor=COHERENCE_NOISE_FLOOR if floor is None else floor)


def test_stiffness_band_starts_at_the_first_line_over_its_noise() -> None:
    """Lines under their noise (coherence 0.3) at the bottom, then lines at 0.9 (signal over
    noise): the automatic stiffness band starts at the first line at 0.9."""
    from processing.identify import choose_bands

    frf = get_bench("engine-rigid").frfset()
    k0 = int(np.searchsorted(frf.freq, 0.0, side="right"))
    g = np.full(frf.H.shape, float(_coherence_for(np.array(0.03))))
    g[..., k0:k0 + 5] = 0.3
    g[..., k0 + 5:k0 + 10] = 0.9
    assert choose_bands(_problem(frf, g)).stiffness_band[0] == frf.freq[k0 + 5]


def test_a_column_weaker_everywhere_leaves_time_data_lines_clean() -> None:
    """FRFs estimated from time records (their error floor): one excitation column a
    hundred times noisier on every line (a far point, a lower force) leaves the clean lines
    as they are; another column dropping out on 20 lines (coherence 0.5: a shaker's force
    at a resonance) makes those lines unclean. FRFs given with their coherence: the weak
    column, under a tenth of the median column's weight, makes the lines unclean."""
    from processing.problem import TIME_DATA_ERROR_FLOOR

    frf = get_bench("engine-rigid").frfset()
    k0 = int(np.searchsorted(frf.freq, 0.0, side="right"))
    g = np.full(frf.H.shape, float(_coherence_for(np.array(0.01))))
    g[:, 5, k0 + 100:k0 + 120] = 0.5
    for floor in (None, TIME_DATA_ERROR_FLOOR):
        clean = _problem(frf, g, floor).clean_lines
        assert not np.any(clean[100:120]) and np.count_nonzero(clean) > frf.freq.size // 2
    weak_g = g.copy()
    weak_g[:, 3] = float(_coherence_for(np.array(0.1)))
    # the weak column's weight still dips at its own resonances: a few % of the lines change
    # (54 of 1024 at the time-data floor; judged against the median column's weight it left
    # no clean line below 42 Hz on a burst-random time-data test)
    weak = _problem(frf, weak_g, TIME_DATA_ERROR_FLOOR).clean_lines
    assert np.count_nonzero(weak != clean) <= 0.06 * frf.freq.size
    assert not np.any(weak[100:120]) and np.count_nonzero(weak) > frf.freq.size // 2
    given = _problem(frf, weak_g).clean_lines
    assert np.count_nonzero(given) < np.count_nonzero(_problem(frf, g).clean_lines) // 2


def test_scattered_coherence_gives_one_projection_per_column() -> None:
    """FRFs off the rigid-body model by 2 % (body flexibility, sensor positions) with a
    coherence that scatters from line to line as over five hits (1 - g from 1e-4 to 1e-2):
    for FRFs estimated from time records, each column's accelerances at O are one fixed map
    of its responses on every line (the responses weighed by their median variance), so the
    model error is not turned into a line-by-line bias. FRFs given with their coherence are
    weighed line by line: no single map."""
    frf = get_bench("engine-rigid").frfset()
    rng = np.random.default_rng(3)
    z = rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)
    off = replace(frf, H=frf.H * (1 + 0.02 * z))
    k0 = int(np.searchsorted(off.freq, 0.0, side="right"))
    g = 1 - 10 ** rng.uniform(-4, -2, off.H.shape)
    H = off.H[..., k0:]

    def misfit(floor: float | None) -> np.ndarray:
        """Per column: how far X is from one linear map of the column's responses."""
        p = _problem(off, g, floor)
        out = []
        for e in range(H.shape[1]):
            Pe, *_ = np.linalg.lstsq(H[:, e].T, p.X[:, e].T, rcond=None)
            out.append(np.linalg.norm(H[:, e].T @ Pe - p.X[:, e].T) / np.linalg.norm(p.X[:, e]))
        return np.array(out)

    from processing.problem import TIME_DATA_ERROR_FLOOR

    assert np.all(misfit(TIME_DATA_ERROR_FLOOR) < 1e-9)
    assert np.all(misfit(None) > 1e-4)
