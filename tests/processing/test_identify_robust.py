"""What the improved method does where the data are poor: it answers with a band and a
reason instead of refusing, chooses the upper residual from the data, and response-point
refinement settles instead of drifting. Errors against the bench model's truth, judged on
medians over draws (single draws scatter)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from hardware_mocks.benches import get_bench
from processing.data import FRFSet, InputError
from processing.identify import IdentifyOptions, identify
from tests.processing.test_identify import errors, within


def _median(errs: list[dict[str, float]]) -> dict[str, float]:
    return {k: float(np.median([e[k] for e in errs])) for k in errs[0]}


def test_rigidity_limit_below_the_rigid_modes_is_reported_not_refused() -> None:
    """5 % noise and +-5 mm put the rigidity check's limit (about 25 Hz) below the engine's
    rigid-body modes (up to 31.5 Hz); the identification used to refuse. It now sets the
    limit aside, says so, and answers within the tolerances below (the elastic mode at
    118.5 Hz is not always seen at this noise: then the band may reach 116 Hz, the limit
    of the check at 3x its error floor, and the mass errs by about 1.6 %)."""
    bench = get_bench("engine")
    errs = []
    for s in range(4):
        r = identify(bench.frfset(0.05, 0.005, seed=100 + s))
        assert "set aside" in r.band_reason and "rigidity check's limit" in r.band_reason
        assert any("set aside" in w for w in r.warnings)
        assert r.mass_band[0] > 31.0 and r.mass_band[1] < 118.5
        errs.append(errors(bench, r))
    within(_median(errs), mass=2.0, cog=3.0, inertia=3.0, stiffness=5.0)


def test_upper_residual_chosen_by_the_data() -> None:
    """Block with its elastic mode at 450 Hz, 1 % noise: the per-mode leakage terms are off
    (noise above 0.2 %), the upper residual is chosen by the data and removes most of the
    mode's leakage (mass error about 1.0 % without it). On rigid data it is not chosen."""
    bench = get_bench("block-flexible")
    errs = []
    for s in range(4):
        r = identify(bench.frfset(0.01, 0.0, seed=100 + s))
        errs.append(errors(bench, r))
    assert sum(e["mass"] < 0.5 for e in errs) >= 3
    within(_median(errs), mass=0.3, cog=0.4, inertia=1.5, stiffness=3.0)
    rigid = get_bench("engine-rigid")
    for s in range(3):
        r = identify(rigid.frfset(0.02, 0.003, seed=100 + s))
        assert r.model_note.startswith("upper residual (w^2 term) not modelled")


def test_rigid_exact_with_the_upper_residual_candidate() -> None:
    """Noise-free rigid benches stay exact (the upper residual is not taken)."""
    for name in ("block-rigid", "engine-rigid"):
        bench = get_bench(name)
        within(errors(bench, identify(bench.frfset())), mass=1e-5, cog=1e-5, inertia=1e-5,
               stiffness=1e-3)


def test_point_refinement_settles() -> None:
    """More rounds never make it worse: on a draw of the noisy row, 30 rounds end (converged
    or stopped, with the reason) with errors no worse than 5 rounds, corrections that stay
    within the +-3 mm errors' reach, and response points closer to the truth than the
    nominal ones (RMS error 0.72x). With the ridge on each step and every round kept, this
    draw's points drifted away (1.8x) and its inertia error went from 0.82 % to 1.9 %. The
    claims on the medians over draws are checked by ``benchmarks/identify_draws.py N refine``."""
    bench = get_bench("engine-rigid")
    true = bench.frfset().resp_xyz
    f = bench.frfset(0.02, 0.003, seed=9106)  # a seed of the tests' own
    r5 = identify(f, IdentifyOptions(refine_points=5))
    r30 = identify(f, IdentifyOptions(refine_points=30))
    assert r30.point_corrections is not None
    assert any(w.startswith("point refinement: ") for w in r30.warnings)
    assert np.abs(r30.point_corrections).max() < 0.006
    before = np.sqrt(np.mean((f.resp_xyz - true) ** 2))
    after = np.sqrt(np.mean((f.resp_xyz - r30.point_corrections - true) ** 2))
    assert after / before < 0.8
    e5, e30 = errors(bench, r5), errors(bench, r30)
    for k in e5:
        assert e30[k] <= 1.2 * e5[k] + 1e-3, (k, e5[k], e30[k])
    within(e30, mass=0.3, cog=1.5, inertia=1.2, stiffness=1.5)


def test_line_operators_of_a_zero_line() -> None:
    """Time data through an anti-alias filter leave the top lines at exactly 0: X X^H is
    singular there. The other lines' operators are those computed without it, the zero
    line's are finite (they raised "Singular matrix" before), and the rigid-mode estimate
    answers on rank-deficient data."""
    from processing.selection import quick_rigid_modes
    from processing.stiffness import line_operators

    rng = np.random.default_rng(0)
    X = rng.standard_normal((6, 12, 40)) + 1j * rng.standard_normal((6, 12, 40))
    X[..., 5] = 0.0
    T = rng.standard_normal((6, 12))
    w = np.linspace(10.0, 100.0, 40)
    B = line_operators(X, T, w).B
    assert np.isfinite(B).all()
    keep = np.arange(40) != 5
    np.testing.assert_allclose(B[keep], line_operators(X[..., keep], T, w[keep]).B, rtol=1e-10)
    X[3:] = 0.0  # rank 3 on every line
    assert quick_rigid_modes(X, T, w).shape == (6,)


def test_rigid_band_starts_past_noisy_lowest_lines() -> None:
    """Time data leave the lowest lines (accelerances falling as f^2 under the rigid-body
    modes) under the noise: the rigidity check fails from the lowest line. When most lines
    are rigid (error floor within twice the threshold) the band starts at the first rigid
    line and ends where the clean data's does; when the noise is everywhere it stays none."""
    import dataclasses

    from processing.rigidity import rigidity_check
    from processing.stages import rigid_band_tops

    frf = get_bench("engine").frfset()
    clean_top = rigid_band_tops(frf)[0]
    assert clean_top is not None and 95.0 < clean_top < 118.5
    rng = np.random.default_rng(1)
    H = frf.H.copy()
    H[..., :6] *= 1 + 0.5 * (rng.standard_normal(H[..., :6].shape)
                             + 1j * rng.standard_normal(H[..., :6].shape))
    noisy = dataclasses.replace(frf, H=H)
    assert rigidity_check(noisy, fmin=float(frf.freq[frf.freq > 0][0])).band is None
    top, _, notes = rigid_band_tops(noisy)
    assert top == clean_top and not notes
    H = frf.H * (1 + 0.5 * rng.standard_normal(frf.H.shape))
    assert rigid_band_tops(dataclasses.replace(frf, H=H))[0] is None


def test_rigid_band_past_noisy_lowest_lines_on_a_flexible_body() -> None:
    """A body that flexes over most of the data (the check's error floor over all lines is
    above twice its threshold): the noisy lowest lines are still passed over, as the lines
    from the lowest one to the band's top are mostly rigid."""
    import dataclasses

    from processing.rigidity import rigidity_check
    from processing.stages import rigid_band_tops

    frf = get_bench("block-flexible").frfset()
    clean_top, clean_raised, _ = rigid_band_tops(frf)
    fmin = float(frf.freq[frf.freq > 0][0])
    assert clean_top is not None and rigidity_check(frf, fmin=fmin).error_floor(fmin) > 0.2
    rng = np.random.default_rng(1)
    H = frf.H.copy()
    H[..., :4] *= 1 + 0.5 * (rng.standard_normal(H[..., :4].shape)
                             + 1j * rng.standard_normal(H[..., :4].shape))
    noisy = dataclasses.replace(frf, H=H)
    assert rigidity_check(noisy, fmin=fmin).band is None
    top, raised, notes = rigid_band_tops(noisy)
    assert top == clean_top and not notes
    # the raised threshold's band starts past them too (its error floor read from there)
    assert clean_raised is not None and raised is not None
    assert abs(raised - clean_raised) <= 0.05 * clean_raised


def test_rigid_band_past_noisy_lowest_lines_on_a_short_rigid_band() -> None:
    """A body whose rigid band is a small part of the spectrum (elastic above 30 Hz here: the
    rigidity check's error floor far above its threshold) with noisy lowest lines: the band
    still starts at the first rigid line and ends where the clean data's does (it used to be
    left out, and a burst-random test's mass line fell among the elastic lines: 85 % mass
    error); a quiet moment after more noisy lines than it holds is no rigid band."""
    import dataclasses

    from processing.stages import rigid_band_tops

    frf = get_bench("engine").frfset()
    rng = np.random.default_rng(2)
    elastic = frf.freq > 30.0

    def noisy(H: np.ndarray, lines: np.ndarray, level: float) -> np.ndarray:
        H = H.copy()
        shape = H[..., lines].shape
        H[..., lines] *= 1 + level * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))
        return H

    H = noisy(frf.H, elastic, 1.0)
    clean_top = rigid_band_tops(dataclasses.replace(frf, H=H))[0]
    assert clean_top is not None and 29.0 < clean_top <= 30.0
    low = np.zeros(frf.freq.size, bool)
    low[:6] = True
    top, _, notes = rigid_band_tops(dataclasses.replace(frf, H=noisy(H, low, 0.5)))
    assert top == clean_top and not notes
    low[:150] = True  # noisy up to 18.8 Hz: more lines than the quiet ones after them
    assert rigid_band_tops(dataclasses.replace(frf, H=noisy(H, low, 0.5)))[0] is None


def test_stiffness_band_when_the_first_line_is_above_the_rigid_modes() -> None:
    """Lines given from above 1.5x the highest rigid-body mode (the lower ones left out):
    the stiffness band runs up to the mass line instead of being empty."""
    from processing.geometry import excitation_matrix, response_matrix
    from processing.selection import choose_bands

    frf = get_bench("engine-rigid").frfset()
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    X = np.einsum("ir,ref->ief", np.linalg.pinv(E), frf.H)
    keep = frf.freq >= 50.0  # the rigid-body modes reach 31.5 Hz
    c = choose_bands(frf.freq[keep], X[..., keep], T, ())
    lo, hi = c.stiffness_band
    assert lo == frf.freq[keep][0] and hi > lo and hi >= c.mass_band[0]


@pytest.mark.parametrize("f_elastic", [70.0, 90.0, 110.0])
def test_rigid_modes_read_again_when_far_above_the_rigidity_limit(f_elastic: float) -> None:
    """Two clean lines under the rigidity limit (the others noisy, left out): the rigid-body
    modes are read over all lines, where an elastic mode the residual does not show bends
    the estimate far above the limit (67-217 Hz for 29 Hz); they are read again over the
    lines up to twice the limit."""
    from processing.geometry import excitation_matrix, response_matrix
    from processing.selection import ElasticPeak, choose_bands, mode_shape_basis

    frf = get_bench("engine-rigid").frfset()
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    f = frf.freq
    X = np.einsum("ir,ref->ief", np.linalg.pinv(E), frf.H)
    keep = (f > 0) & ((f <= 0.25) | (f >= 21))
    exact = choose_bands(f[keep], X[..., keep], T, ()).rigid_mode_max
    rng = np.random.default_rng(0)
    A = rng.standard_normal(X.shape[:2]) * np.median(np.abs(X[..., f > 60]))
    X = X + A[..., None] * mode_shape_basis(2 * np.pi * f, ElasticPeak(f_elastic, 0.02))
    c = choose_bands(f[keep], X[..., keep], T, (), rigid_band_top=20.2)
    assert c.rigid_mode_max == pytest.approx(exact, rel=0.02)
    assert 1.3 * exact <= c.mass_band[0] <= 2.01 * exact


@pytest.mark.parametrize(("f_elastic", "size"), [(110.0, 1.0), (110.0, 3.0), (130.0, 3.0)])
def test_rigid_modes_read_bottom_up_without_a_rigidity_limit(f_elastic: float,
                                                              size: float) -> None:
    """No rigidity limit (the check failed from the lowest line, as time data's noisy first
    lines make it): the rigid-body modes were read over every line to the end of the data,
    where an elastic mode just above it bends the apparent mass and the lines' signal
    weights make the top lines decide K: 94-295 Hz for 29 Hz, and a mass line among the
    lines the mode bends. Read bottom-up (lines up to tops doubling from the eighth, until
    the top is twice the modes read), they are the bench's."""
    from processing.geometry import excitation_matrix, response_matrix
    from processing.selection import ElasticPeak, choose_bands, mode_shape_basis

    frf = get_bench("engine-rigid").frfset()
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    f = frf.freq
    X = np.einsum("ir,ref->ief", np.linalg.pinv(E), frf.H)
    keep = f > 0
    exact = choose_bands(f[keep], X[..., keep], T, ()).rigid_mode_max
    rng = np.random.default_rng(5)
    A = rng.standard_normal(X.shape[:2]) * np.median(np.abs(X[..., f > 60])) * size
    X = X + A[..., None] * mode_shape_basis(2 * np.pi * f, ElasticPeak(f_elastic, 0.02))
    snr = np.linalg.norm(X.reshape(-1, f.size), axis=0)[keep]
    c = choose_bands(f[keep], X[..., keep], T, (), line_weights=snr / snr.max())
    assert c.rigid_mode_max == pytest.approx(exact, rel=0.03)
    assert 1.3 * exact <= c.mass_band[0] <= 2.1 * exact


@pytest.mark.parametrize(("n_noisy", "level"), [(16, 1.0), (32, 1.0), (32, 3.0), (64, 1.0)])
def test_noisy_lowest_lines_do_not_pull_the_modes_down(n_noisy: int, level: float) -> None:
    """The lowest lines under noise (``level`` times their signal, weighed down by their
    signal-to-noise ratio): a bottom-up reading over them alone finds modes of 0.5-3 Hz,
    self-consistent at one top; it is taken only where it agrees with the readings at half
    and a quarter of the lines' top, so the modes stay the bench's (29 Hz)."""
    from processing.geometry import excitation_matrix, response_matrix
    from processing.selection import choose_bands

    frf = get_bench("engine-rigid").frfset()
    E = response_matrix(frf.resp_xyz, frf.resp_dirs)
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    f = frf.freq
    X = np.einsum("ir,ref->ief", np.linalg.pinv(E), frf.H)
    exact = choose_bands(f, X, T, ()).rigid_mode_max
    rng = np.random.default_rng(4711)
    noisy = X[..., :n_noisy]
    scale = level * np.abs(noisy).mean()
    X[..., :n_noisy] += scale * (rng.standard_normal(noisy.shape)
                                 + 1j * rng.standard_normal(noisy.shape))
    signal = np.abs(frf.H).mean(axis=(0, 1))
    snr = signal / np.where(np.arange(f.size) < n_noisy, scale, 1e-3 * signal.mean())
    c = choose_bands(f, X, T, (), line_weights=snr)
    assert c.rigid_mode_max == pytest.approx(exact, rel=0.02)


def test_an_impossible_mass_is_refused_not_reported() -> None:
    """A fitted mass that is not finite, not positive or far from what the mass line reads
    by itself is refused with one line; the bench's own fit passes."""
    from dataclasses import replace

    from processing.problem import prepare
    from processing.stages import (
        choose_bands,
        mass_line_reading,
        refuse_implausible_mass,
        settle_mass_band,
        solve,
        weigh_lines,
    )

    b = get_bench("engine-rigid")
    frf = b.frfset(noise=0.002)
    problem = prepare(frf.freq, frf.H, frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
                      coherence=None, options=IdentifyOptions(), exponential_tau=None)
    bands = choose_bands(problem)
    bands, weights = settle_mass_band(problem, bands, weigh_lines(problem, bands))
    fitted = solve(problem, bands, weights)
    reading = mass_line_reading(problem, weights)
    assert abs(reading / b.model.mass - 1) < 0.1  # M - K/w^2 on the mass line
    refuse_implausible_mass(problem, bands, weights, fitted)  # a good fit passes
    for mass in (1.25e24, np.nan, -50.0, reading / 4):
        theta = fitted.theta.copy()
        theta[0] = mass
        with pytest.raises(InputError, match=r"^no usable mass: the fit gave .* mass line"):
            refuse_implausible_mass(problem, bands, weights, replace(fitted, theta=theta))


def _reference_frf(seed: int):
    """A scenario of the independent reference suite (seed 2026) as an FRFSet, and its truth."""
    from hardware_mocks.reference.scenarios import build_scenario, suite
    from processing.data import FRFSet, Geometry

    spec = next(s for s in suite(200, 2026) if s.seed == seed)
    sc = build_scenario(spec)
    ids, xyz = sc.geometry()
    frf = FRFSet(freq=sc.freq, H=sc.H, resp_nodes=sc.sensors.ids,
                 resp_dirs=sc.sensors.reported_dirs, exc_nodes=sc.forces.ids,
                 exc_dirs=sc.forces.reported_dirs, geometry=Geometry(ids, xyz),
                 coherence=sc.coherence)
    return frf, sc.truth


def test_reference_scenario_2026189_gives_no_garbage_mass() -> None:
    """Block on soft mounts, 3 triaxial sensors, 2.7 % noise: a residual peak at 8.6 Hz read
    as an elastic mode (its fit at the damping's lower bound: narrower than the lines) put
    the mass line under the rigid-body modes and the fit reported 1.3e24 kg. The peak is no
    mode; and whatever the bands, an answer within a factor 3 of the true mass or a one-line
    refusal."""
    from processing.problem import prepare

    frf, truth = _reference_frf(2026189)
    problem = prepare(frf.freq, frf.H, frf.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
                      coherence=frf.coherence, options=IdentifyOptions(), exponential_tau=None)
    assert all(p.frequency > 20 for p in problem.peaks), problem.peaks
    try:
        r = identify(frf, IdentifyOptions(uncertainty=False))
    except InputError as err:
        assert str(err).startswith("no usable mass") and "\n" not in str(err)
    else:
        assert 1 / 3 < r.properties.mass / truth.mass < 3, r.properties.mass


@pytest.mark.parametrize(("seed", "tol"), [(2026122, 1.0), (2026121, 15.0)])
def test_frfs_given_with_their_coherence(seed: int, tol: float) -> None:
    """Reference scenarios whose FRFs come with a coherence that stands for their noise
    (0.2 % and 1.1 % noise, elastic mode 2-3x the rigid ones): weighed by it with the noise
    floor of FRFs given (1e-3 of their RMS, not the time-data error floor of 3e-2) and clean
    lines judged also against the median column, mass errors 0.25 % and 7.9 % (were 6.1 % and
    51 % with the time-data floor and the per-column clean rule)."""
    frf, truth = _reference_frf(seed)
    r = identify(frf, IdentifyOptions(uncertainty=False))
    assert abs(r.properties.mass / truth.mass - 1) * 100 < tol


def _one_noisy_hit_a_point(seed: int, noise: float) -> tuple[Any, FRFSet]:
    """The engine-rigid bench's nine well-conditioned points (those of the noisy end-to-end
    test), lines of a 1.5 s record to 400 Hz, with sensor noise the same on every line (one
    hit a point): ``noise`` times each FRF's largest value (1 %: some 10 % of its mass-line
    level)."""
    import dataclasses

    bench = get_bench("engine-rigid")
    points = [0, 1, 3, 4, 6, 8, 9, 12, 15]
    freq = np.arange(1, 601) / 1.5
    H = bench.exact_frf(freq)[:, points]
    rng = np.random.default_rng(seed)
    H = H + noise * np.abs(H).max(axis=-1, keepdims=True) * (
        rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    frf = bench.frfset()
    return bench, dataclasses.replace(frf, freq=freq, H=H, exc_nodes=frf.exc_nodes[points],
                                      exc_dirs=frf.exc_dirs[points])


@pytest.mark.parametrize(("seed", "noise"), [(8421, 0.01), (8422, 0.01), (8432, 0.01),
                                             (8400, 0.015), (8412, 0.015)])
def test_a_mass_line_among_the_modes_is_moved_above_them(seed: int, noise: float) -> None:
    """One noisy hit a point: the rigid-body modes read off the lines fall far under the
    modes (10.7-28.9 Hz) and the mass line starts among them. Three ways the fit on it
    used to stay there: its M not even positive definite, so that its modes could not be
    read (-63 % and -50 % for seeds 8421 and 8432 at 1 %); a second mass line still among
    the modes, the fit on it reading them low too; a mass that is no answer (seed 8422 at
    1 %, 8400 and 8412 at 1.5 %: refused). At 1 % noise 3 of 40 seeds (8400-8439) failed,
    at 1.5 % 35 of 40, at 2 % 23 of 40; now none. The bands are chosen again above
    the fit's top mode (the general eigenproblem's largest positive root when M is not
    positive definite), or above a mass line whose mass is no answer (with room above
    it), while that floor rises."""
    bench, frf = _one_noisy_hit_a_point(seed, noise)
    r = identify(frf)
    assert "raised by the fit on a lower mass line" in r.band_reason, r.band_reason
    assert r.mass_band[0] > 28.9  # above every rigid-body mode (by the fit's reading of them)
    assert r.properties.mass == pytest.approx(bench.model.theta[0], rel=0.03)


def test_an_automatic_stiffness_band_holds_lines() -> None:
    """Rigid-body modes read far under them (at 0.2 Hz on lines 0.2 Hz apart, where a
    hammer test's lowest lines are noise) gave a stiffness band of one line, and the
    identification refused ("holds fewer than 2 lines: widen it") before any fit could
    move the bands above its own modes. The band now holds at least 4 lines."""
    from processing.selection import MIN_STIFFNESS_LINES, _stiffness_band

    freq = 0.2 * np.arange(1, 500)
    lo, hi = _stiffness_band(freq, 0.2, 0.4, None)
    assert np.count_nonzero((freq >= lo) & (freq <= hi)) == MIN_STIFFNESS_LINES
    lo, hi = _stiffness_band(freq, 10.0, 20.0, None)  # a band of its own: as before
    assert (lo, hi) == (0.2, 15.0)
