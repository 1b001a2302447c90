"""The identification of a measurement: one public :func:`fit`, as statsmodels has
``model.fit() -> results``.

``fit(measurement, options) -> IdentificationResult`` reads the FRFs and their provenance
(:class:`processing.measurement.Measurement`: given or estimated here from time records, the
exponential window, the hammer's usable band, the per-hit or per-block spectra) and the
user's choices (:class:`IdentifyOptions`); how the solver works is apart
(:class:`SolverSettings`). It runs the stages of :mod:`processing.stages`
(:func:`stages`: bands, weights, the mass line settled, the solve, the refusal of an
implausible mass, the checks), then the :func:`uncertainty` (the fit's covariance, the
Monte Carlo of stated test uncertainties, the bootstrap over hits or blocks of
:mod:`processing.bootstrap`) and :func:`processing.stages.assemble`.

:func:`identify` is the shorthand for FRFs given without provenance (an analyser's, a
simulation's): ``fit(Measurement(frf), options)``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.blas import one_blas_thread
from processing.bootstrap import DEFAULT_RESAMPLES, Bootstrap, Progress, resample
from processing.data import FRFSet, InputError
from processing.delays import ChannelDelays, estimate_delays, realness_delays
from processing.geometry import excitation_matrix
from processing.inertia import mass_matrix
from processing.measurement import Measurement
from processing.montecarlo import simulate
from processing.problem import (
    COHERENCE_NOISE_FLOOR,
    TIME_DATA_ERROR_FLOOR,
    IdentifyOptions,
    Problem,
    SolverSettings,
    prepare,
)
from processing.refine import point_offsets
from processing.results import IdentificationResult, Method, Uncertainty
from processing.selection import mode_shape_basis
from processing.stages import (
    Bands,
    Checks,
    Fit,
    LineWeights,
    assemble,
    check,
    choose_bands,
    implausible_mass,
    mass_line_among_modes,
    monte_carlo_model,
    refuse_implausible_mass,
    rigid_band_tops,
    settle_mass_band,
    solve,
    stiffness_operators,
    upper_residual,
    weigh_lines,
)
from processing.stiffness import stiffening_factor
from processing.synthesis import synthesise
from processing.uncertainty import (
    FitCovariance,
    combine,
    draw_covariance,
    draw_variances,
    fit_covariance,
    force_noise_ratio,
    regressor_weights,
)
from processing.units import MIN_UNITS, TimeUnits

__all__ = [
    "Bands",
    "Checks",
    "Fit",
    "IdentificationResult",
    "IdentifyOptions",
    "LineWeights",
    "Method",
    "SolverSettings",
    "Stages",
    "assemble",
    "bootstrap_identify",
    "check",
    "choose_bands",
    "coherence_unchecked",
    "fit",
    "identify",
    "settle_mass_band",
    "solve",
    "stages",
    "uncertainty",
    "upper_residual",
    "weigh_lines",
]


# --- what the fit reads from a measurement ---------------------------------------------------


@dataclass(frozen=True)
class _Data:
    """A measurement's arrays and the values its provenance sets, read once."""

    frf: FRFSet
    resp_xyz: NDArray[np.float64]
    exponential_tau: float | None
    coherence_floor: float
    elastic_top: float | None
    rigid_tops: tuple[float | None, float | None]
    units: TimeUnits | None
    notes: tuple[str, ...]
    measurement: Measurement


def _data(measurement: Measurement, options: IdentifyOptions,
          solver: SolverSettings) -> _Data:
    """What :func:`fit` reads from ``measurement``: the exponential window's tau, the error
    floor (FRFs given, or estimated here from time records), the hammer's usable band (no
    elastic mode above it: a note says so), the rigidity check's band tops (they bound the
    automatic mass line) and the per-hit or per-block spectra."""
    frf, prov = measurement.frf, measurement.provenance
    notes: list[str] = []
    top = prov.force_band_top
    elastic_top = top if top is not None and top < frf.freq[-1] else None
    if elastic_top is not None:
        notes.append(f"the hammer's force is 20 dB or more under its peak above {top:.0f} Hz: "
                     "residual peaks there are not taken for elastic modes (a harder tip "
                     "reaches higher)")
    tops: tuple[float | None, float | None] = (None, None)
    if solver.use_rigidity and (options.mass_band is None or options.stiffness_band is None):
        rigid_top, rigid_raised, rigid_notes = rigid_band_tops(frf)
        tops = (rigid_top, rigid_raised)
        notes += rigid_notes
    return _Data(frf, frf.resp_xyz, prov.exponential_tau,
                 TIME_DATA_ERROR_FLOOR if prov.estimated else COHERENCE_NOISE_FLOOR,
                 elastic_top, tops, measurement.time_units, tuple(notes), measurement)


# --- the stages ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Stages:
    """The stages of one fit (:mod:`processing.stages`), up to the checks."""

    problem: Problem
    bands: Bands
    weights: LineWeights
    fitted: Fit
    checks: Checks
    #: the response channels' delays taken out of the FRFs before the fit, or None
    delays: ChannelDelays | None = None
    #: how the channel delays were read, in words
    delays_note: str = ""


#: most times the mass line is moved above the fit's rigid-body modes (:func:`_stages`),
#: each raising the modes' floor by at least FLOOR_RISE
FLOOR_ROUNDS = 3
FLOOR_RISE = 1.05


def _problem(d: _Data, options: IdentifyOptions, solver: SolverSettings) -> Problem:
    frf = d.frf
    return prepare(frf.freq, frf.H, d.resp_xyz, frf.resp_dirs, frf.exc_xyz, frf.exc_dirs,
                   coherence=frf.coherence, options=options, solver=solver,
                   exponential_tau=d.exponential_tau, coherence_floor=d.coherence_floor,
                   elastic_top=d.elastic_top)


def _stages(d: _Data, options: IdentifyOptions, solver: SolverSettings) -> Stages:
    problem = _problem(d, options, solver)
    fits = [_fit_in_bands(problem, choose_bands(problem, *d.rigid_tops))]
    floor = 0.0
    for _ in range(FLOOR_ROUNDS):
        # the lines put the mass line among the rigid-body modes the fit finds: above
        # them; a fit on a mass line still among the modes reads them low: again. A fit
        # whose mass is no answer reads no mode: above the mass line it was given, when a
        # mass line from twice its top fits in the data (near the end of the data the
        # mass line more likely meets an elastic mode the residual did not show)
        bands, weights, fitted = fits[-1]
        top = mass_line_among_modes(problem, bands, fitted)
        hi = float(bands.mass_band[1])
        if (top is None and bands.choice is not None and options.mass_band is None
                and 2 * hi < problem.freq[-1]
                and implausible_mass(problem, bands, weights, fitted)):
            top = hi
        if top is None or top <= FLOOR_RISE * floor:
            break
        floor = top
        try:
            fits.append(_fit_in_bands(
                problem, choose_bands(problem, *d.rigid_tops, rigid_floor=floor)))
        except InputError:  # no bands above that floor: the rounds before stand
            break
    # the last round whose mass is an answer (the last round is refused when none is)
    bands, weights, fitted = next((f for f in reversed(fits) if not implausible_mass(
        problem, *f)), fits[-1])
    refuse_implausible_mass(problem, bands, weights, fitted)
    return Stages(problem, bands, weights, fitted, check(problem, bands, weights, fitted))


def _fit_in_bands(problem: Problem, bands: Bands) -> tuple[Bands, LineWeights, Fit]:
    """The lines weighed, the mass line settled and the fit, in ``bands``."""
    weights = weigh_lines(problem, bands)
    ops = stiffness_operators(problem, bands)  # the settling keeps the stiffness band
    bands, weights = settle_mass_band(problem, bands, weights, ops)
    return bands, weights, solve(problem, bands, weights, ops)


# --- the response channels' delays ----------------------------------------------------------

#: rounds of the channel-delay correction: read the delays against the fit, take them out,
#: fit again (:mod:`processing.delays`)
DELAY_ROUNDS = 6
#: the rounds stop when one turns no channel's phase at the top line by more than this, rad
DELAY_SETTLED = 2e-3
#: the delays are taken out when one is at least this many standard deviations from zero
#: and turns its channel's phase at the top line by at least DELAY_PHASE rad
DELAY_Z = 5.0
DELAY_PHASE = 0.01
#: the delays are kept only when they take the phase misfit to at most this fraction of the
#: FRFs' as given and under DELAY_MISFIT rad: delays explain most of the phase, not a
#: model that does not fit
DELAY_GAIN = 0.5
DELAY_MISFIT = 0.2
#: the delays are read from this factor times the highest rigid-body mode up
DELAY_LINES_FROM = 1.25
#: at least this many lines, else the mass line's
DELAY_MIN_LINES = 8
#: when the delays read against the first fit are not kept, they are read from the FRFs
#: alone (:func:`processing.delays.realness_delays`) on the lines under this fraction of
#: the first elastic mode seen (every line when fewer than DELAY_REAL_LINES are left)
DELAY_REAL_BELOW = 0.8
DELAY_REAL_LINES = 16
#: ... and taken out only when one turns its channel by this much at the top of those lines,
#: rad: delays too large for the first fit's band choice, not the ones damping mimics there
#: (under 0.44 rad on the development budget suite's exact FRFs, which have none, where no
#: elastic mode was seen and every line was read; time data read 0.9 rad and more)
DELAY_REAL_PHASE = 0.5


def _delay_lines(st: Stages) -> NDArray[np.bool_]:
    """The lines the delays are read on: from above the rigid-body modes to the top of the
    fit's mass line (the rigid model holds there), or the mass line's."""
    p, top = st.problem, float(st.bands.mass_band[1])
    modes = st.checks.rigid_modes_hz[np.isfinite(st.checks.rigid_modes_hz)]
    lo = DELAY_LINES_FROM * float(np.max(modes)) if modes.size else np.inf
    sel = (p.freq >= lo) & (p.freq <= top) & p.line_ok
    return sel if np.count_nonzero(sel) >= DELAY_MIN_LINES else st.weights.mass_lines


def _delays_against_fit(st: Stages, sel: NDArray[np.bool_]) -> ChannelDelays:
    """The delays of the problem's FRFs against the FRFs its fit synthesises, on ``sel``."""
    p, f = st.problem, st.fitted
    freq = p.freq[sel]
    model = synthesise(freq, p.E, p.T, mass_matrix(f.theta), f.K, f.C, f.D,
                       stiffening_factor(f.stiffening, 2 * np.pi * freq))
    return estimate_delays(freq, p.H[..., sel], model, p.col_weights[:, sel])


def _without_delays(d: _Data, delays: ChannelDelays, options: IdentifyOptions,
                    solver: SolverSettings, units: bool = True) -> _Data:
    """The data with the delays taken out of the FRFs and (``units``) of the per-unit
    spectra; without ``units``, none (a round's fit reads only the FRFs: the units, as
    large as the records, are shifted once, for the round kept)."""
    m = d.measurement
    frf = dataclasses.replace(m.frf, H=delays.shifted(m.frf.freq, m.frf.H))
    prov = m.provenance
    if prov.units is not None:
        prov = dataclasses.replace(prov, units=delays.units(prov.units) if units else None)
    out = _data(dataclasses.replace(m, frf=frf, provenance=prov), options, solver)
    return dataclasses.replace(out, resp_xyz=d.resp_xyz)


def _delayed_stages(d: _Data, options: IdentifyOptions, solver: SolverSettings,
                    ) -> tuple[Stages, _Data]:
    """The stages of ``d``, with the response channels' delays taken out first when the
    fit's phase shows them (:mod:`processing.delays`): the delays are read against the
    fitted model, taken out and the fit run again, until a round changes them no more. The
    round whose FRFs fit their own model best is kept, when it takes the phase misfit to at
    most :data:`DELAY_GAIN` of the FRFs' as given and under :data:`DELAY_MISFIT`. Else the
    delays are read from the FRFs alone (their values nearest the real axis under the first
    elastic mode, :func:`_delays_alone`: a first fit whose bands were chosen on FRFs turned
    by delays of a sample can be too far off to read them against) and the rounds run
    from there, the best kept when it fits its model better than the FRFs as given on its
    lines; else the FRFs as given. FRFs whose first fit has no usable mass get the delays
    they show alone the same way, kept when the round's phase misfit is under
    :data:`DELAY_MISFIT` (there is no first fit to do better than); else refused as before."""
    try:
        st = _stages(d, options, solver)
    except InputError:
        if options.channel_delays == "off" or options.method != "improved":
            raise
        alone = _delays_alone(d, options, solver, None)
        if alone is None or alone[1][0] > DELAY_MISFIT:  # no first fit to do better than
            raise
        _, (misfit, st_k, kept, rounds), span = alone
        assert kept is not None and st_k is not None
        note = (f"channel delays read from the FRFs alone, then read on {kept.lines} lines "
                f"{span[0]:.1f}-{span[1]:.1f} Hz and taken out (round {rounds}; the FRFs as "
                f"given had no usable mass; phase misfit {misfit:.3f} rad): up to "
                f"{1e3 * np.max(np.abs(kept.seconds)):.3g} ms")
        return (dataclasses.replace(st_k, delays=kept, delays_note=note),
                _without_delays(d, kept, options, solver))
    if options.channel_delays == "off":
        return dataclasses.replace(st, delays_note="channel delays not read: asked for"), d
    if not st.problem.improved:  # the article's plain method takes the FRFs as they are
        return dataclasses.replace(st, delays_note="channel delays not read: the article's "
                                   "method"), d
    sel = _delay_lines(st)
    step = _delays_against_fit(st, sel)
    w_top = 2 * np.pi * float(st.problem.freq[sel][-1])
    z = np.abs(step.seconds) / np.where(step.std > 0, step.std, np.inf)
    turn = w_top * np.abs(step.seconds)
    if not np.any((z >= DELAY_Z) & (turn >= DELAY_PHASE)):
        return dataclasses.replace(
            st, delays_note=(f"no channel delay: the largest turns the phase by "
                             f"{np.max(turn):.3f} rad at {w_top / 2 / np.pi:.0f} Hz "
                             f"({np.max(z):.1f} sd), under {DELAY_PHASE} rad or {DELAY_Z} sd")), d
    # each round on the first fit's lines; the round whose data fit their own model best
    # is kept (the FRFs as given when none fits better)
    first = step.misfit
    misfit, st_k, kept, rounds = _delay_rounds(d, options, solver, (first, st, None, 0), step,
                                               st.problem.freq, sel)
    span = (float(st.problem.freq[sel][0]), float(st.problem.freq[sel][-1]))
    how = ""
    if kept is None or misfit > min(DELAY_GAIN * first, DELAY_MISFIT):
        # the first fit's phase is too far off for the delays read against it (its bands
        # chosen on the delayed FRFs): the delays the FRFs show alone, then the rounds
        alone = _delays_alone(d, options, solver, st)
        if alone is None:
            return dataclasses.replace(
                st, delays_note=(f"channel delays not taken out: they take the phase misfit "
                                 f"from {first:.3f} rad only to {misfit:.3f} rad (at most "
                                 f"{DELAY_GAIN:g}x and {DELAY_MISFIT} rad), and the FRFs "
                                 "show none alone: the model does not fit for another "
                                 "reason")), d
        first, (misfit, st_k, kept, rounds), span = alone
        how = "read from the FRFs alone, then "
    assert kept is not None and st_k is not None
    note = (f"channel delays {how}read on {kept.lines} lines {span[0]:.1f}-{span[1]:.1f} Hz "
            f"and taken out (round {rounds}; phase misfit {first:.3f} -> {misfit:.3f} "
            f"rad): up to {1e3 * np.max(np.abs(kept.seconds)):.3g} ms")
    d_k = _without_delays(d, kept, options, solver)  # the FRFs of round k, and the units
    return dataclasses.replace(st_k, delays=kept, delays_note=note), d_k


_Round = tuple[float, "Stages | None", ChannelDelays | None, int]


def _delay_rounds(d: _Data, options: IdentifyOptions, solver: SolverSettings,
                  given: _Round, total: ChannelDelays, freq: NDArray[np.float64],
                  sel: NDArray[np.bool_], first: Stages | None = None) -> _Round:
    """(misfit, stages, delays, round) of the round whose FRFs fit their own model best on
    ``sel`` (of the lines ``freq``), the delays ``total`` taken out, then those read against
    each round's fit; ``given`` (the FRFs as given's misfit there, their stages, no delays,
    round 0; misfit inf when they have no fit) when no round does better. ``first``: the
    stages of the first round when they are already at hand."""
    w_top = 2 * np.pi * float(freq[sel][-1])
    best = given
    for rounds in range(1, DELAY_ROUNDS + 1):
        if rounds == 1 and first is not None:
            st_k = first
        else:
            d_k = _without_delays(d, total, options, solver, units=False)
            try:
                st_k = _stages(d_k, options, solver)
            except InputError:  # a round's fit refused: the best round so far stands
                break
        step = _delays_against_fit(st_k, sel)
        if step.misfit < best[0]:
            best = (step.misfit, st_k, total, rounds)
        if w_top * float(np.max(np.abs(step.seconds))) < DELAY_SETTLED:
            break
        total = total + step
    return best


def _delays_alone(d: _Data, options: IdentifyOptions, solver: SolverSettings,
                  st: Stages | None) -> tuple[float, _Round, tuple[float, float]] | None:
    """The rounds from the delays the FRFs show alone (:func:`realness_delays`), on the
    lines the fit without them reads delays on: (the FRFs as given's misfit there, the best
    round, the lines' span), or None when the FRFs show no delay, or no round fits its model
    better than the FRFs as given. Read with no model, these delays need no fit to hold
    (on a development-suite case, the channels' skews to 0.1 ms), so a round is kept
    even when something else leaves the misfit high. ``st`` None: the FRFs as given have no
    fit (their misfit inf)."""
    p = _problem(d, options, solver) if st is None else st.problem
    under = p.line_ok.copy()
    if p.peaks:
        low = under & (p.freq < DELAY_REAL_BELOW * min(k.frequency for k in p.peaks))
        under = low if np.count_nonzero(low) >= DELAY_REAL_LINES else under
    if np.count_nonzero(under) < DELAY_MIN_LINES:
        return None
    alone = realness_delays(p.freq[under], p.H[..., under], p.col_weights[:, under] > 0,
                            1.0 / (2 * float(p.freq[-1])))
    w_top = 2 * np.pi * float(p.freq[under][-1])
    z = np.abs(alone.seconds) / np.where(alone.std > 0, alone.std, np.inf)
    if not np.any((z >= DELAY_Z) & (w_top * np.abs(alone.seconds) >= DELAY_REAL_PHASE)):
        return None
    try:
        st_a = _stages(_without_delays(d, alone, options, solver, units=False), options,
                       solver)
    except InputError:
        return None
    sel = _delay_lines(st_a)
    first = np.inf if st is None else _delays_against_fit(st, sel).misfit
    best = _delay_rounds(d, options, solver, (first, st, None, 0), alone, p.freq, sel, st_a)
    if best[2] is None:  # no round fits its model better than the FRFs as given
        return None
    return first, best, (float(p.freq[sel][0]), float(p.freq[sel][-1]))


@one_blas_thread
def stages(measurement: Measurement, options: IdentifyOptions | None = None,
           solver: SolverSettings | None = None) -> Stages:
    """The stages :func:`fit` runs on ``measurement`` (no point refinement): prepared
    problem, bands, line weights, the fit and its checks.

    Raises
    ------
    InputError, GeometryError
        With a one-line message naming the problem and what to do.
    """
    opt, sol = options or IdentifyOptions(), solver or SolverSettings()
    return _delayed_stages(_data(measurement, opt, sol), opt, sol)[0]


# --- uncertainty -----------------------------------------------------------------------------


_COV_SOURCE = ("fit covariance: mass-line residual (block-robust over lines, band drift), "
               "stiffness-line scatter, force-noise bias (coherence) and body flexibility, "
               "propagated to first order")


def _bootstrap(st: Stages, units: TimeUnits, progress: Progress | None = None,
               ) -> Bootstrap | str | None:
    """The bootstrap over the time data's hits or blocks (a :class:`Bootstrap`), or why it
    did not run (a line), or None when turned off (``options.bootstrap == 0``). By default it
    runs with 200 resamples when every point has at least :data:`MIN_UNITS` units."""
    n = st.problem.options.bootstrap
    if n == 0:
        return None
    least = min(c.n_units for c in units.columns)
    if n is None:
        if not _bootstrap_runs(st.problem.options, units):
            return (f"no bootstrap over {units.kind}s: a point has {least} (at least "
                    f"{MIN_UNITS} for the default; --bootstrap N runs it with 2)")
        n = DEFAULT_RESAMPLES
    return resample(st.problem, st.bands, st.weights, st.fitted, units, n, progress=progress)


def _bootstrap_runs(options: IdentifyOptions, units: TimeUnits | None) -> bool:
    """Whether :func:`_bootstrap` resamples these units with these options."""
    if units is None or options.bootstrap == 0 or not options.uncertainty:
        return False
    return options.bootstrap is not None or min(c.n_units for c in units.columns) >= MIN_UNITS


def uncertainty(st: Stages,
                node_ids: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
                units: TimeUnits | None = None,
                progress: Progress | None = None) -> Uncertainty | None:
    """Standard deviations of every result: the fit's covariance
    (:mod:`processing.uncertainty`), plus the Monte Carlo of the stated test uncertainties
    (:mod:`processing.montecarlo`) when the options state any, and, for time data whose
    ``units`` are given, the bootstrap over hits or blocks (:mod:`processing.bootstrap`;
    it measures the FRF noise the covariance reads off the residual, so per number the
    larger of the two is kept, and it gives the asymmetric ``ci95``); None when the fit
    kept no state for it. ``progress(done, total)`` follows the bootstrap's resamples."""
    problem, bands, weights, fitted = st.problem, st.bands, st.weights, st.fitted
    if fitted.mass_line is None or fitted.mass_rhs is None or fitted.stiffness_map is None:
        return None
    used = weights.stiffness_lines[bands.in_stiffness]
    msel = weights.mass_lines
    coh = problem.coherence
    w_s = problem.w[weights.stiffness_lines]
    Ks = st.checks.stiffness_per_line[used]
    if fitted.stiffening is not None:  # each line's K* brought to f_k: (K* - j w C) / g + j w C
        jwC = 1j * w_s[:, None, None] * fitted.C[None]
        Ks = (Ks - jwC) / fitted.stiffening.factor(w_s)[:, None, None] + jwC
    cov: FitCovariance = fit_covariance(
        fitted.mass_line, fitted.theta, fitted.mass_rhs, fitted.stiffness_map, Ks, w_s, fitted.K,
        fitted.C, half_thetas=fitted.half_thetas, D=fitted.D, w_mass=problem.w[msel],
        force_noise=0.0 if coh is None else force_noise_ratio(coh[..., msel], weights.mass),
        stiff_weight=regressor_weights(problem.X[..., weights.stiffness_lines],
                                       weights.stiffness, problem.row_scale),
        elastic_hz=tuple(p.frequency for p in problem.peaks),
        # K and C come out symmetric but for the plain method's line average
        symmetric=problem.solver.symmetric and (problem.improved
                                                or bool(problem.window_decay)))
    stated = problem.options.stated
    sources: tuple[str, ...] = (_COV_SOURCE,)
    extra = extra_cov = None
    if stated is not None and stated.stated:
        draws = simulate(monte_carlo_model(problem, weights, fitted, node_ids), stated)
        extra = draw_variances(draws.theta, draws.K, draws.C, draws.z, draws.groups)
        extra_cov = draw_covariance(draws.theta, draws.K, draws.C)
        sources = (*sources, stated.describe())
    boot = None if units is None else _bootstrap(st, units, progress)
    if isinstance(boot, str):
        sources = (*sources, boot)
        boot = None
    if boot is None:
        return combine(fitted.theta, fitted.K, cov.parts, sources, extra, extra_cov)
    unc = combine(fitted.theta, fitted.K, cov.parts, (*sources, boot.describe()), extra,
                  extra_cov, boot.variances(), boot.covariance())
    return dataclasses.replace(unc, ci95=boot.intervals(fitted.theta, fitted.K, fitted.C,
                                                        unc.std))


# --- the fit ---------------------------------------------------------------------------------


#: called with the result before the bootstrap runs (see :func:`fit`)
Preliminary = Callable[[IdentificationResult], None]


def _fit_once(d: _Data, options: IdentifyOptions, solver: SolverSettings,
              progress: Progress | None = None,
              preliminary: Preliminary | None = None) -> IdentificationResult:
    st, d = _delayed_stages(d, options, solver)
    frf = d.frf
    nodes = (frf.resp_nodes, frf.exc_nodes)
    if preliminary is not None and _bootstrap_runs(options, d.units):
        preliminary(_assembled(st, uncertainty(st, nodes)))
    unc = uncertainty(st, nodes, d.units, progress) if options.uncertainty else None
    return _assembled(st, unc)


def _assembled(st: Stages, unc: Uncertainty | None) -> IdentificationResult:
    """The result of the stages (:func:`processing.stages.assemble`) with their delays."""
    return dataclasses.replace(
        assemble(st.problem, st.bands, st.weights, st.fitted, st.checks, unc),
        channel_delays=st.delays, channel_delays_note=st.delays_note)


@one_blas_thread
def fit(measurement: Measurement, options: IdentifyOptions | None = None,
        solver: SolverSettings | None = None, *,
        progress: Progress | None = None,
        preliminary: Preliminary | None = None) -> IdentificationResult:
    """Identify the ten inertia parameters and K, C at O from a measurement.

    Uses what the measurement carries besides H: its coherence (each FRF value weighed by
    the noise it stands for, with the error floor of FRFs estimated here from time records
    when its provenance says so), the rigidity check of its response nodes (bounds the
    automatic mass-line band), the exponential window's tau (the damping it added is
    removed from C), the hammer's usable band and the per-hit or per-block spectra (the
    bootstrap).

    Parameters
    ----------
    measurement : the FRFs and their provenance
    options : the user's choices (bands, method, physical constraint, uncertainty)
    solver : how the solver works (default :class:`SolverSettings`)
    progress : ``progress(done, total)``, called as the bootstrap's resamples are solved
        (for a view's progress bar; the result does not depend on it)
    preliminary : when the bootstrap runs, called first with the result without it (the
        same estimates, the fit covariance's spreads): a live view shows that at once,
        the bootstrap taking a second or more

    Raises
    ------
    InputError, GeometryError
        With a one-line message naming the problem and what to do.

    Examples
    --------
    >>> from hardware_mocks.benches import get_bench  # doctest: +SKIP
    >>> fit(Measurement(get_bench("engine-rigid").frfset())).properties.mass  # doctest: +SKIP
    110.0...
    """
    opt, sol = options or IdentifyOptions(), solver or SolverSettings()
    d = _data(measurement, opt, sol)
    unchecked = coherence_unchecked(measurement)

    def noted(result: IdentificationResult) -> IdentificationResult:
        if d.notes:
            result = dataclasses.replace(result, warnings=(*result.warnings, *d.notes))
        if unchecked:
            result = dataclasses.replace(result, coherence_checked=False,
                                         coherence_unchecked=unchecked)
        return result

    early = None if preliminary is None else lambda r: preliminary(noted(r))
    return noted(_refined(d, opt, sol) if opt.refine_points > 0
                 else _fit_once(d, opt, sol, progress, early))


def coherence_unchecked(measurement: Measurement) -> str:
    """Why the coherence of ``measurement`` cannot show noise, or "" when it can.

    Without coherence there is nothing to check; with at most as many records (hits,
    blocks) a point as forces driven at once (one hit, one block; two blocks of two
    shakers) the H1 coherence is 1 by definition, whatever the noise: a check on it cannot
    fail."""
    prov = measurement.provenance
    if measurement.frf.coherence is None:
        return "no coherence in the input"
    if not prov.n_averages or max(prov.n_averages) > prov.references:
        return ""
    kind = prov.excitation
    word = "hit" if kind in ("impact", "hammer") else "block" if kind else "record"
    n = max(prov.n_averages)
    if prov.references > 1:
        return (f"{n} {word}{'s' if n > 1 else ''} a point for {prov.references} forces: "
                "the multiple coherence is 1 by definition")
    return f"one {word} a point: the coherence is 1 by definition"


def identify(frf: FRFSet, options: IdentifyOptions | None = None,
             solver: SolverSettings | None = None) -> IdentificationResult:
    """:func:`fit` of FRFs given without provenance (an analyser's, a simulation's)."""
    return fit(Measurement(frf), options, solver)


def _refined(d: _Data, opt: IdentifyOptions, solver: SolverSettings) -> IdentificationResult:
    """Identification alternated at most ``opt.refine_points`` times with response-point
    refinement on the mass-line lines (:mod:`processing.refine`); no bootstrap.

    A round is kept only when the synthesised FRFs fit the data better than before; the
    rounds stop when a step moves no point by more than 0.01 mm (converged) or when a
    step does not improve the fit (the previous locations are kept). The reason is
    given in the warnings.
    """
    # the channel delays read once, on the given locations, and kept for every round
    st0, d = _delayed_stages(d, opt, solver)
    once = dataclasses.replace(opt, refine_points=0, channel_delays="off")
    d = dataclasses.replace(d, units=None)

    def identify_at(xyz: NDArray[np.float64]) -> IdentificationResult:
        return dataclasses.replace(_fit_once(dataclasses.replace(d, resp_xyz=xyz), once, solver),
                                   channel_delays=st0.delays,
                                   channel_delays_note=st0.delays_note)

    frf = d.frf
    xyz0 = np.asarray(d.resp_xyz, dtype=float)
    result, xyz = identify_at(xyz0), xyz0.copy()
    T = excitation_matrix(frf.exc_xyz, frf.exc_dirs)
    freq = np.asarray(frf.freq, dtype=float)
    why = f"the {opt.refine_points} rounds asked for were done"
    for k in range(1, opt.refine_points + 1):
        lines = np.isin(freq, result.mass_lines)
        w = 2 * np.pi * freq[lines]
        shapes = [mode_shape_basis(w, p) for p in result.elastic_modes]
        shapes.append(np.asarray(w**2, dtype=np.complex128))  # quasi-static, modes above
        step = point_offsets(freq[lines], np.asarray(frf.H)[..., lines], xyz, frf.resp_dirs,
                             T, result.M, result.K, result.C, shapes=np.array(shapes),
                             applied=xyz0 - xyz, D=result.D)
        trial = identify_at(xyz - step)
        if trial.synthesis.overall >= result.synthesis.overall:
            why = f"round {k} did not improve the fit of the synthesised FRFs; kept round {k - 1}"
            break
        result, xyz = trial, xyz - step
        if np.max(np.abs(step)) < 1e-5:
            why = f"converged after {k} rounds (last step under 0.01 mm)"
            break
    return dataclasses.replace(result, point_corrections=xyz0 - xyz,
                               warnings=(*result.warnings, f"point refinement: {why}"))


# --- the bootstrap alone ---------------------------------------------------------------------


@one_blas_thread
def bootstrap_identify(measurement: Measurement, options: IdentifyOptions | None = None,
                       n: int = DEFAULT_RESAMPLES, seed: int = 0,
                       solver: SolverSettings | None = None,
                       progress: Progress | None = None) -> tuple[Fit, Bootstrap | str]:
    """The fit of ``fit(measurement, options)`` (every stage, bands and model as it chooses
    them; no point refinement) and its bootstrap over the measurement's hits or blocks
    alone (without the other sources): for studies of the bootstrap itself."""
    if measurement.time_units is None:
        raise InputError("the measurement carries no per-hit or per-block spectra for every "
                         "column (time data only)")
    opt, sol = options or IdentifyOptions(), solver or SolverSettings()
    st, d = _delayed_stages(_data(measurement, opt, sol), opt, sol)
    units = d.units
    assert units is not None
    return st.fitted, resample(st.problem, st.bands, st.weights, st.fitted, units, n, seed,
                               progress)
