"""The stages of the identification, each a function of the prepared problem.

:func:`processing.problem.prepare` -> :func:`choose_bands` -> :func:`weigh_lines` ->
:func:`settle_mass_band` -> :func:`solve` -> :func:`refuse_implausible_mass` ->
:func:`check` -> (the uncertainty: :func:`processing.identify.uncertainty`) ->
:func:`assemble`. :func:`processing.identify.fit` runs them on a measurement; the bootstrap
(:mod:`processing.bootstrap`) re-solves with the same :class:`StiffnessStep` and
:func:`iterate`, with the bands, lines and models of the main fit held fixed.

Two methods on the same data:

``plain``
    The article as written: X = E^+ H (eq. 6); inertia by least squares over
    the mass-band lines (eqs. 7-11) with the stiffness term from eq. (14)
    averaged over the stiffness band; iterated until theta converges
    (section 2.2); lines kept by the rules of section 3.
``improved`` (default)
    The same equations, plus: moment equations scaled by the size of the
    measurement (balanced rows); K and C fitted directly and symmetric over the
    stiffness band, with a structural (hysteretic) damping D in ``K* = K + j w C + j D``
    instead of or besides C when the stiffness lines call for it (BIC); the leakage
    of elastic modes into the mass line modelled by free terms with the shape of each
    elastic mode found in the data (and a ``w^2`` term for modes above it), eliminated
    by projection; the mass
    line allowed to extend close to the first elastic mode.

Both weigh each FRF value by its coherence (a low value counts for less; none is
dropped for it: :func:`processing.problem.prepare`), honour the per-line rank and
condition of T, and optional physical consistency (``physical=True``).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from processing.coherence import coherence_gate
from processing.data import FRFSet, InputError
from processing.geometry import GeometryError
from processing.inertia import InertiaProperties, inertia_properties, mass_matrix
from processing.massline import MassLineFit, MassLineProblem, stack_real
from processing.montecarlo import MonteCarloModel, build_model
from processing.physical import constrain_physical
from processing.problem import Problem
from processing.results import IdentificationResult, Uncertainty
from processing.rigidity import rigidity_check
from processing.selection import (
    BandChoice,
    mode_shape_basis,
    quick_rigid_modes,
    select_lines,
)
from processing.selection import choose_bands as choose_automatic_bands
from processing.stiffness import (
    DAMPING_MODELS,
    DampingModel,
    LeakageMoments,
    LineOperators,
    Stiffening,
    StiffnessMoments,
    choose_damping,
    choose_stiffening,
    dynamic_stiffness,
    fit_stiffness,
    line_operators,
    stiffening_factor,
    stiffness_moments,
)
from processing.synthesis import SynthesisFit, synthesis_error, synthesise
from processing.uncertainty import StiffnessMap
from processing.windows import correct_dynamic_stiffness

__all__ = [
    "BAND_CANDIDATES",
    "Bands",
    "Checks",
    "Fit",
    "LineWeights",
    "StiffnessStep",
    "assemble",
    "check",
    "choose_bands",
    "implausible_mass",
    "iterate",
    "leakage_shapes",
    "mass_line_among_modes",
    "mass_line_reading",
    "monte_carlo_model",
    "refuse_implausible_mass",
    "rigid_band_tops",
    "settle_mass_band",
    "solve",
    "stiffness_operators",
    "upper_residual",
    "weigh_lines",
]

log = logging.getLogger(__name__)


# --- stage 1: bands --------------------------------------------------------------------------


@dataclass(frozen=True)
class Bands:
    """The mass-line and stiffness bands (Hz) and their lines.

    ``leakage`` is True when the elastic modes' leakage into the mass line is
    modelled (the band may then reach 0.7x the first elastic mode, else 0.5x);
    ``choice`` holds the evidence of an automatic choice.
    """

    mass_band: tuple[float, float]
    stiffness_band: tuple[float, float]
    in_mass: NDArray[np.bool_]
    in_stiffness: NDArray[np.bool_]
    leakage: bool
    choice: BandChoice | None
    warnings: tuple[str, ...]
    #: which bands were chosen and why, in words
    reason: str = ""


def _band_mask(freq: NDArray[np.float64], band: tuple[float, float], what: str) -> (
    NDArray[np.bool_]
):
    lo, hi = float(band[0]), float(band[1])
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
        raise InputError(f"{what} band {lo:g}-{hi:g} Hz is empty: give LO < HI")
    if lo < freq[0] - 1e-9 or hi > freq[-1] + 1e-9:
        raise InputError(
            f"{what} band {lo:g}-{hi:g} Hz is outside the data ({freq[0]:g}-{freq[-1]:g} Hz): "
            "choose a band inside it"
        )
    m = (freq >= lo) & (freq <= hi)
    if np.count_nonzero(m) < 2:
        raise InputError(f"{what} band {lo:g}-{hi:g} Hz holds fewer than 2 lines: widen it")
    return m


def choose_bands(problem: Problem, rigid_band_top: float | None = None,
                 rigid_band_fallback: float | None = None,
                 rigid_floor: float | None = None) -> Bands:
    """The bands given in the options, or chosen from the data (``rigid_band_top``, Hz,
    bounds an automatic mass line; ``rigid_band_fallback`` when it leaves none;
    ``rigid_floor``, Hz, the least highest rigid-body mode, :func:`mass_line_among_modes`)."""
    opt, peaks, noise = problem.options, problem.peaks, problem.noise
    # Leakage terms are free per equation entry: on noisy data the regressors left after
    # eliminating them are dominated by noise and the fit is biased low (errors in
    # variables). Model the leakage only when the FRF noise, read off the rigid-body
    # reconstruction residual well below the first elastic mode, is small.
    leak = (problem.improved and problem.solver.leakage == "auto" and len(peaks) > 0
            and noise <= problem.solver.leakage_max_noise)
    warnings: list[str] = []
    choice: BandChoice | None = None
    if opt.mass_band is None or opt.stiffness_band is None:
        clean = problem.clean_lines
        # the rigid-body modes are read from the lines under the rigidity check's limit;
        # where lightly damped resonances make every line there unclean (a column's weight
        # dips with its FRF's peak), fewer than 8 would be left: all the lines are used
        under = problem.freq <= (rigid_band_top or problem.freq[-1])
        if np.count_nonzero(clean & under) < 8 <= np.count_nonzero(under):
            clean = np.ones_like(clean)
        snr = problem.line_snr
        # the stiffness band from the first line holding more signal than noise (the fit
        # weighs each line by its coherence; lines left out of the clean ones still count)
        heard = np.ones(problem.freq.size, bool) if snr is None else snr >= 1.0
        choice = choose_automatic_bands(problem.freq[clean], problem.X[..., clean], problem.T,
                                        peaks, elastic_margin=0.7 if leak else 0.5,
                                        line_weights=None if snr is None else snr[clean],
                                        rigid_band_top=rigid_band_top,
                                        rigid_band_fallback=rigid_band_fallback,
                                        stiffness_low=float(problem.freq[heard][0])
                                        if np.any(heard) else None,
                                        rigid_floor=rigid_floor)
    mass_band = opt.mass_band or (choice.mass_band if choice else (0.0, 0.0))
    stiff_band = opt.stiffness_band or (choice.stiffness_band if choice else (0.0, 0.0))
    reason = "bands given" if choice is None else (
        choice.reason if opt.mass_band is None else "mass line given; stiffness band chosen")
    if problem.improved and peaks and not leak and choice is not None and opt.mass_band is None:
        reason += f"; {_unmodelled_leakage(problem)}: mass line kept under half the elastic mode"
    if choice is not None and choice.relaxed and opt.mass_band is None:
        warnings.append(choice.reason)
    return Bands(
        mass_band=(float(mass_band[0]), float(mass_band[1])),
        stiffness_band=(float(stiff_band[0]), float(stiff_band[1])),
        in_mass=_band_mask(problem.freq, mass_band, "mass-line"),
        in_stiffness=_band_mask(problem.freq, stiff_band, "stiffness"),
        leakage=leak, choice=choice, warnings=tuple(warnings), reason=reason,
    )


#: an automatic mass line starts at least this many times above the fitted rigid-body modes
MODE_CLEARANCE = 1.3


def mass_line_among_modes(problem: Problem, bands: Bands, fitted: Fit) -> float | None:
    """The fit's highest rigid-body mode (Hz) when the automatic mass line starts under
    :data:`MODE_CLEARANCE` times it, else None.

    The rigid-body modes the bands are chosen by are read off the lines' apparent mass
    (:func:`~processing.selection.quick_rigid_modes`); on noisy FRFs under a rigidity limit
    set low by that noise, the estimate can fall far under the modes, and the mass line
    starts among them: the fit then reads resonances as mass (one noisy hit a point: 92 kg
    for 110). The modes of the fitted M and K say so. When the fitted M is not even
    positive definite (the resonances read as mass make it so) but its mass is positive,
    the largest real positive eigenvalue of ``K v = w^2 M v`` stands for the highest mode.
    """
    if bands.choice is None or problem.options.mass_band is not None:
        return None
    M = mass_matrix(fitted.theta)
    try:
        w2 = scipy.linalg.eigh(fitted.K, M, eigvals_only=True)
    except (np.linalg.LinAlgError, ValueError):
        if not fitted.theta[0] > 0:  # no mass, no modes to read
            return None
        try:
            ev = scipy.linalg.eigvals(fitted.K, M)
        except (np.linalg.LinAlgError, ValueError):
            return None
        w2 = np.sort(ev.real[np.isfinite(ev) & (np.abs(ev.imag) <= 1e-9 * np.abs(ev))])
        if not w2.size:
            return None
    top = float(np.sqrt(max(float(w2[-1]), 0.0)) / (2 * np.pi))
    return top if bands.mass_band[0] < MODE_CLEARANCE * top else None


def _unmodelled_leakage(problem: Problem) -> str:
    """Why the elastic modes' leakage into the mass line is not modelled, in words."""
    if problem.solver.leakage == "off":
        return "elastic leakage not modelled (turned off)"
    return (f"elastic leakage not modelled (FRF noise {problem.noise * 100:.2f} % > "
            f"{problem.solver.leakage_max_noise * 100:g} %)")


def _leakage_unmodelled(problem: Problem, bands: Bands) -> bool:
    """True when elastic modes are seen but their leakage into the mass line is not modelled
    (improved method)."""
    return problem.improved and bool(problem.peaks) and not bands.leakage


#: the half-band drift of an estimate (its two halves' difference over that difference's
#: standard deviation) above which the unmodelled elastic leakage is warned about: the
#: largest of ten near-normal numbers exceeds it by chance about once in 40 fits (3 > the
#: 2.8 of a 5 % Bonferroni bound over the ten parameters)
LEAKAGE_DRIFT_Z = 3.0

_THETA_NAMES = ("mass", "m x_c", "m y_c", "m z_c", "J_xx", "J_yy", "J_zz", "J_xy", "J_xz",
                "J_yz")


def leakage_drift(fitted: Fit) -> tuple[float, int] | None:
    """How far the estimates of the lower and upper halves of the mass line disagree, in
    standard deviations of their difference (twice the fit's own, drift-free standard
    deviation, :func:`processing.uncertainty.theta_covariance`), and the parameter where
    most: (z, index into theta); None without the halves or the mass-line state.

    Elastic modes above the band add a residual growing like ``w^2`` to the mass line's
    accelerances: where it matters, the estimate drifts with the band beyond its noise."""
    if fitted.half_thetas is None or fitted.mass_line is None or fitted.mass_rhs is None:
        return None
    from processing.uncertainty import theta_covariance

    d = np.asarray(fitted.half_thetas[1]) - np.asarray(fitted.half_thetas[0])
    sd = np.sqrt(np.clip(np.diag(theta_covariance(fitted.mass_line, fitted.theta,
                                                   fitted.mass_rhs)), 0.0, None))
    z = np.abs(d) / np.maximum(2 * sd, 1e-300)
    if not np.all(np.isfinite(z)):
        return None
    k = int(np.argmax(z))
    return float(z[k]), k


def leakage_warning(problem: Problem, bands: Bands, fitted: Fit) -> str | None:
    """The warning when unmodelled elastic leakage bends the mass line beyond its noise
    (:func:`leakage_drift` over :data:`LEAKAGE_DRIFT_Z`), else None."""
    if not _leakage_unmodelled(problem, bands):
        return None
    drift = leakage_drift(fitted)
    if drift is None or drift[0] <= LEAKAGE_DRIFT_Z:
        return None
    z, k = drift
    lo, hi = bands.mass_band
    first = min(p.frequency for p in problem.peaks)
    covered = "; the ± include the drift" if problem.options.uncertainty else ""
    return (f"{_unmodelled_leakage(problem)}: the estimate drifts across the mass line "
            f"{lo:.1f}-{hi:.1f} Hz by {z:.1f} standard deviations ({_THETA_NAMES[k]}), more "
            f"than its noise explains{covered}. A mass line further under the elastic mode "
            f"at {first:.1f} Hz, or less FRF noise (more averages), reduces it")


# --- stage 2: weights ------------------------------------------------------------------------


@dataclass(frozen=True)
class LineWeights:
    """The lines of each band that enter the fit, and the weight of each column on them.

    ``mass_lines`` / ``stiffness_lines`` (n_f,) select the lines; ``mass`` /
    ``stiffness`` (n_exc, n_lines) weigh each excitation column on them (0 drops it).
    The coherence figures (FRF values under the threshold, weighted down, and the
    ranges of lines holding any) cover the lines of both bands.
    """

    mass_lines: NDArray[np.bool_]
    stiffness_lines: NDArray[np.bool_]
    mass: NDArray[np.float64]
    stiffness: NDArray[np.float64]
    coherence_low: int
    coherence_values: int
    coherence_min: float
    coherence_ranges_hz: tuple[tuple[float, float], ...]


def weigh_lines(problem: Problem, bands: Bands) -> LineWeights:
    """Section 3: band lines with a usable T and a reconstruction error under ``level`` x the
    band's mean; each excitation column weighed by its coherence (:class:`Problem`)."""
    opt, coh, colw = problem.options, problem.coherence, problem.col_weights
    mass_sel = select_lines(problem.rel_err, bands.in_mass & problem.line_ok, problem.solver.level)
    stiff_sel = bands.in_stiffness & problem.line_ok
    mb, sb = bands.mass_band, bands.stiffness_band
    if np.count_nonzero(mass_sel) < 2:
        raise InputError(
            f"fewer than 2 usable lines in the mass-line band {mb[0]:g}-{mb[1]:g} Hz "
            "(rank or condition of T): widen the band or re-measure"
        )
    if np.count_nonzero(stiff_sel) < 2:
        raise InputError(
            f"fewer than 2 usable lines in the stiffness band {sb[0]:g}-{sb[1]:g}"
            " Hz: widen the band or re-measure"
        )
    in_any = bands.in_mass | bands.in_stiffness
    low = 0 if coh is None else int(np.count_nonzero(coh[..., in_any] < opt.coherence_threshold))
    return LineWeights(
        mass_lines=mass_sel, stiffness_lines=stiff_sel,
        mass=colw[:, mass_sel], stiffness=colw[:, stiff_sel],
        coherence_low=low,
        coherence_values=0 if coh is None else int(coh[..., in_any].size),
        coherence_min=float(np.min(coh[..., bands.in_mass])) if coh is not None else 1.0,
        coherence_ranges_hz=() if coh is None else coherence_gate(  # lines outside pass
            np.where(in_any, coh, 1.0), problem.freq, opt.coherence_threshold).ranges,
    )


# --- stage 3: fit ----------------------------------------------------------------------------


def _zeros66() -> NDArray[np.float64]:
    return np.zeros((6, 6))


@dataclass(frozen=True)
class Fit:
    """The ten inertia parameters and K, C (and D) at O, and how they were reached.

    ``normal`` is the 10x10 normal matrix of the last mass-line solve;
    ``operators`` the per-line operators of eq. 14 on the stiffness band;
    ``D`` the structural damping of ``K* = K + j w C + j D`` (zero for the viscous model).
    """

    theta: NDArray[np.float64]
    K: NDArray[np.float64]
    C: NDArray[np.float64]
    iterations: int
    converged: bool
    normal: NDArray[np.float64]
    physical_enforced: bool
    operators: LineOperators
    #: how the mass-line model was chosen, in words
    model_note: str = ""
    #: structural (hysteretic) damping at O, N/m, ... (zero for the viscous model)
    D: NDArray[np.float64] = dataclasses.field(default_factory=_zeros66)
    #: the damping model of K* ("viscous", "hysteretic" or "both")
    damping_model: DampingModel = "viscous"
    #: how the damping model was chosen, in words
    damping_note: str = ""
    #: the final mass-line problem and its right-hand side (for the fit's covariance)
    mass_line: MassLineProblem | None = field(default=None, repr=False, compare=False)
    mass_rhs: NDArray[np.complex128] | None = field(default=None, repr=False, compare=False)
    #: the stiffness step, M -> (K, C), on the final stiffness lines (affine in M)
    stiffness_map: StiffnessMap | None = field(default=None, repr=False, compare=False)
    #: theta of the same model fitted to the lower and the upper half of the mass lines
    half_thetas: tuple[NDArray[np.float64], NDArray[np.float64]] | None = field(
        default=None, repr=False, compare=False)
    #: the mounts' stiffening with frequency carried into the mass line (K and D then hold
    #: at its reference frequency), None for a constant K
    stiffening: Stiffening | None = None
    #: how the stiffness's frequency dependence was chosen, in words
    stiffening_note: str = ""


class StiffnessStep:
    """K, C, D for a mass matrix on the stiffness lines, by the rule the problem calls for:

    with an exponential window, eq. 14 per line with the window's pole shift undone,
    C by least squares (Im P = w C; viscous only: the shift ``K*(j w + a)`` holds for
    damping analytic in s); improved, a direct (symmetric) fit from moments of the terms
    ``model`` names; plain, the article's eq. 14 averaged over lines (viscous only).
    """

    def __init__(self, problem: Problem, weights: LineWeights, operators: LineOperators,
                 stiff_in_band: NDArray[np.bool_]) -> None:
        self.problem = problem
        self.w = problem.w[weights.stiffness_lines]
        #: the stiffness lines' X (not cleaned of leakage): one array, so that the fits that
        #: share this step share its moments too
        self.lines = problem.X[..., weights.stiffness_lines]
        self.weights = weights.stiffness
        self.mean = operators.mean_kc(stiff_in_band)
        self._sel = weights.stiffness_lines
        self._moments: StiffnessMoments | None = None
        self._key: tuple[object, object] | None = None
        #: the lines cleaned last (:meth:`cleaned`): that array, its leakage amplitudes and
        #: shapes on the stiffness lines; and the leakage moments of the last shapes and
        #: stiffening
        self._cleaned: tuple[object, NDArray[np.complex128], NDArray[np.complex128]] | None = None
        self._leakage: tuple[bytes, object, LeakageMoments] | None = None
        self.model: DampingModel = "viscous"
        #: the mounts' stiffening (None: K constant), in the fit of K and in the mass line
        self.stiffening: Stiffening | None = None

    def factor(self, w: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """``K(w) / K`` at w (rad/s); None for a constant K."""
        return stiffening_factor(self.stiffening, w)

    def cleaned(self, amplitudes: NDArray[np.complex128], shapes: NDArray[np.complex128],
                ) -> NDArray[np.complex128]:
        """The stiffness lines cleaned of the leakage ``amplitudes`` (6, n_exc, n_s) on
        ``shapes`` (n_s, all lines). Their moments, when asked for, follow from the lines'
        own and the amplitudes (:class:`processing.stiffness.LeakageMoments`), not from a
        new sum over the lines."""
        on_lines = shapes[:, self._sel]
        Xcs = self.lines - np.einsum("iks,sl->ikl", amplitudes, on_lines)
        self._cleaned = (Xcs, amplitudes, on_lines)
        return Xcs

    def moments(self, Xs: NDArray[np.complex128]) -> StiffnessMoments:
        """The stiffness moments of Xs (with the step's stiffening), kept while the same
        array and stiffening are passed."""
        if (self._key is None or self._key[0] is not Xs or self._key[1] is not self.stiffening
                or self._moments is None):
            p = self.problem
            if self._cleaned is not None and self._cleaned[0] is Xs:
                amplitudes, shapes = self._cleaned[1:]
                key = shapes.tobytes()
                if (self._leakage is None or self._leakage[0] != key
                        or self._leakage[1] is not self.stiffening):
                    self._leakage = (key, self.stiffening, LeakageMoments.of(
                        self.lines, p.T, self.w, shapes, self.weights, self.factor(self.w)))
                self._moments = self._leakage[2].at(amplitudes)
            else:
                self._moments = stiffness_moments(Xs, p.T, self.w, self.weights,
                                                  self.factor(self.w))
            self._key = (Xs, self.stiffening)
        return self._moments

    def __call__(self, M: NDArray[np.float64], Xs: NDArray[np.complex128]) -> (
        tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
    ):
        """K, C, D (6, 6) for mass matrix M on the (leakage-cleaned) stiffness lines Xs."""
        p, w = self.problem, self.w
        a = p.window_decay
        if a and p.improved:  # moments reused while the same Xs is passed
            sf = fit_stiffness(self.moments(Xs), p.T, w, M, row_scale=p.row_scale,
                               symmetric=p.solver.symmetric, decay=a)
            return sf.K, sf.C, sf.D
        if a:
            s = 1j * w + a
            P = -(s**2 / w**2)[:, None, None] * dynamic_stiffness(Xs, p.T, w, M)
            C = np.tensordot(w, P.imag, axes=1) / np.sum(w**2)  # least squares, Im P = w C
            K = np.mean(P.real, axis=0) - a * C
            D = np.zeros((6, 6))
            return (0.5 * (K + K.T), 0.5 * (C + C.T), D) if p.solver.symmetric else (K, C, D)
        if p.improved:  # moments reused while the same Xs is passed
            sf = fit_stiffness(self.moments(Xs), p.T, w, M, row_scale=p.row_scale,
                               symmetric=p.solver.symmetric, model=self.model)
            return sf.K, sf.C, sf.D
        return (*self.mean(M), np.zeros((6, 6)))

    def choose(self, M: NDArray[np.float64], Xs: NDArray[np.complex128]) -> tuple[
        DampingModel, str
    ]:
        """The damping model the stiffness lines Xs call for at mass matrix M (BIC, see
        :func:`processing.stiffness.choose_damping`); viscous with an exponential window."""
        p, w = self.problem, self.w
        if p.window_decay:
            return "viscous", ("damping viscous (K + jwC): kept with an exponential window "
                               f"(tau = {p.exponential_tau:g} s; the damping it added was "
                               "removed from C, by K*(jw + a), which holds for damping "
                               "analytic in s)")
        ch = choose_damping(Xs, p.T, w, M, weights=self.weights, row_scale=p.row_scale,
                            symmetric=p.solver.symmetric, moments=self.moments(Xs),
                            stiffening=self.factor(w))
        return ch.model, ch.reason

    def choose_stiffening(self, M: NDArray[np.float64], K: NDArray[np.float64],
                          Xs: NDArray[np.complex128], most: float = np.inf,
                          ) -> tuple[Stiffening | None, str]:
        """The mounts' stiffening the stiffness lines Xs call for at mass matrix M (K the
        step's stiffness there), with the step's damping model (BIC, see
        :func:`processing.stiffness.choose_stiffening`), read on the lines up to
        :data:`STIFFENING_TOP` times the highest rigid-body mode of M and K: above the modes
        a line's K* is mostly ``w^2`` times what the mass matrix misses (its error, the
        elastic modes' residual), whose rise with frequency would read as a stiffening; and
        on none above ``most`` (rad/s)."""
        p = self.problem
        try:
            top = STIFFENING_TOP * float(np.sqrt(max(float(
                scipy.linalg.eigh(0.5 * (K + K.T), M, eigvals_only=True)[-1]), 0.0)))
        except (np.linalg.LinAlgError, ValueError):
            return None, "stiffness constant over frequency: the fit has no rigid-body modes"
        sel = self.w <= min(top, most)
        ch = choose_stiffening(Xs[..., sel], p.T, self.w[sel], M, weights=self.weights[:, sel],
                               row_scale=p.row_scale, symmetric=p.solver.symmetric,
                               model=self.model)
        return ch.stiffening, ch.reason


def upper_residual(w: NDArray[np.float64]) -> NDArray[np.complex128]:
    """Frequency shape (all lines) of the upper residual, the modes above the band:
    ``(w / w_top)^2``."""
    return np.asarray((w / w[-1]) ** 2 + 0j, dtype=np.complex128)


def leakage_shapes(problem: Problem, bands: Bands) -> list[NDArray[np.complex128]]:
    """Frequency shapes (all lines) of the modelled leakage: each elastic mode, then w^2."""
    if not bands.leakage:
        return []
    w = problem.w
    return [*(mode_shape_basis(w, p) for p in problem.peaks), upper_residual(w)]


def iterate(problem: Problem, weights: LineWeights, ml: MassLineProblem,
             step: StiffnessStep, shapes: list[NDArray[np.complex128]],
             start: tuple[NDArray[np.float64], NDArray[np.complex128]] | None = None,
             ) -> tuple[
    MassLineFit, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
    NDArray[np.float64], NDArray[np.complex128], int, bool,
]:
    """Section 2.2: inertia from the mass line with the stiffness term, K, C and D from the
    stiffness band, until theta converges (from zero, or from ``start`` = theta and the
    cleaned stiffness-line X it was reached with: K, C, D then start from the stiffness
    step there). Returns the last fit, theta, K, C, D, the cleaned stiffness-line X, the
    iterations and whether theta converged."""
    T, a = problem.T, problem.window_decay
    msel = weights.mass_lines
    Xm, wm = problem.X[..., msel], problem.w[msel]
    Xs = step.lines
    s_m = 1j * wm + a
    g = step.factor(wm)
    Xcm, Xcs = Xm, Xs
    K, C, D, theta = np.zeros((6, 6)), np.zeros((6, 6)), np.zeros((6, 6)), np.zeros(10)
    S = np.array(shapes)[ml.shape_index] if shapes else np.zeros((0, problem.w.size), complex)
    if start is not None:
        theta = start[0]
        K, C, D = step(mass_matrix(theta), start[1])
    fit_ = None
    for it in range(1, problem.solver.max_iter + 1):
        if a:  # B = T + K*_m X / w^2 with the windowed K*_m
            Xf = Xcm.reshape(6, -1)
            KX = ((K + a * C) @ Xf).reshape(Xm.shape) + 1j * wm * (C @ Xf).reshape(Xm.shape)
            fit_ = ml.solve(T[:, :, None] - KX / s_m**2 + 0j)
        else:
            fit_ = ml.solve_kc(T, K, C, Xcm, wm, D if step.model != "viscous" else None, g)
        new = fit_.theta
        M = mass_matrix(new)
        if fit_.leakage is not None:  # B - M X = -M Y b: clean X of the fitted leakage
            Yk = -np.einsum("ia,aks->iks", np.linalg.pinv(M), fit_.leakage)
            Xcm = Xm - np.einsum("iks,sl->ikl", Yk, S[:, msel])
            Xcs = step.cleaned(Yk, S)
        K, C, D = step(M, Xcs)
        change = np.max(np.abs(new - theta) / np.maximum(np.abs(new), 1e-12 * abs(new[0])))
        theta = new
        if change < problem.solver.tol:
            return fit_, theta, K, C, D, Xcs, it, True
    assert fit_ is not None
    return fit_, theta, K, C, D, Xcs, problem.solver.max_iter, False


def _mass_line_rhs(problem: Problem, Xm: NDArray[np.complex128], wm: NDArray[np.float64],
                   K: NDArray[np.float64], C: NDArray[np.float64],
                   D: NDArray[np.float64] | None = None,
                   stiffening: NDArray[np.float64] | None = None) -> NDArray[np.complex128]:
    """``B = T + K* X / w^2`` on the mass lines (K* = K + j w C + j D as the exponential
    window shows it; K and D times the mounts' stiffening on these lines when given)."""
    a = problem.window_decay
    s2 = (1j * wm + a) ** 2
    KD = K + (0 if D is None else 1j * D)
    KX = (np.einsum("ab,bel->ael", KD, Xm) * (1.0 if stiffening is None else stiffening)
          + a * np.einsum("ab,bel->ael", C, Xm) + 1j * wm * np.einsum("ab,bel->ael", C, Xm))
    return problem.T[:, :, None] - KX / s2 + 0j


@dataclass(frozen=True)
class _Candidate:
    """One mass-line model fitted to the end of the iteration."""

    ml: MassLineProblem
    fit: MassLineFit
    theta: NDArray[np.float64]
    K: NDArray[np.float64]
    C: NDArray[np.float64]
    Xs: NDArray[np.complex128]
    iterations: int
    converged: bool
    D: NDArray[np.float64] = dataclasses.field(default_factory=_zeros66)


def _fit_model(problem: Problem, weights: LineWeights, step: StiffnessStep,
               shapes: list[NDArray[np.complex128]],
               start: _Candidate | None = None) -> _Candidate:
    """The mass-line model with the given leakage shapes, fitted (plain method without a
    window: the article's fixed point, solved directly); the iteration starts from
    ``start``'s estimates when given."""
    msel = weights.mass_lines
    ml = MassLineProblem(problem.X[..., msel], weights=weights.mass, row_scale=problem.row_scale,
                         shapes=np.array([stack_real(s[msel]) for s in shapes]) if shapes
                         else None)
    if not problem.improved and not problem.window_decay:
        # the article's iteration is affine in theta here: its limit is solved directly
        mean = step.mean
        fit_ = ml.fixed_point_affine(problem.T, mean.w2, mean.KB, mean.C, problem.w[msel])
        Xs = step.lines
        K, C, D = step(mass_matrix(fit_.theta), Xs)
        return _Candidate(ml, fit_, fit_.theta, K, C, Xs, 1, True, D)
    init = None if start is None else (start.theta, start.Xs)
    fit_, theta, K, C, D, Xs, it, converged = iterate(problem, weights, ml, step, shapes, init)
    return _Candidate(ml, fit_, theta, K, C, Xs, it, converged, D)


def _halves(weights: LineWeights) -> tuple[LineWeights, LineWeights]:
    """The mass lines split into their lower and upper halves."""
    idx = np.flatnonzero(weights.mass_lines)
    n = idx.size // 2
    parts = []
    for sl in (slice(0, n), slice(n, None)):
        lines = np.zeros_like(weights.mass_lines)
        lines[idx[sl]] = True
        parts.append(dataclasses.replace(weights, mass_lines=lines, mass=weights.mass[:, sl]))
    return parts[0], parts[1]


def _spread(problem: Problem, weights: LineWeights, step: StiffnessStep,
            shapes: list[NDArray[np.complex128]]) -> float:
    """How far the estimates from the two halves of the mass line disagree: the largest
    difference of mass, first moments / L and inertia / L^2, relative to the mass."""
    L = problem.geometry.length
    scale = np.array([1.0, *(3 * [1 / L]), *(6 * [1 / L**2])])
    lo, hi = (_fit_model(problem, w, step, shapes).theta for w in _halves(weights))
    return float(np.max(np.abs(hi - lo) * scale) / max(abs(lo[0] + hi[0]) / 2, 1e-300))


def _upper_residual_chosen(problem: Problem, weights: LineWeights,
                           step: StiffnessStep) -> tuple[bool, str]:
    """Whether the upper residual (a ``w^2`` term per equation entry, for modes above the
    band) is modelled: when the estimate from the two halves of the mass line agrees
    better with it than without it (unmodelled residual makes the estimate drift with
    the band; a residual fitted to noise makes it scatter)."""
    if np.count_nonzero(weights.mass_lines) < 8:
        return False, "upper residual not modelled: fewer than 8 mass lines"
    without = _spread(problem, weights, step, [])
    with_ = _spread(problem, weights, step, [upper_residual(problem.w)])
    use = with_ < without
    return use, (f"upper residual (w^2 term) {'modelled' if use else 'not modelled'}: "
                 f"half-band disagreement {with_:.2%} with it, {without:.2%} without")


#: candidate tops of the automatic mass line tried by :func:`settle_mass_band`
BAND_CANDIDATES = 6
#: a wider candidate is preferred while its disagreement is within this factor of the least
BAND_TOLERANCE = 1.5
#: convergence of the candidates' fits (relative change of theta) and their iterations
SCORE_TOL, SCORE_ITER = 1e-4, 6


def stiffness_operators(problem: Problem, bands: Bands) -> LineOperators:
    """The per-line operators of eq. 14 on the stiffness band (:func:`processing.stiffness.
    line_operators`), built once for :func:`settle_mass_band` and :func:`solve` (the
    settling changes the mass line only)."""
    ins = bands.in_stiffness
    return line_operators(problem.X[..., ins], problem.T, problem.w[ins])


def settle_mass_band(problem: Problem, bands: Bands, weights: LineWeights,
                     operators: LineOperators | None = None) -> tuple[Bands, LineWeights]:
    """The automatic mass line's top chosen by the stability of the estimate.

    An elastic mode the residual does not show (its shape looks rigid at the sensors, or it
    sits at the edge of the data) still bends the mass line: the estimate then drifts with
    the band. The chosen band's top and ``BAND_CANDIDATES - 1`` lower tops (geometric, down
    to the band's 16th line) are each fitted on the two halves of their
    lines; the widest whose halves disagree at most ``BAND_TOLERANCE`` times the least
    disagreement is kept, and the reason says so. Bands given in the options, the plain
    method and mass lines under 32 lines are left as they are. ``operators``: the
    stiffness band's :func:`stiffness_operators` (built here when not given).

    Without modelled elastic leakage, the model the candidates are fitted with (an upper
    ``w^2`` residual or none) is one for all of them: the one whose half-band disagreement
    has the smaller geometric mean over the candidates. A residual left out biases both
    halves of a narrow band alike (it hardly changes over a few lines), so a candidate free
    to drop it would look most stable at the narrowest band; chosen on the whole band
    alone, the model would follow whatever spoils that band's top (a hammer's force falls
    to a spectral zero near the end of the data). The measurements behind this rule:
    ``benchmarks/results/accuracy-mass-line-model.md``.
    """
    if problem.options.mass_band is not None or not problem.improved:
        return bands, weights
    freq, idx = problem.freq, np.flatnonzero(weights.mass_lines)
    if idx.size < 32:
        return bands, weights
    lo, hi = bands.mass_band
    least = float(freq[idx[15]])
    if least >= hi:
        return bands, weights
    tops = np.geomspace(hi, least, BAND_CANDIDATES)
    ins = bands.in_stiffness
    # the candidates are compared, not reported: a loose convergence suffices
    rough = dataclasses.replace(problem, solver=dataclasses.replace(
        problem.solver, tol=SCORE_TOL, max_iter=SCORE_ITER))
    ops = operators if operators is not None else stiffness_operators(problem, bands)
    step = StiffnessStep(rough, weights, ops, weights.stiffness_lines[ins])
    shapes = leakage_shapes(problem, bands)
    models = [shapes] if shapes else [[], [upper_residual(problem.w)]]
    cands = []
    for top in tops:
        keep = freq[idx] <= top * (1 + 1e-9)
        lines = np.zeros_like(weights.mass_lines)
        lines[idx[keep]] = True
        cands.append((float(top), dataclasses.replace(weights, mass_lines=lines,
                                                      mass=weights.mass[:, keep])))
    spreads = np.array([[_spread(rough, trial, step, m) for _, trial in cands] for m in models])
    # one model for every candidate: the one whose halves agree better over the candidates
    # (geometric mean), not on one band, whose own edge (an elastic mode, the force's
    # spectral zero) may sway the choice
    scores = spreads[np.argmin(np.mean(np.log(np.maximum(spreads, 1e-300)), axis=1))]
    trials = [(top, trial, float(sc)) for (top, trial), sc in zip(cands, scores, strict=True)]
    best = min(score for *_, score in trials)
    top, chosen, score = next(t for t in trials if t[2] <= BAND_TOLERANCE * best)
    if top >= hi * (1 - 1e-9):
        return bands, weights
    reason = (f"{bands.reason}; mass line ended at {top:.1f} Hz, where the estimate is "
              f"stable (half-band disagreement {score:.2%}, {trials[0][2]:.2%} to "
              f"{hi:.1f} Hz)")
    in_mass = bands.in_mass & (freq <= top * (1 + 1e-9))
    return dataclasses.replace(bands, mass_band=(lo, top), in_mass=in_mass,
                               reason=reason), chosen


def solve(problem: Problem, bands: Bands, weights: LineWeights,
          operators: LineOperators | None = None) -> Fit:
    """Inertia, K and C (and D): the article's fixed point solved directly (plain, no
    window), else the iteration of section 2.2; then projected onto consistent inertia if
    asked.

    Improved method without modelled elastic leakage: the fit with an upper residual (a
    ``w^2`` term for modes above the band) is kept when the data call for it (by how the
    two halves of the mass line agree). Improved method: at the converged mass matrix the
    damping model of ``K*`` (viscous C, structural D or both) is chosen by BIC over the
    stiffness lines; when it is not the viscous one the iteration is resumed with it.
    ``operators``: the stiffness band's :func:`stiffness_operators` (built here when not
    given).
    """
    opt = problem.options
    ssel = weights.stiffness_lines
    ins = bands.in_stiffness
    ops = operators if operators is not None else stiffness_operators(problem, bands)
    step = StiffnessStep(problem, weights, ops, ssel[ins])
    shapes = leakage_shapes(problem, bands)
    best = _fit_model(problem, weights, step, shapes)
    note = ""
    if problem.improved and not shapes and problem.solver.leakage == "auto":
        use, note = _upper_residual_chosen(problem, weights, step)
        if use:
            shapes = [upper_residual(problem.w)]
            best = _fit_model(problem, weights, step, shapes)
    damping_note = "damping viscous (K + jwC): the article's model (plain method)"
    if problem.improved and opt.damping == "viscous":
        damping_note = "damping viscous (K + jwC): asked for"
    elif problem.improved:
        # chosen at the converged M; a fit with another model moves M, so the choice is
        # made again there until it stands (at most three models to try)
        tried: set[str] = {"viscous"}
        for _ in range(len(DAMPING_MODELS)):
            model, damping_note = step.choose(mass_matrix(best.theta), best.Xs)
            if model == step.model:
                break
            step.model = model
            done = best.iterations
            best = _fit_model(problem, weights, step, shapes, start=best)
            best = dataclasses.replace(best, iterations=done + best.iterations)
            if model in tried:
                break
            tried.add(model)
    stiffening_note = "stiffness constant over frequency: the article's model (plain method)"
    if problem.improved and problem.window_decay:
        stiffening_note = ("stiffness constant over frequency: kept with an exponential "
                           "window (its correction holds for a constant K)")
    elif problem.improved and opt.stiffening != "auto":
        stiffening_note = "stiffness constant over frequency: asked for"
    elif problem.improved:
        best, stiffening_note = _stiffening(problem, bands, weights, step, shapes, best)
    theta, K, C, D, Xs = best.theta, best.K, best.C, best.D, best.Xs
    halves = None
    if ((opt.uncertainty or _leakage_unmodelled(problem, bands))
            and np.count_nonzero(weights.mass_lines) >= 8):
        lo, hi = (_fit_model(problem, w, step, shapes).theta for w in _halves(weights))
        halves = (lo, hi)
    enforced = False
    if opt.physical:
        theta_c = constrain_physical(theta, best.fit.normal)
        enforced = not np.array_equal(theta_c, theta)
        if enforced:
            theta = theta_c
            K, C, D = step(mass_matrix(theta), Xs)
    msel = weights.mass_lines
    rhs = _mass_line_rhs(problem, problem.X[..., msel], problem.w[msel], K, C, D,
                         step.factor(problem.w[msel]))

    def stiffness_map(M: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        K_, C_, _D = step(M, Xs)
        return K_, C_

    return Fit(theta, K, C, best.iterations, best.converged, best.fit.normal, enforced, ops,
               note, D, step.model, damping_note, mass_line=best.ml, mass_rhs=rhs,
               stiffness_map=stiffness_map, half_thetas=halves, stiffening=step.stiffening,
               stiffening_note=stiffening_note)


#: the stiffening is read on the stiffness lines up to this factor over the highest
#: rigid-body mode (:meth:`StiffnessStep.choose_stiffening`)
STIFFENING_TOP = 1.25
#: with elastic modes seen and their leakage not modelled, the stiffening is read on the
#: lines up to this fraction of the lowest one (its residual there: 1 % of the mass line's)
STIFFENING_ELASTIC = 0.1
#: rounds of reading the stiffening and fitting again with it (the mass matrix the fit
#: moves changes the stiffness lines' equations a little)
STIFFENING_ROUNDS = 3


def _stiffening(problem: Problem, bands: Bands, weights: LineWeights, step: StiffnessStep,
                shapes: list[NDArray[np.complex128]], best: _Candidate) -> tuple[
    _Candidate, str
]:
    """The fit with the mounts' stiffening, read from the stiffness lines at the fitted mass
    matrix, in the stiffness fit and the mass line, when the lines call for it
    (:meth:`StiffnessStep.choose_stiffening`); else ``best`` as it is. Read again at each
    new fit's mass matrix, at most :data:`STIFFENING_ROUNDS` times; ``step`` keeps the
    stiffening taken (the last one found, once one is)."""
    note = ""
    # elastic modes seen but their leakage not modelled: their residual rises on the
    # stiffness lines as (f / f_e)^2; only the lines where it is under 1 % are read
    f_e = min((pk.frequency for pk in problem.peaks), default=np.inf)
    most = 2 * np.pi * STIFFENING_ELASTIC * f_e if _leakage_unmodelled(problem, bands) else np.inf
    for _ in range(STIFFENING_ROUNDS):
        found, why = step.choose_stiffening(mass_matrix(best.theta), best.K, best.Xs, most)
        if found is None:
            return best, note or why
        before = step.stiffening
        step.stiffening = found
        done = best.iterations
        best = _fit_model(problem, weights, step, shapes, start=best)
        best = dataclasses.replace(best, iterations=done + best.iterations)
        note = why
        if before is not None and abs(found.alpha - before.alpha) < 1e-3:
            break
    return best, note


# --- stage 4: checks -------------------------------------------------------------------------


#: the identified mass may differ from the mass line's own reading by at most this factor
MASS_READING_FACTOR = 3.0


def mass_line_reading(problem: Problem, weights: LineWeights) -> float:
    """The mass the mass line reads by itself, kg: the median over its lines of the mean
    translational diagonal of the apparent mass ``Re(T X^+)`` (``M - K / w^2`` there)."""
    sel = weights.mass_lines
    B = line_operators(problem.X[..., sel], problem.T, problem.w[sel]).B
    return float(np.median(np.trace(B.real[:, :3, :3], axis1=1, axis2=2) / 3))


def implausible_mass(problem: Problem, bands: Bands, weights: LineWeights,
                     fitted: Fit) -> str:
    """Why the fitted mass cannot be an answer (not finite, not positive, or more than
    :data:`MASS_READING_FACTOR` times off the mass line's own reading,
    :func:`mass_line_reading`, as when the fit diverges on a mass line under the rigid-body
    modes), in words; empty when it can."""
    mass = float(fitted.theta[0])
    lo, hi = bands.mass_band
    where = f"mass line {lo:.1f}-{hi:.1f} Hz"
    if not np.isfinite(mass) or mass <= 0:
        return f"the fit gave {mass:.3g} kg on the {where}"
    reading = mass_line_reading(problem, weights)
    if not reading > 0 or not (1 / MASS_READING_FACTOR <= mass / reading
                               <= MASS_READING_FACTOR):
        return f"the fit gave {mass:.3g} kg where the {where} reads {reading:.3g} kg"
    return ""


def refuse_implausible_mass(problem: Problem, bands: Bands, weights: LineWeights,
                            fitted: Fit) -> None:
    """Raise :class:`InputError` when the fitted mass cannot be an answer
    (:func:`implausible_mass`)."""
    if why := implausible_mass(problem, bands, weights, fitted):
        raise InputError(f"no usable mass: {why}; give the bands (--mass-band, "
                         "--stiffness-band) or check the data")


@dataclass(frozen=True)
class Checks:
    """What the fitted model says about itself: properties, rigid-body modes (Hz), the fit of
    its synthesised FRFs, K* per stiffness-band line, and warnings."""

    properties: InertiaProperties
    rigid_modes_hz: NDArray[np.float64]
    synthesis: SynthesisFit
    stiffness_per_line: NDArray[np.complex128]
    warnings: tuple[str, ...]


def check(problem: Problem, bands: Bands, weights: LineWeights, fitted: Fit) -> Checks:
    """Physical consistency, rigid-body modes, synthesis error over the data up to the top
    of the mass line, and K* per line (window corrected)."""
    tau, freq = problem.exponential_tau, problem.freq
    M, K = mass_matrix(fitted.theta), fitted.K
    warnings: list[str] = []
    leak = leakage_warning(problem, bands, fitted)
    if leak:
        warnings.append(leak)
    props = inertia_properties(fitted.theta)
    if not props.physically_consistent:
        warnings.append(
            "identified inertia is not physically consistent "
            f"(triangle margin {props.triangle_margin:+.3f}): use --physical or check the data"
        )
    try:
        w2 = scipy.linalg.eigh(0.5 * (K + K.T), M, eigvals_only=True)
        rigid_hz = np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi)
    except (np.linalg.LinAlgError, ValueError):
        used = weights.stiffness_lines | weights.mass_lines
        rigid_hz = quick_rigid_modes(problem.X[..., used], problem.T, problem.w[used])
    # the measured FRFs as the exponential window left them: the model at s = j w + a
    H_syn = synthesise(freq, problem.E, problem.T, M, K, fitted.C, fitted.D,
                       stiffening_factor(fitted.stiffening, 2 * np.pi * freq),
                       decay=problem.window_decay)
    syn = synthesis_error(freq, problem.H, H_syn, (float(freq[0]), bands.mass_band[1]))
    Ks_line = fitted.operators.stiffness(M)
    if tau:
        Ks_line = np.moveaxis(correct_dynamic_stiffness(
            np.moveaxis(Ks_line, 0, -1), freq[bands.in_stiffness], tau), -1, 0)
    return Checks(props, rigid_hz, syn, Ks_line, tuple(warnings))


# --- stage 5: uncertainty --------------------------------------------------------------------


_COV_SOURCE = ("fit covariance: mass-line residual (block-robust over lines, band drift), "
               "stiffness-line scatter, force-noise bias (coherence) and body flexibility, "
               "propagated to first order")


def monte_carlo_model(problem: Problem, weights: LineWeights, fitted: Fit,
                      node_ids: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
                      ) -> MonteCarloModel:
    """The :class:`~processing.montecarlo.MonteCarloModel` of a fit (improved method), for
    :func:`processing.montecarlo.simulate`.

    With an exponential window the fast re-solve leaves the window's decay out: a draw's
    change is that of the same fit without it, which differs from the windowed fit's change
    by terms of order ``1 / (tau w)`` on the mass line (tested against full re-fits).

    Raises
    ------
    InputError
        For the plain method (the fast re-solve does not cover it).
    """
    if not problem.improved or fitted.mass_line is None:
        raise InputError("the Monte Carlo of stated test uncertainties needs the improved "
                         "method: drop --method plain or the uncertainty options")
    msel, ssel = weights.mass_lines, weights.stiffness_lines
    return build_model(fitted.mass_line, problem.H[..., msel], problem.w[msel],
                       problem.H[..., ssel], problem.w[ssel], weights.stiffness,
                       problem.resp_xyz, problem.E[:, :3], problem.exc_xyz, problem.T[:3].T,
                       problem.row_scale,
                       problem.solver.symmetric, fitted.theta, fitted.K, fitted.C,
                       *(node_ids if node_ids is not None else (None, None)))


# --- stage 6: results ------------------------------------------------------------------------


def assemble(problem: Problem, bands: Bands, weights: LineWeights, fitted: Fit,
             checks: Checks, uncertain: Uncertainty | None = None) -> IdentificationResult:
    """The :class:`IdentificationResult` of the stages."""
    opt, freq = problem.options, problem.freq
    return IdentificationResult(
        method=opt.method,
        theta=fitted.theta,
        M=mass_matrix(fitted.theta),
        K=fitted.K,
        C=fitted.C,
        properties=checks.properties,
        mass_band=bands.mass_band,
        stiffness_band=bands.stiffness_band,
        mass_lines=freq[weights.mass_lines],
        stiffness_lines=freq[weights.stiffness_lines],
        iterations=fitted.iterations,
        converged=fitted.converged,
        geometry=problem.geometry,
        elastic_modes=problem.peaks,
        rigid_modes_hz=checks.rigid_modes_hz,
        reconstruction_error=problem.rel_err[weights.mass_lines],
        synthesis=checks.synthesis,
        coherence_low=weights.coherence_low,
        coherence_values=weights.coherence_values,
        coherence_checked=problem.coherence is not None,
        coherence_min=weights.coherence_min,
        coherence_ranges_hz=weights.coherence_ranges_hz,
        coherence_threshold=opt.coherence_threshold,
        physical_enforced=fitted.physical_enforced,
        warnings=(*problem.warnings, *bands.warnings, *checks.warnings),
        stiffness_per_line=checks.stiffness_per_line,
        band_reason=bands.reason,
        model_note=fitted.model_note,
        D=fitted.D,
        damping_model=fitted.damping_model,
        damping_note=fitted.damping_note,
        uncertainty=uncertain,
        stiffening=fitted.stiffening,
        stiffening_note=fitted.stiffening_note,
    )



# --- the rigidity check's band ---------------------------------------------------------------


def rigid_band_tops(frf: FRFSet) -> tuple[float | None, float | None, list[str]]:
    """Top of the rigid band of the rigidity check (article section 5.1), Hz, when below the
    data's top; the same with the threshold raised to 3x the check's error floor (noise,
    location or sensor errors), used when the first leaves no mass line; and notes. When
    the lowest lines are above the threshold (accelerances, falling as the square of the
    frequency under the rigid-body modes, under the noise), the band starts at the first
    line under it when it holds at least three lines from there, at least as many as the
    noisy lines below it (a stretch after a few noisy lines, not a quiet moment in noise),
    and most lines from the lowest one to its top are within it (their error floor, the
    lower quartile, within the threshold: the lines above the band, where the body flexes,
    do not count); the raised threshold's band and error floor then start there too."""
    fmin = float(frf.freq[frf.freq > 0][0]) if np.any(frf.freq > 0) else 0.0
    try:
        rc = rigidity_check(frf, fmin=fmin)
    except GeometryError:
        return None, None, []  # under 3 response nodes: the elastic-mode detection bounds it
    heard = (rc.freq >= fmin) & (rc.worst <= rc.threshold)
    start = fmin  # the lowest line of the band (and of the raised one)
    if rc.band is None and np.any(heard):
        band = rc.band_at(rc.threshold, fmin=float(rc.freq[heard][0]))
        if band is not None:
            upto = (rc.freq >= fmin) & (rc.freq <= band[1])
            n_band = int(np.count_nonzero((rc.freq >= band[0]) & (rc.freq <= band[1])))
            n_noisy = int(np.count_nonzero((rc.freq >= fmin) & (rc.freq < band[0])))
            if (n_band >= max(3, n_noisy)  # a stretch, not a quiet moment in the noise
                    and np.percentile(rc.worst[upto], 25) <= rc.threshold):
                rc = dataclasses.replace(rc, band=band)
                start = band[0]
    top = float(frf.freq[-1])

    def below_top(band: tuple[float, float] | None) -> float | None:
        return band[1] if band is not None and band[1] < top else None

    raised = rc.band_at(3 * rc.error_floor(start), fmin=start)
    notes = [] if rc.band is not None else [
        "rigidity check: no rigid band found (check sensor mounting and coordinates)"]
    return below_top(rc.band), below_top(raised) if raised != rc.band else None, notes

