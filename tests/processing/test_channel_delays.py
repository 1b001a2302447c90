"""Each response channel's delay against the force (channel skew), read from the FRFs' phase
and taken out before the fit. Truth from the independent reference model
(``hardware_mocks/reference``), the delays put on its exact FRFs here; seeds of these tests
only (the time-data budget suites are 6060 and 6161)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from hardware_mocks.reference.metrics import errors
from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
from processing.data import FRFSet, Geometry, InputError
from processing.delays import ChannelDelays, estimate_delays, realness_delays
from processing.identify import identify
from processing.problem import IdentifyOptions
from processing.units import TimeUnits, UnitSpectra

#: a sample of the front end the delays stand for, s (1024 Hz)
SAMPLE = 1 / 1024


def _frfs(sc, tau: np.ndarray | None = None) -> FRFSet:
    """The scenario's FRFs, each response ``tau`` late (written here: ``exp(-j w tau)``)."""
    ids, xyz = sc.geometry()
    H = sc.H if tau is None else sc.H * np.exp(-2j * np.pi * sc.freq[None, :] * tau[:, None])[
        :, None, :]
    return FRFSet(sc.freq, H, sc.sensors.ids, sc.sensors.reported_dirs, sc.forces.ids,
                  sc.forces.reported_dirs, Geometry(ids, xyz), sc.coherence)


def _errors(sc, res) -> dict[str, float]:
    p = res.properties
    return errors(sc.truth, p.mass, p.cog, p.inertia_origin, p.inertia_cog, res.K)


def test_estimate_recovers_delays_through_noise_and_bad_lines() -> None:
    """Delays within a sample on FRFs built here (real model values, 1 % noise, a tenth of
    the lines turned by an unmodelled resonance): each is read within 2 % of a sample, and
    its std covers the error."""
    rng = np.random.default_rng(8201)
    f = np.linspace(60.0, 200.0, 141)
    model = rng.normal(size=(12, 9))[..., None] * np.ones(f.size)
    tau = rng.uniform(-1, 1, 12) * SAMPLE
    noise = 0.01 * np.abs(model) * (rng.normal(size=model.shape)
                                   + 1j * rng.normal(size=model.shape))
    H = (model + noise) * np.exp(-2j * np.pi * f * tau[:, None, None])
    bad = rng.uniform(size=f.size) < 0.1
    H[..., bad] *= np.exp(1j * rng.uniform(0.5, 1.5, bad.sum()))
    d = estimate_delays(f, H, model)
    assert_allclose(d.seconds / SAMPLE, tau / SAMPLE, atol=0.02)
    assert np.all(np.abs(d.seconds - tau) < 5 * d.std)
    assert d.lines == f.size


def test_delays_are_read_from_the_frfs_alone_under_the_elastic_modes() -> None:
    """No model: a reference scenario's FRFs with 1 % noise (damped rigid-body modes, the
    elastic ones above the lines read), each response up to a sample late: read within 0.1
    sample from the values nearest the real axis (damping biases them a little); under 0.1
    sample where there is none."""
    sc = build_scenario(ScenarioSpec(seed=8210, shape="gearbox", n_forces=12, noise=0.01,
                                     elastic_ratio=6.0))
    under = sc.freq < 0.8 * sc.first_elastic_hz
    sample = 1 / (2.56 * sc.freq[-1])
    tau = np.random.default_rng(8310).uniform(-1, 1, sc.H.shape[0]) * sample
    use = np.ones(sc.H.shape[1:], bool)[:, under]
    d = realness_delays(sc.freq[under], _frfs(sc, tau).H[..., under], use,
                        1 / (2 * sc.freq[-1]))
    assert_allclose(d.seconds / sample, tau / sample, atol=0.1)
    none = realness_delays(sc.freq[under], sc.H[..., under], use, 1 / (2 * sc.freq[-1]))
    assert np.max(np.abs(none.seconds)) < 0.1 * sample
    with pytest.raises(InputError, match="values to read"):
        realness_delays(sc.freq[under], sc.H[..., under], use[:, :-1], 0.01)


def test_frfs_refused_for_their_delays_are_answered_with_the_delays_they_show() -> None:
    """5 % noise and delays of up to 1.25 samples: the first fit, on the FRFs as they are,
    has no usable mass (with the delays off the identification refuses). The delays read
    from the FRFs alone, then against the fit, are within 3 % of the largest, and the
    result is the unskewed FRFs' to a tenth of their errors."""
    sc = build_scenario(ScenarioSpec(seed=8218, shape="engine", n_forces=12, noise=0.05,
                                     elastic_ratio=6.0, band_ratio=0.4))
    tau = np.random.default_rng(8318).uniform(-1, 1, sc.H.shape[0]) / (2.048 * sc.freq[-1])
    with pytest.raises(InputError, match="no usable mass"):
        identify(_frfs(sc, tau), IdentifyOptions(channel_delays="off"))
    auto, clean = identify(_frfs(sc, tau)), identify(_frfs(sc))
    assert auto.channel_delays is not None, auto.channel_delays_note
    assert "from the FRFs alone" in auto.channel_delays_note
    assert np.max(np.abs(auto.channel_delays.seconds - tau)) < 0.03 * np.max(np.abs(tau))
    e, ec = _errors(sc, auto), _errors(sc, clean)
    for k in ("mass", "cog", "inertia"):
        assert abs(e[k] - ec[k]) <= 0.1 * ec[k] + 0.05, (k, e, ec)


def test_units_give_the_shifted_frfs() -> None:
    """The per-unit spectra with the delays taken out form the FRFs :meth:`shifted` gives."""
    rng = np.random.default_rng(8202)
    f = np.linspace(1.0, 100.0, 50)
    Sfx = rng.normal(size=(3, 4, f.size)) + 1j * rng.normal(size=(3, 4, f.size))
    col = UnitSpectra(f, rng.uniform(1, 2, (3, f.size)), Sfx, np.ones((3, 4, f.size)),
                      np.ones(3))
    units = TimeUnits("hit", (col,), np.array([1]), np.array([[0.0, 0.0, 1.0]]))
    d = ChannelDelays(rng.uniform(-1, 1, 4) * SAMPLE, np.zeros(4))
    H = col.Sfx.sum(0) / col.Sff.sum(0)
    got = d.units(units).columns[0]
    # the units are kept in single precision (processing.units): sums to a few roundings
    assert_allclose(got.Sfx.sum(0) / got.Sff.sum(0), d.shifted(f, H[:, None])[:, 0], rtol=2e-6)


@pytest.mark.parametrize("shape", ["engine", "gearbox"])
def test_skewed_channels_are_read_and_taken_out(shape: str) -> None:
    """A reference scenario's FRFs with 0.5 % noise, each response up to a sample late at
    1024 Hz: the delays are read within 0.05 sample, the inertia parameters come within the
    unskewed FRFs' errors (plus a little), CoG and inertia at least twice as close as with the
    FRFs as they are, the mass closer."""
    sc = build_scenario(ScenarioSpec(seed=8203, shape=shape, n_forces=12, noise=0.005,
                                     elastic_ratio=8.0))
    tau = np.random.default_rng(8204).uniform(-1, 1, sc.H.shape[0]) * SAMPLE
    auto = identify(_frfs(sc, tau))
    off = identify(_frfs(sc, tau), IdentifyOptions(channel_delays="off"))
    clean = identify(_frfs(sc))
    assert auto.channel_delays is not None, auto.channel_delays_note
    assert "taken out" in auto.channel_delays_note
    assert_allclose(auto.channel_delays.seconds / SAMPLE, tau / SAMPLE, atol=0.05)
    e, e0, ec = _errors(sc, auto), _errors(sc, off), _errors(sc, clean)
    for k in ("mass", "cog", "inertia"):
        assert e[k] <= ec[k] + {"mass": 0.2, "cog": 0.5, "inertia": 0.5}[k], (k, e, ec)
    assert e0["cog"] > 2 * e["cog"] and e0["inertia"] > 2 * e["inertia"], (e0, e)
    assert e0["mass"] > e["mass"], (e0, e)
    js = auto.to_json()["channel_delays"]
    assert_allclose(js["seconds"], auto.channel_delays.seconds)
    assert off.channel_delays is None and off.channel_delays_note.endswith("asked for")


@pytest.mark.parametrize("seed", [8205, 8206])
def test_frfs_without_delays_are_left_as_they_are(seed: int) -> None:
    """Reference FRFs with noise, a flexible body and test errors but no delay: no delay is
    taken out, and the result is the one with the delays off, to the bit."""
    sc = build_scenario(ScenarioSpec(seed=seed, shape="engine", n_forces=18, noise=0.01,
                                     elastic_ratio=8.0, location_error=0.002,
                                     misalignment_deg=1.0))
    auto = identify(_frfs(sc))
    off = identify(_frfs(sc), IdentifyOptions(channel_delays="off"))
    assert auto.channel_delays is None, auto.channel_delays_note
    assert_allclose(auto.theta, off.theta, rtol=0, atol=0)


def test_the_plain_method_reads_no_delay() -> None:
    sc = build_scenario(ScenarioSpec(seed=8207, shape="engine", n_forces=12))
    tau = np.full(sc.H.shape[0], 0.5 * SAMPLE)
    res = identify(_frfs(sc, tau), IdentifyOptions(method="plain"))
    assert res.channel_delays is None and "article's method" in res.channel_delays_note


def test_the_command_line_reads_or_leaves_the_delays(tmp_path) -> None:
    """``insitu identify`` takes the delays out by default and states them in the result JSON
    and on the terminal; ``--channel-delays off`` leaves the FRFs as they are."""
    from app.cli.main import main
    from app.io.uff import write_frf_uff

    sc = build_scenario(ScenarioSpec(seed=8208, shape="engine", n_forces=12, noise=0.005,
                                     elastic_ratio=8.0))
    tau = np.random.default_rng(8209).uniform(-1, 1, sc.H.shape[0]) * SAMPLE
    path = tmp_path / "frf.uff"
    write_frf_uff(path, dataclasses.replace(_frfs(sc, tau)), binary=True)
    out = {}
    for name, extra in (("auto", []), ("off", ["--channel-delays", "off"])):
        js = tmp_path / f"{name}.json"
        assert main(["identify", str(path), *extra, "--no-uncertainty", "--out", str(js)]) == 0
        out[name] = json.loads(js.read_text())
    assert_allclose(np.asarray(out["auto"]["channel_delays"]["seconds"]) / SAMPLE, tau / SAMPLE,
                    atol=0.05)
    assert out["auto"]["channel_delays_choice"].startswith("channel delays read on")
    assert out["off"]["channel_delays"] is None
    assert out["off"]["channel_delays_choice"].endswith("asked for")


def test_realness_grid_search_is_the_direct_one() -> None:
    """The realness delays' grid search (cos and sin of each line's turn) picks the delays
    the plain search picks: the mean |cos(angle(H) + w tau)| over the values read, each
    grid delay evaluated directly, then the same refinement."""
    from processing.delays import REAL_GRID, REAL_ROUNDS

    rng = np.random.default_rng(7201)
    freq = np.linspace(5.0, 300.0, 120)
    w = 2 * np.pi * freq
    true = np.array([2e-4, -5e-4, 0.0, 9e-4])
    H = (rng.standard_normal((4, 5, 120)) + 0.05j * rng.standard_normal((4, 5, 120))) * np.exp(
        -1j * w * true[:, None, None])
    use = rng.random((5, 120)) > 0.3
    use[:, 100:] = False
    H[1, 2, 7] = np.nan
    got = realness_delays(freq, H, use, 2e-3)

    keep = use[None] & np.isfinite(H) & (np.abs(H) > 0)
    ph = np.where(keep, np.angle(np.where(keep, H, 1.0)), 0.0)
    centre, half = np.zeros(4), 2e-3
    for _ in range(REAL_ROUNDS):
        taus = centre[:, None] + np.linspace(-half, half, REAL_GRID)[None]
        score = np.array([[np.sum(np.abs(np.cos(ph[r] + t * w))[keep[r]]) for t in taus[r]]
                          for r in range(4)])
        centre = taus[np.arange(4), np.argmax(score, axis=1)]
        half *= 4.0 / (REAL_GRID - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = H / np.abs(H)
    want = estimate_delays(freq, np.where(keep, unit, np.nan),
                           np.sign(np.cos(ph + w * centre[:, None, None])), use.astype(float))
    assert_allclose(got.seconds, want.seconds, rtol=1e-12, atol=1e-15)
    assert_allclose(got.seconds, true, atol=5e-5)  # and it finds them
