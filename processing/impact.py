"""Impact (hammer) tests: trigger, per-hit checks, windows and FRFs averaged over accepted hits.

One recording holds the force channel and the responses of one excitation point,
hit several times. Each trigger on the force (level, slope) opens one record of
``record_length`` samples starting ``pretrigger`` samples before the trigger;
a new trigger is armed only after the record ends. Every hit gets a verdict:

- *accepted*;
- *double hit*: after the force has fallen below half the double-hit level, it rises
  again above ``double_hit_ratio`` times the peak within the record;
- *overload* on a named channel: a peak at or above 99 % of its range (when the ranges are
  given), else a sample at its converter's last code (:func:`converter_tops`, read from
  the samples' code step) or the extreme level that other hits of the recording reach too
  (:func:`common_clip`: a digitiser's last code), or a clipped (flat-topped) waveform:
  ``clip_samples`` consecutive samples at the channel's peak;
- *incomplete*: the record runs past the end (or start) of the data.

Accepted hits are windowed (force window times exponential window on the force,
the exponential window on the responses, see :mod:`processing.windows`) and averaged
into H1 (or H2, Hv) with the coherence over hits. The exponential window's time
constant is reported so the damping it adds can be removed from identified
results (:func:`processing.windows.correct_dynamic_stiffness`).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.data import FRFSet, Geometry, InputError
from processing.decay import CARRY_MIN, CARRY_STRETCH, free_decay, noise_sigma
from processing.measurement import Measurement, Provenance
from processing.spectral import CrossSpectra, combine, frf, record_spectra
from processing.units import TimeUnits, UnitSpectra, record_units
from processing.windows import exponential_window, force_window

__all__ = [
    "CLIP_MIN_CODES",
    "ExcitationGuess",
    "HitVerdict",
    "ImpactDefaults",
    "ImpactResult",
    "ImpactSettings",
    "common_clip",
    "converter_tops",
    "excitation_type",
    "exponential_for",
    "find_triggers",
    "force_band_top",
    "impact_defaults",
    "impact_measurement",
    "merge_results",
    "pretrigger_for",
    "process_impacts",
    "wanted_record",
]

log = logging.getLogger(__name__)

#: the usable band ends where the averaged force auto-spectrum falls under this fraction
#: of its peak (20 dB: the usual limit of a hammer tip's band)
FORCE_DROP = 0.01


@dataclass(frozen=True)
class ImpactSettings:
    """How hits are found, checked and windowed.

    Attributes
    ----------
    level : float
        Trigger level on the force channel, force unit (N); crossed with ``slope``.
    record_length : int
        Samples per hit record (line spacing ``fs / record_length`` Hz).
    pretrigger : int
        Samples kept before the trigger.
    slope : {'rising', 'falling'}
        A hammer pushing along the excitation direction gives a rising force.
    exp_tau : float or None
        Exponential window time constant, s (None: no exponential window).
    force_window : float or None
        Force window length after the trigger, s; None sizes it from each pulse
        (pulse end plus the larger of one pulse width and ``ring``, then a half-cosine
        as long).
    ring : int
        Samples after a pulse's end the automatic force window keeps at least (the
        acquisition's anti-alias filter rings after a short pulse; cutting that ringing
        biases the force spectrum, :attr:`ImpactDefaults.ring`).
    carryover : bool
        Take the earlier hits' ringing off each record: the responses' free decay on the
        stretch before the record (from :data:`SAME_HIT` after the previous trigger, at
        most :data:`CARRY_STRETCH` s) is fitted as a sum of damped sinusoids
        (:func:`processing.decay.free_decay`) and its continuation subtracted from the
        record's responses.
    complete : bool
        Put each record's own cut-off tail back: the responses' free decay after the
        pulse (from :data:`SAME_HIT` after its end to the record's end, at most
        :data:`CARRY_STRETCH` s) is continued past the record's end and folded onto it, so
        the record holds the periodic response to its hit and the rectangular window leaks
        nothing (the responses need not die out within the record). Not with ``exp_tau``.
    double_hit_ratio : float
        A second rise above this fraction of the peak force is a double hit.
    clip_samples : int
        Consecutive samples at a channel's peak that mean clipping.
    """

    level: float
    record_length: int
    pretrigger: int = 0
    slope: Literal["rising", "falling"] = "rising"
    exp_tau: float | None = None
    force_window: float | None = None
    double_hit_ratio: float = 0.1
    clip_samples: int = 3
    ring: int = 0
    carryover: bool = False
    complete: bool = False

    def __post_init__(self) -> None:
        if not np.isfinite(self.level) or self.level == 0:
            raise InputError(f"trigger level must be a non-zero force, got {self.level}")
        if self.record_length < 8:
            raise InputError(f"record_length must be >= 8 samples, got {self.record_length}")
        if not 0 <= self.pretrigger < self.record_length:
            raise InputError(
                f"pretrigger must be in [0, record_length), got {self.pretrigger}"
            )
        if self.slope not in ("rising", "falling"):
            raise InputError(f"slope must be 'rising' or 'falling', got {self.slope!r}")
        if self.exp_tau is not None and not self.exp_tau > 0:
            raise InputError(f"exp_tau must be positive (s) or None, got {self.exp_tau}")
        if self.force_window is not None and not self.force_window > 0:
            raise InputError(f"force_window must be positive (s) or None, got {self.force_window}")
        if not 0 < self.double_hit_ratio < 1:
            raise InputError(f"double_hit_ratio must be in (0, 1), got {self.double_hit_ratio}")
        if self.clip_samples < 2:
            raise InputError(f"clip_samples must be >= 2, got {self.clip_samples}")
        if self.ring < 0:
            raise InputError(f"ring must be >= 0 samples, got {self.ring}")
        if self.complete and self.exp_tau is not None:
            raise InputError("a record completed with its own tail takes no exponential "
                             "window: give one or the other")


@dataclass(frozen=True)
class HitVerdict:
    """One hit: trigger sample, record start, peak force (N), accepted or the reason why not."""

    index: int
    trigger: int
    start: int
    peak_force: float
    accepted: bool
    reason: str = ""


@dataclass(frozen=True)
class ImpactResult:
    """FRF column of one excitation point from its accepted hits.

    Attributes
    ----------
    freq : (n_f,) Hz
    H : (n_resp, 1, n_f) complex, response unit per force unit, or None if no hit was accepted
    coherence : (n_resp, 1, n_f) coherence over the accepted hits (1 for a single hit)
    verdicts : one per hit found
    spectra : averaged spectra of the accepted hits (to merge with other recordings)
    estimator : 'H1', 'H2' or 'Hv'
    exp_tau : exponential window time constant, s (None if none was applied)
    """

    freq: NDArray[np.float64]
    H: NDArray[np.complex128] | None
    coherence: NDArray[np.float64] | None
    verdicts: tuple[HitVerdict, ...]
    spectra: CrossSpectra | None
    estimator: str
    exp_tau: float | None
    meta: dict[str, object] = field(default_factory=dict, compare=False)
    #: the accepted hits' spectra, hit by hit (``keep_units``; for the bootstrap over hits)
    units: UnitSpectra | None = field(default=None, compare=False, repr=False)
    #: responses (indices into H's rows) left out of this point's FRFs: every hit of the
    #: point overloads them, so the hits are kept for the other responses and these get a
    #: coherence of 0 (weighed out of the fit)
    left_out: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if (self.H is None) != (self.coherence is None) or (self.H is None) != (
            self.spectra is None
        ):
            raise InputError("H, coherence and spectra must all be given or all be None")
        if self.H is not None and self.coherence is not None:
            if self.H.ndim != 3 or self.H.shape[1] != 1 or self.H.shape[-1] != self.freq.size:
                raise InputError(
                    f"H must have shape (n_resp, 1, {self.freq.size}), got {self.H.shape}"
                )
            if self.coherence.shape != self.H.shape:
                raise InputError("coherence and H shapes differ")

    @property
    def n_accepted(self) -> int:
        return sum(v.accepted for v in self.verdicts)

    @property
    def rejected(self) -> tuple[HitVerdict, ...]:
        return tuple(v for v in self.verdicts if not v.accepted)


def find_triggers(force: ArrayLike, settings: ImpactSettings) -> NDArray[np.int64]:
    """Sample indices where the force crosses the trigger level with the slope, one per record.

    A crossing inside the record of the previous trigger is not a new hit.
    """
    f = np.asarray(force, dtype=float).ravel()
    sign = 1.0 if settings.slope == "rising" else -1.0
    g, lvl = sign * f, sign * settings.level
    crossings = np.flatnonzero((g[:-1] < lvl) & (g[1:] >= lvl)) + 1
    out: list[int] = []
    next_ok = -1
    for c in crossings.tolist():  # loop over hits (few), each re-arming after its record
        if c >= next_ok:
            out.append(c)
            next_ok = c + settings.record_length
    return np.asarray(out, dtype=np.int64)


#: a channel reaches its input range only when it spans many of its converter's codes: the
#: least number of distinct values in a channel's records for its common extreme to mean
#: clipping (a quiet channel a few codes above its noise reaches the same code by chance)
CLIP_MIN_CODES = 256


def common_clip(rec: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(n_hit, n_ch)``: which records of one run reach their channel's clipping level.

    A channel whose largest (or most negative) value over the run is reached by two hits or
    more, where the samples next to it differ between those hits, is clipped at that level,
    as a digitiser at the end of its range: the same extreme is the converter's last code,
    not the structure's (a clip of one sample leaves no flat top to see in one hit).
    Identical hits (a noise-free simulation) reach the same extreme with the same neighbours
    (to 1e-6 of the level) and are not clipped; a record of fewer than
    :data:`CLIP_MIN_CODES` distinct values on the channel neither.
    """
    n_hit, n_ch, _ = rec.shape
    out = np.zeros((n_hit, n_ch), dtype=bool)
    if n_hit < 2:
        return out
    rows = np.arange(n_hit)
    for sign in (1.0, -1.0):
        z = sign * rec
        ext = z.max(axis=-1)  # (n_hit, n_ch)
        top = ext.max(axis=0)  # the run's extreme of each channel
        at = (ext >= top - 1e-9 * np.abs(top)) & (top > 0)
        # the sample before each record's first sample at its extreme: differs between
        # clipped hits (their signals differ), equal between identical ones
        first = np.argmax(z >= ext[..., None], axis=-1)  # (n_hit, n_ch)
        before = z[rows[:, None], np.arange(n_ch), np.maximum(first - 1, 0)]
        spread = np.where(at, before, np.nan)
        differ = (np.nanmax(spread, axis=0, initial=-np.inf)
                  - np.nanmin(spread, axis=0, initial=np.inf)) > 1e-6 * np.abs(top)
        out |= at & ((at.sum(axis=0) >= 2) & differ)[None, :]
    return _many_codes(rec, out)


#: where a channel's converter's end is known (:func:`converter_tops`), a level several hits
#: reach (:func:`common_clip`) is clipping only at this fraction of it or more
COMMON_CLIP_OF_TOP = 0.5
#: converters whose last code a recording's samples show: 16 and 24 bits (signed codes)
CONVERTER_BITS = (16, 24)
#: a channel's samples are a converter's codes when this fraction of them sits within
#: CODE_TOLERANCE of a whole number of its smallest step
CODES_ON_GRID = 0.999
CODE_TOLERANCE = 1e-3


def converter_tops(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(n_ch,)`` each channel's converter's last code, in the samples' unit, or inf.

    A digitised channel's samples are whole numbers of its code step ``q`` (the smallest
    step between two of its values) times its scale: read from the samples, the step gives
    the converter's full scale, ``2^(b-1) q`` for ``b`` the fewest bits of
    :data:`CONVERTER_BITS` that hold the largest code seen. A sample at the last code
    (``2^(b-1) - 1`` or more steps) is where the converter clipped, as a device flags it: a
    clip of one sample on one hit shows no flat top and no level other hits reach. Inf for
    a channel whose samples are not on one grid (a file of floats, a scaled or filtered
    record), or that holds fewer than :data:`CLIP_MIN_CODES` codes.

    Examples
    --------
    >>> q = 2 * 5.0 / 2**24  # a 24-bit converter over +-5 V, 2 V RMS: clips at 2.5 sd
    >>> v = np.random.default_rng(0).normal(0.0, 2.0, (1, 20000))
    >>> x = np.clip(np.round(v / q) * q, -2**23 * q, 2**23 * q)
    >>> round(float(converter_tops(x)[0]), 5)
    5.0
    """
    x = np.asarray(x, dtype=float)
    srt = np.sort(x, axis=-1)
    d = np.diff(srt, axis=-1)
    scale = np.max(np.abs(srt[..., [0, -1]]), axis=-1, keepdims=True)
    q = np.min(np.where(d > 1e-12 * scale, d, np.inf), axis=-1)  # (n_ch,)
    out = np.full(x.shape[0], np.inf)
    ok = np.isfinite(q) & (q > 0)
    if not np.any(ok):
        return out
    codes = x[ok] / q[ok, None]
    on_grid = np.mean(np.abs(codes - np.round(codes)) < CODE_TOLERANCE, axis=-1) >= CODES_ON_GRID
    top_code = np.max(np.abs(codes), axis=-1)
    bits = np.array(CONVERTER_BITS, dtype=float)
    fits = top_code[:, None] <= 2.0 ** (bits - 1) + 0.5  # (n, n_bits)
    half = np.where(np.any(fits, axis=1), 2.0 ** (bits[np.argmax(fits, axis=1)] - 1), np.inf)
    tops = np.where(on_grid & (top_code >= CLIP_MIN_CODES), (half - 1 - CODE_TOLERANCE) * q[ok],
                    np.inf)
    out[ok] = tops
    return out


def _many_codes(rec: NDArray[np.float64], flagged: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """``flagged`` (n_hit, n_ch) kept where the record's channel has at least
    :data:`CLIP_MIN_CODES` distinct values: a channel a few codes above its noise reaches
    its largest code on several samples and hits without being clipped."""
    out = flagged.copy()
    for k, c in zip(*np.nonzero(flagged), strict=True):  # the few records flagged
        out[k, c] = np.unique(rec[k, c]).size >= CLIP_MIN_CODES
    return out


def _max_run_at_peak(x: NDArray[np.float64], k: int) -> NDArray[np.bool_]:
    """True where a record channel has ``k`` consecutive samples at its absolute peak."""
    a = np.abs(x)
    peak = a.max(axis=-1, keepdims=True)
    at = (a >= peak * (1 - 1e-9)) & (peak > 0)
    c = np.cumsum(at, axis=-1)
    c = np.concatenate([np.zeros((*c.shape[:-1], 1), c.dtype), c], axis=-1)
    return np.any(c[..., k:] - c[..., :-k] >= k, axis=-1)


def _pulse_edges(
    g: NDArray[np.float64], ratio: float
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """First sample above, first back below (half the level) and the first re-rise, per record.

    ``g`` (n_hit, n) is the force with the slope's sign; a re-rise index of ``n`` means none.
    """
    n = g.shape[-1]
    peak = g.max(axis=-1, keepdims=True)
    above = g > ratio * peak
    below = g < 0.5 * ratio * peak
    idx = np.arange(n)
    first_above = np.argmax(above, axis=-1)
    after = idx > first_above[:, None]
    fall = np.where(np.any(below & after, axis=-1), np.argmax(below & after, axis=-1), n)
    again = above & (idx > fall[:, None])
    rerise = np.where(np.any(again, axis=-1), np.argmax(again, axis=-1), n)
    return first_above, fall, rerise


def process_impacts(
    data: ArrayLike,
    fs: float,
    settings: ImpactSettings,
    *,
    force_channel: int = 0,
    channel_names: Sequence[str] | None = None,
    ranges: ArrayLike | None = None,
    estimator: str = "H1",
    force_accept: bool = False,
    max_averages: int | None = None,
    keep_units: bool = False,
) -> ImpactResult:
    """Find, check, window and average the hits of one impact recording.

    Parameters
    ----------
    data : (n_ch, n) array
        Force channel (N) and responses (m/s^2), float32 or float64.
    fs : float
        Sample rate, Hz.
    settings : ImpactSettings
    force_channel : int
        Index of the force channel; the other channels are the responses, in order.
    channel_names : sequence of str, optional
        Names used in verdicts (default ``'channel i'``).
    ranges : (n_ch,) array, optional
        Full-scale input range of each channel, in its unit, for overload detection.
    estimator : {'H1', 'H2', 'Hv'}
    force_accept : bool
        Accept every complete hit whatever its checks say (an operator's override).
        The checks still run: an overridden verdict is accepted and its ``reason``
        reads ``"accepted by override: <what the checks found>"``. A double hit's
        force window then spans every impact (up to the last rise above
        ``double_hit_ratio`` of the peak, plus one pulse width and the taper), so the
        rebound's force is not cut off while its response is kept. Incomplete
        records stay rejected.
    max_averages : int, optional
        Average only the first ``max_averages`` accepted hits (at least 1); the later
        ones are not used: their verdict is not accepted, with the reason
        ``"not used: the first N accepted hits are averaged"``.
    keep_units : bool
        Keep each accepted hit's spectra (``ImpactResult.units``, for the bootstrap over
        hits, :mod:`processing.bootstrap`).

    Returns
    -------
    ImpactResult
        ``H`` and ``coherence`` are None when no hit was accepted; the verdicts say why.

    Examples
    --------
    >>> fs, n = 1024.0, 2048
    >>> t = np.arange(n) / fs
    >>> f = 100 * np.exp(-(((t - 0.1) / 0.002) ** 2)) + 40 * np.exp(-(((t - 0.115) / 0.002) ** 2))
    >>> x = np.vstack([f, np.convolve(f, np.exp(-t * 20), "full")[:n] / fs])
    >>> s = ImpactSettings(20.0, 1024, 32)
    >>> process_impacts(x, fs, s).verdicts[0].accepted
    False
    >>> process_impacts(x, fs, s, force_accept=True).verdicts[0].reason[:20]
    'accepted by override'
    """
    hits, verdicts, accepted, left_out = _judged_hits(
        data, fs, settings, force_channel, channel_names, ranges, force_accept, max_averages)
    L, pre = settings.record_length, settings.pretrigger
    freq = np.asarray(np.fft.rfftfreq(L, 1.0 / fs), dtype=np.float64)
    meta: dict[str, object] = {"fs": float(fs), "record_length": L, "pretrigger": pre}
    if not accepted.any():
        return ImpactResult(freq, None, None, tuple(verdicts), None, estimator, settings.exp_tau,
                            meta)
    windows = _windows(hits, accepted, fs, settings, force_channel, force_accept)
    rec = _without_force_offset(hits.rec[accepted], force_channel)
    sp = record_spectra(rec, fs, windows, references=(force_channel,))
    H, coh = frf(sp, estimator)
    meta["n_averages"] = int(accepted.sum())
    units = record_units(rec, fs, windows, force_channel) if keep_units else None
    return ImpactResult(freq, H, _weighed_out(coh, left_out), tuple(verdicts), sp, estimator,
                        settings.exp_tau, meta, units, left_out)


def _weighed_out(coh: NDArray[np.float64], rows: tuple[int, ...]) -> NDArray[np.float64]:
    """The coherence with ``rows`` set to 0 (their FRF values weigh nothing in the fit)."""
    if not rows:
        return coh
    out = coh.copy()
    out[list(rows)] = 0.0
    return out


def _judged_hits(data: ArrayLike, fs: float, settings: ImpactSettings, force_channel: int,
                 channel_names: Sequence[str] | None, ranges: ArrayLike | None,
                 force_accept: bool, max_averages: int | None,
                 ) -> tuple[_Hits, list[HitVerdict], NDArray[np.bool_], tuple[int, ...]]:
    """The hits of a recording, cleaned as ``settings`` ask, one verdict per trigger (each
    logged), which complete records are averaged (:func:`process_impacts`'s parameters) and
    the responses left out of the point's FRFs when the hits were kept though they overload
    them (:func:`_kept_without`)."""
    x, names, full_scale = _checked_input(data, fs, force_channel, channel_names, ranges,
                                          max_averages)
    hits = _Hits.find(x, fs, settings, force_channel, full_scale)
    if settings.carryover:
        _remove_carryover(x, hits, fs, settings, force_channel)
    if settings.complete:
        _complete_tails(x, hits, fs, force_channel)
    verdicts, accepted = _verdicts(hits, names, fs, force_accept, max_averages)
    left_out = _kept_without(hits, verdicts, accepted, names, force_channel, max_averages)
    _log_verdicts(verdicts)
    return hits, verdicts, accepted, left_out


def _kept_without(hits: _Hits, verdicts: list[HitVerdict], accepted: NDArray[np.bool_],
                  names: Sequence[str], force_channel: int, max_averages: int | None,
                  ) -> tuple[int, ...]:
    """When every complete hit is rejected only for overloading responses (not the force,
    no double hit), the point would be lost for a few channels: the hits are accepted
    instead (``verdicts`` and ``accepted`` changed in place), their verdicts saying which
    responses are left out of the point's FRFs. Returns those responses (row indices of H,
    those the accepted hits overload: :attr:`ImpactResult.left_out`), empty otherwise."""
    over = hits.over | hits.clipped  # (n_complete, n_ch)
    if accepted.any() or not over.shape[0] or np.any(hits.double) or np.any(
            over[:, force_channel]) or not np.all(over.any(axis=1)):
        return ()
    gone = ", ".join(names[int(c)] for c in np.flatnonzero(over.any(axis=0)))
    k = 0
    for i, v in enumerate(verdicts):
        if np.isnan(v.peak_force):  # an incomplete record stays rejected
            continue
        ok = max_averages is None or k < max_averages
        accepted[k] = ok
        verdicts[i] = dataclasses.replace(
            v, accepted=ok, reason=(f"accepted without {gone}: every hit of the point "
                                    f"overloads it ({v.reason})" if ok else
                                    f"not used: the first {max_averages} accepted hits are "
                                    "averaged"))
        k += 1
    rows = np.flatnonzero(np.delete(np.any(over[accepted], axis=0), force_channel))
    return tuple(int(i) for i in rows)


def _log_verdicts(verdicts: Sequence[HitVerdict]) -> None:
    """Log, at INFO, each verdict that has a reason."""
    for v in verdicts:
        if v.reason:
            log.info("hit %d at sample %d %s", v.index, v.trigger,
                     v.reason if v.accepted else f"rejected: {v.reason}")


def _remove_carryover(x: NDArray[Any], hits: _Hits, fs: float, settings: ImpactSettings,
                      force_channel: int) -> None:
    """Each complete record's responses (``hits.rec``, changed in place) less the
    continuation of the free decay on the stretch before it (:attr:`ImpactSettings.carryover`);
    a record with a stretch under :data:`CARRY_MIN` s is left as it is."""
    resp = np.arange(x.shape[0]) != force_channel
    sigma = noise_sigma(x[resp])
    guard, longest = round(SAME_HIT * fs), round(CARRY_STRETCH * fs)
    k = 0
    for i in range(hits.triggers.size):  # few hits, one fit each
        if not hits.complete[i]:
            continue
        b = int(hits.starts[i])
        a = max(0, b - longest, int(hits.triggers[i - 1]) + guard if i else 0)
        if b - a >= CARRY_MIN * fs:
            hits.rec[k, resp] -= free_decay(x[resp, a:b], settings.record_length, sigma)
        k += 1


def _complete_tails(x: NDArray[Any], hits: _Hits, fs: float, force_channel: int) -> None:
    """Each complete record's responses (``hits.rec``, changed in place) plus their own free
    decay past the record's end, folded onto it (:attr:`ImpactSettings.complete`); a record
    with under :data:`CARRY_MIN` s after its pulse is left as it is."""
    resp = np.arange(x.shape[0]) != force_channel
    sigma = noise_sigma(x[resp])
    L = hits.rec.shape[-1]
    guard, longest = round(SAME_HIT * fs), round(CARRY_STRETCH * fs)
    for k in range(hits.rec.shape[0]):  # few hits, one fit each
        a = max(int(hits.fall[k]) + guard, L - longest)
        if L - a >= CARRY_MIN * fs:
            hits.rec[k, resp] += free_decay(hits.rec[k, resp, a:], L, sigma, fold=True)


def _without_force_offset(rec: NDArray[np.float64], force_channel: int) -> NDArray[np.float64]:
    """The records (n_hit, n_ch, L) with each force's baseline (its median over the record,
    N: the pulse holds a few samples) taken off. The force window keeps the samples around the
    pulse, and an offset there is a force the structure never felt: a 1 N offset under a
    pulse of a few ms biases the force spectrum by about a percent."""
    out = rec.copy()
    out[:, force_channel] -= np.median(rec[:, force_channel], axis=-1, keepdims=True)
    return out


def _checked_input(data: ArrayLike, fs: float, force_channel: int,
                   channel_names: Sequence[str] | None, ranges: ArrayLike | None,
                   max_averages: int | None) -> tuple[NDArray[Any], list[str],
                                                      NDArray[np.float64] | None]:
    """The recording (n_ch, n), the channel names and the full-scale ranges (or None), checked
    (:func:`process_impacts`'s parameters); InputError naming what is wrong."""
    x = np.asarray(data)
    if x.ndim != 2 or x.shape[0] < 2:
        raise InputError(f"impact data must have shape (n_ch >= 2, n_samples), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError("impact data contain NaN or infinite samples")
    if not np.isfinite(fs) or fs <= 0:
        raise InputError(f"sample rate must be positive, got {fs}")
    if max_averages is not None and max_averages < 1:
        raise InputError(f"max_averages must be at least 1 (or None), got {max_averages}")
    n_ch = x.shape[0]
    if not 0 <= force_channel < n_ch:
        raise InputError(f"force channel {force_channel} out of range for {n_ch} channels")
    names = [f"channel {i}" for i in range(n_ch)] if channel_names is None else list(channel_names)
    if len(names) != n_ch:
        raise InputError(f"{len(names)} channel names for {n_ch} channels")
    full_scale = None
    if ranges is not None:
        full_scale = np.asarray(ranges, dtype=float).ravel()
        if full_scale.size != n_ch or np.any(full_scale <= 0):
            raise InputError(f"ranges must be {n_ch} positive full-scale values")
    return x, names, full_scale


@dataclass(frozen=True)
class _Hits:
    """The hits of a recording: every trigger and its record start (samples), whether the
    record is complete, and for the complete ones (n_hit rows) the records (n_hit, n_ch, L),
    the force with the slope's sign ``g``, its peak (N), the pulse edges (see
    :func:`_pulse_edges`), and the checks: double hit, clipped and overloaded channels."""

    triggers: NDArray[np.int64]
    starts: NDArray[np.int64]
    complete: NDArray[np.bool_]
    rec: NDArray[np.float64]
    g: NDArray[np.float64]
    peak_force: NDArray[np.float64]
    first_above: NDArray[np.int64]
    fall: NDArray[np.int64]
    rerise: NDArray[np.int64]
    double: NDArray[np.bool_]
    clipped: NDArray[np.bool_]
    over: NDArray[np.bool_]
    over_reason: str  # what ``over`` means: at the range, or at a level other hits reach

    @classmethod
    def find(cls, x: NDArray[Any], fs: float, settings: ImpactSettings, force_channel: int,
             full_scale: NDArray[np.float64] | None) -> _Hits:
        L, pre = settings.record_length, settings.pretrigger
        sign = 1.0 if settings.slope == "rising" else -1.0
        triggers = find_triggers(x[force_channel], settings)
        starts = triggers - pre
        complete = (starts >= 0) & (starts + L <= x.shape[1])
        ok_starts = starts[complete]
        # records (n_hit, n_ch, L) of the complete hits, one fancy-indexing gather
        rec = x[:, ok_starts[:, None] + np.arange(L)].transpose(1, 0, 2).astype(float)
        g = sign * rec[:, force_channel]
        peak_force = g.max(axis=-1) if rec.shape[0] else np.zeros(0)
        first_above, fall, rerise = _pulse_edges(g, settings.double_hit_ratio)
        clipped = _many_codes(rec, _max_run_at_peak(rec, settings.clip_samples))
        if full_scale is not None:  # the channels' input ranges decide
            over = np.abs(rec).max(axis=-1) >= 0.99 * full_scale
            why = "peak at or above 99 % of its range"
        else:  # the converter's last code, read from the samples; or, the run's hits tell:
            # a level several reach is the converter's end
            tops = converter_tops(x)[None, :]
            peak = np.abs(rec).max(axis=-1)
            last = peak >= tops
            # a level several hits reach is clipping where the converter's end is not known,
            # or near it (an amplifier saturating before the converter), not far under it
            common = common_clip(rec) & ((peak >= COMMON_CLIP_OF_TOP * tops)
                                         | ~np.isfinite(tops))
            over = last | common
            why = ("clipped: a sample at its converter's last code" if np.any(last) else
                   "clipped: it reaches the extreme other hits of the run stop at")
        return cls(triggers, starts, complete, rec, g, peak_force, first_above, fall, rerise,
                   rerise < L, clipped, over, why)


def _reasons(hits: _Hits, k: int, names: Sequence[str], fs: float) -> list[str]:
    """What the checks found on complete record ``k`` (empty if nothing)."""
    reasons = []
    if hits.over[k].any():
        ch = names[int(np.argmax(hits.over[k]))]
        reasons.append(f"overload on {ch} ({hits.over_reason})")
    elif hits.clipped[k].any():
        ch = names[int(np.argmax(hits.clipped[k]))]
        reasons.append(f"overload on {ch} (clipped: flat top at its peak)")
    if hits.double[k]:
        dt = (hits.rerise[k] - hits.first_above[k]) / fs * 1e3
        reasons.append(f"double hit (second impact {dt:.1f} ms after the first)")
    return reasons


def _verdicts(hits: _Hits, names: Sequence[str], fs: float, force_accept: bool,
              max_averages: int | None) -> tuple[list[HitVerdict], NDArray[np.bool_]]:
    """One verdict per trigger, and which complete records are averaged."""
    verdicts: list[HitVerdict] = []
    accepted = np.zeros(int(hits.complete.sum()), dtype=bool)  # per complete record
    k = n_used = 0
    for i, (trig, start, comp) in enumerate(zip(hits.triggers, hits.starts, hits.complete,
                                                strict=True)):
        if not comp:
            where = "start" if start < 0 else "end"
            verdicts.append(HitVerdict(i, int(trig), int(start), float("nan"), False,
                                       f"record incomplete: it runs past the {where} of the data"))
            continue
        reasons = _reasons(hits, k, names, fs)
        ok = force_accept or not reasons
        reason = "; ".join(reasons)
        if force_accept and reasons:
            reason = f"accepted by override: {reason}"
        if ok and max_averages is not None and n_used >= max_averages:
            ok, reason = False, f"not used: the first {max_averages} accepted hits are averaged"
        accepted[k] = ok
        n_used += ok
        verdicts.append(HitVerdict(i, int(trig), int(start), float(hits.peak_force[k]),
                                   bool(accepted[k]), reason))
        k += 1
    return verdicts, accepted


def _windows(hits: _Hits, accepted: NDArray[np.bool_], fs: float, settings: ImpactSettings,
             force_channel: int, force_accept: bool) -> NDArray[np.float64]:
    """The windows (n_acc, n_ch, L) of the accepted records: the exponential window on every
    channel if any, times the force window on the force channel (its stop and taper from the
    pulse, or ``settings.force_window``; an accepted double hit's spans the last impact)."""
    n_acc, n_ch, L = int(accepted.sum()), hits.rec.shape[1], settings.record_length
    windows = np.ones((n_acc, n_ch, L))
    if settings.exp_tau is not None:
        windows *= exponential_window(L, fs, settings.exp_tau)
    if settings.force_window is not None:
        stop = np.full(n_acc, settings.pretrigger + round(settings.force_window * fs))
        taper = np.zeros_like(stop)
    else:
        fall, first_above = hits.fall[accepted], hits.first_above[accepted]
        width = np.maximum(np.maximum(fall - first_above, 1), settings.ring)
        stop = fall + width
        taper = width
        if force_accept:  # an accepted double hit: the window spans the last impact too
            g_a = hits.g[accepted]
            above = g_a > settings.double_hit_ratio * g_a.max(axis=-1, keepdims=True)
            last = L - 1 - np.argmax(above[:, ::-1], axis=-1)
            stop = np.where(hits.double[accepted], np.maximum(stop, last + 2 * width), stop)
    windows[:, force_channel] *= force_window(L, np.minimum(stop, L), taper)
    return windows


def merge_results(results: Sequence[ImpactResult]) -> ImpactResult:
    """One result from several recordings of the same excitation point (hits averaged together)."""
    if not results:
        raise InputError("no impact result to merge")
    first = results[0]
    for r in results[1:]:
        if r.exp_tau != first.exp_tau or r.estimator != first.estimator:
            raise InputError("impact results to merge must share window and estimator")
    verdicts = tuple(v for r in results for v in r.verdicts)
    spectra = [r.spectra for r in results if r.spectra is not None]
    if not spectra:
        return ImpactResult(first.freq, None, None, verdicts, None, first.estimator,
                            first.exp_tau, dict(first.meta))
    sp = spectra[0]
    for other in spectra[1:]:
        sp = combine(sp, other)
    H, coh = frf(sp, first.estimator)
    parts = [r.units for r in results if r.spectra is not None]
    units = (UnitSpectra.concat([u for u in parts if u is not None])
             if parts and all(u is not None for u in parts) else None)
    left_out = tuple(sorted({i for r in results for i in r.left_out}))
    return ImpactResult(sp.freq, H, _weighed_out(coh, left_out), verdicts, sp,
                        first.estimator, first.exp_tau,
                        {**first.meta, "n_averages": sp.n_averages}, units, left_out)


def impact_measurement(
    results: Sequence[ImpactResult],
    geometry: Geometry,
    resp_nodes: ArrayLike,
    resp_dirs: ArrayLike,
    exc_nodes: ArrayLike,
    exc_dirs: ArrayLike,
    units: TimeUnits | None = None,
) -> Measurement:
    """A :class:`~processing.measurement.Measurement` with one FRF column per excitation
    point, in the order of ``results``: estimated here from hits, with the exponential
    window's tau (when every point shares one), the hammer's usable band
    (:func:`force_band_top`) and the per-hit spectra ``units`` when given.

    Raises InputError naming the excitation without any accepted hit.
    """
    en = np.asarray(exc_nodes).ravel()
    if len(results) != en.size:
        raise InputError(f"{len(results)} impact results for {en.size} excitation DOFs")
    cols, cohs, forces = [], [], []
    for j, r in enumerate(results):
        if r.H is None or r.coherence is None or r.spectra is None:
            why = "; ".join(sorted({v.reason for v in r.verdicts})) or "no hit found"
            raise InputError(f"excitation {j} (node {en[j]}) has no accepted hit: {why}")
        if not np.array_equal(r.freq, results[0].freq):
            raise InputError("impact results have different frequency lines")
        cols.append(r.H)
        cohs.append(r.coherence)
        forces.append(r.spectra.Sff[0, 0].real)  # the averaged force auto-spectrum
    taus = {r.exp_tau for r in results}
    estimator = results[0].estimator
    frf = FRFSet(
        freq=results[0].freq,
        H=np.concatenate(cols, axis=1),
        resp_nodes=np.asarray(resp_nodes),
        resp_dirs=np.asarray(resp_dirs),
        exc_nodes=en,
        exc_dirs=np.asarray(exc_dirs),
        geometry=geometry,
        coherence=np.concatenate(cohs, axis=1),
    )
    return Measurement(frf, Provenance(
        origin="estimated", excitation="impact", estimator=estimator, units=units,
        exponential_tau=taus.pop() if len(taus) == 1 else None,
        force_band_top=force_band_top(results[0].freq, np.stack(forces)),
        n_averages=tuple(r.n_accepted for r in results)))


def force_band_top(freq: NDArray[np.float64], Sff: NDArray[np.float64]) -> float | None:
    """The hammer's usable band: the highest line, Hz, under which every column's averaged
    force auto-spectrum (``Sff``, (n_columns, n_f)) stays within ``FORCE_DROP`` (20 dB) of
    its peak; None when it does to the end of the data.

    Above it the pulse has little force left, and at the pulse's spectral zero (a half-sine
    of width ``tau`` has its first at ``1.5 / tau``: 375 Hz for 4 ms) an FRF is response
    noise and force errors over almost nothing: a spike the elastic-mode detection reads as
    a mode. A harder tip (a shorter pulse) reaches higher.
    """
    S = np.atleast_2d(np.asarray(Sff, dtype=float))
    peak = np.max(S, axis=1, keepdims=True)
    after = np.arange(S.shape[1]) >= np.argmax(S, axis=1)[:, None]
    low = after & (S < FORCE_DROP * peak)
    if not np.any(low):
        return None
    first = int(np.min(np.where(np.any(low, axis=1), np.argmax(low, axis=1), S.shape[1])))
    return float(freq[max(first - 1, 0)])


# ---- defaults read from the data ----

#: a force whose kurtosis exceeds this is impulsive (hammer); Gaussian random has 3, a sine
#: 1.5, burst random about 3 over its duty cycle
IMPULSIVE_KURTOSIS = 20.0
#: impacts closer than this (s) are one hit (a double hit's rebound)
SAME_HIT = 0.1
#: impacts closer than this fraction of the median time between a recording's impacts are
#: a double hit's rebound, not the hits' spacing (the record length)
REBOUND_GAP = 0.25


@dataclass(frozen=True)
class ExcitationGuess:
    """What the force channel looks like: ``kind`` ('impact' or 'random'), its kurtosis
    (``E[x^4] / E[x^2]^2`` about the median) and crest factor (peak / RMS)."""

    kind: Literal["impact", "random"]
    kurtosis: float
    crest: float


def excitation_type(force: ArrayLike) -> ExcitationGuess:
    """Hammer or shaker from one force channel (N): impulsive (kurtosis above
    :data:`IMPULSIVE_KURTOSIS`) is a hammer test, anything else random excitation.

    >>> t = np.arange(8192) / 1024.0
    >>> excitation_type(np.exp(-((t % 2 - 1) / 0.002) ** 2)).kind
    'impact'
    >>> excitation_type(np.random.default_rng(0).normal(size=8192)).kind
    'random'
    """
    x = np.asarray(force, dtype=float).ravel()
    x = x - np.median(x)
    m2 = float(np.mean(x**2))
    if not m2 > 0:
        return ExcitationGuess("random", 0.0, 0.0)
    k = float(np.mean(x**4) / m2**2)
    crest = float(np.max(np.abs(x)) / np.sqrt(m2))
    return ExcitationGuess("impact" if k > IMPULSIVE_KURTOSIS else "random", k, crest)


@dataclass(frozen=True)
class ImpactDefaults:
    """Hammer-test settings read from one recording (see :func:`impact_defaults`).

    Attributes
    ----------
    level : trigger level, N (baseline plus 10 noise standard deviations, at least 2 % of the
        largest impact above the baseline)
    noise : the force's noise standard deviation, N
    n_hits : impacts found (those closer than :data:`SAME_HIT` counted once)
    spacing : shortest time between impacts, s (None: one impact)
    pulse_width : median pulse width (first above 10 % of the peak to back below 5 %), s
    decay : median over impacts of the time their slowest response channel takes to fall
        under three times its noise (extrapolated exponentially past the next impact), s
    record : record length, s: :data:`TAIL_FACTOR` times the decay plus the pre-trigger (at
        least :data:`MIN_RECORD`), at most 95 % of the spacing (one impact: what follows it)
    exp_tau : exponential window time constant, s, when the responses have not decayed by
        the end of the record (it takes them down to their noise by then,
        :func:`exponential_for`); None otherwise
    ratio : the slowest channel's envelope just after the impact over its noise threshold
    ring_before, ring_after : median over impacts of the samples the force stands above four
        noise standard deviations (about its local baseline) before the pulse's first sample
        above the trigger level and after its end: the acquisition's anti-alias filter
        rings on both sides of a pulse a few samples long (:func:`ringing`)
    carryover : median over the impacts followed by another of the responses' ringing just
        before the next impact (the last 50 ms block envelope, block mean removed, of the
        channel that rings most) over that channel's noise standard deviation (0: one impact)
    """

    level: float
    noise: float
    n_hits: int
    spacing: float | None
    pulse_width: float
    decay: float
    record: float
    exp_tau: float | None
    ratio: float = float(np.exp(1.0))
    ring_before: int = 0
    ring_after: int = 0
    carryover: float = 0.0


#: shortest default record, s (lines 0.5 Hz apart: a mount mode of a few Hz needs lines below it)
MIN_RECORD = 2.0
#: the default record holds this many times the responses' decay to three noise standard
#: deviations: a mount mode's tail under the broadband noise still stands out of the noise on
#: its own lines (a tail cut there biases the lowest lines by tens of %), so it is followed
#: as far again (as far under the noise as the response started above it, for a
#: start-to-noise ratio of about 10)
TAIL_FACTOR = 2.0


def wanted_record(decay: float, pretrigger: float) -> float:
    """The record a decay of ``decay`` s asks for, s: :data:`TAIL_FACTOR` times it plus the
    pre-trigger, at least :data:`MIN_RECORD`, up to the next 10 ms (before any cap by the
    hit spacing)."""
    return float(np.ceil(max(TAIL_FACTOR * decay + pretrigger, MIN_RECORD) * 100) / 100)


def exponential_for(record: float, pretrigger: float, decay: float, ratio: float,
                    ) -> float | None:
    """Exponential window time constant (s) that brings responses decaying in ``decay`` s
    (start-to-noise ratio ``ratio``) down to their noise by the end of a ``record`` s record
    starting ``pretrigger`` s before the impact: ``tau = T d / (ln(r) (d - T))`` with
    ``T = record - pretrigger``, at least ``T / 10``; None when they have decayed by then."""
    T = record - pretrigger
    if not decay > T or not ratio > 1:
        return None
    return float(max(T * decay / (np.log(ratio) * (decay - T)), T / 10))


#: samples either side of a pulse searched for its ringing (:func:`ringing`)
RING_SPAN = 64


def ringing(g: NDArray[np.float64], starts: NDArray[np.int64], sigma: float,
            ) -> tuple[int, int]:
    """Samples the force ``g`` (N, baseline off) stands above ``4 sigma`` before each pulse's
    first sample ``starts`` and after its end (back under 5 % of its peak), medians over the
    pulses, each at most :data:`RING_SPAN`. The baseline is the median around each pulse
    (a drifting force offset is not ringing)."""
    n, R = g.size, RING_SPAN
    idx = np.clip(starts[:, None] + np.arange(-2 * R, 2 * R), 0, n - 1)
    seg = g[idx]
    seg = seg - np.median(seg, axis=-1, keepdims=True)
    c = 2 * R  # the pulse's first sample in each segment
    peak = seg[:, c:c + R].max(axis=-1, keepdims=True)
    after = np.arange(seg.shape[-1]) > c
    below = (seg < 0.05 * peak) & after
    fall = np.where(np.any(below, axis=-1), np.argmax(below, axis=-1), c + 1)
    loud = np.abs(seg) > 4 * sigma
    k = np.arange(seg.shape[-1])
    pre = (k >= c - R) & (k < c)
    first = np.where(np.any(loud & pre, axis=-1), np.argmax(loud & pre, axis=-1), c)
    post = loud & (k[None] >= fall[:, None]) & (k[None] < fall[:, None] + R)
    last = np.where(np.any(post, axis=-1), seg.shape[-1] - 1 - np.argmax(post[:, ::-1], axis=-1),
                    fall - 1)
    return int(np.median(c - first)), int(np.median(last + 1 - fall))


#: shortest default pre-trigger, s
MIN_PRETRIGGER = 0.01
#: the default pre-trigger holds this many times the samples the force rings above its
#: noise before a pulse (the filter's ringing goes on under the noise)
PRE_RING_FACTOR = 2


def pretrigger_for(ring_before: int, fs: float) -> float:
    """Pre-trigger, s, that holds the anti-alias filter's ringing before a pulse: twice the
    samples ``ring_before`` the force stands above its noise before the pulse
    (:func:`ringing`; the ringing goes on under the noise), at least
    :data:`MIN_PRETRIGGER`. A record that starts inside that ringing cuts it from the force
    and the responses alike, and H1 is biased wherever the accelerance is small.

    >>> pretrigger_for(7, 256.0)
    0.0546875
    >>> pretrigger_for(1, 256.0)
    0.01
    """
    if not fs > 0 or ring_before < 0:
        raise InputError(f"pretrigger_for needs fs > 0 and ring_before >= 0, got {fs}, "
                         f"{ring_before}")
    return float(max(MIN_PRETRIGGER, PRE_RING_FACTOR * ring_before / fs))


def _impacts(g: NDArray[np.float64], level: float, fs: float) -> NDArray[np.int64]:
    """First sample of each impact: rising crossings of ``level`` more than SAME_HIT apart."""
    above = g > level
    rise = np.flatnonzero(above[1:] & ~above[:-1]) + 1
    out: list[int] = []
    for r in rise.tolist():  # few crossings: one or two a hit
        if not out or r - out[-1] > SAME_HIT * fs:
            out.append(r)
    return np.asarray(out, dtype=np.int64)


def _decay_time(env: NDArray[np.float64], thr: NDArray[np.float64], dt: float,
                ) -> tuple[float, float]:
    """Time (s) until a response's block envelope (n_ch, n_blk, from an impact to the next)
    stays under ``thr`` (n_ch,), the slowest channel's, and that channel's start-to-threshold
    ratio. Past the segment's end, the decay of its last half is extrapolated."""
    n_ch, nb = env.shape
    above = env > thr[:, None]
    times = np.empty(n_ch)
    for c in range(n_ch):  # few channels, each a vectorised look-up
        idx = np.flatnonzero(above[c])
        if idx.size == 0:
            times[c] = 0.0
            continue
        last = int(idx[-1])
        if last < nb - 1:
            times[c] = (last + 1) * dt
            continue
        half = np.arange(nb // 2, nb)
        y = np.log(np.maximum(env[c, half], 1e-300))
        slope = np.polyfit(half * dt, y, 1)[0] if half.size >= 3 else 0.0
        end = float(np.mean(env[c, -max(1, nb // 8):]))
        if slope < 0 and end > thr[c]:
            times[c] = nb * dt + np.log(end / thr[c]) / -slope
        else:  # not decaying (or already there): say ten segments
            times[c] = 10 * nb * dt
    c = int(np.argmax(times))
    ratio = float(np.max(env[c, : max(1, nb // 20 + 1)]) / thr[c])
    return float(times[c]), max(ratio, 1.0 + 1e-9)


def impact_defaults(force: ArrayLike, responses: ArrayLike, fs: float,
                    pretrigger: float = 0.01) -> ImpactDefaults:
    """Trigger level, record length and exponential window read from one hammer recording.

    Parameters
    ----------
    force : (n,) force, N (a hammer pushing along the excitation: positive pulses)
    responses : (n_resp, n) accelerations
    fs : sample rate, Hz
    pretrigger : s kept before each trigger

    Returns
    -------
    ImpactDefaults
        See its attributes for how each is chosen. The exponential window is chosen so
        that ``envelope(T) exp(-T / tau)`` is down at three noise standard deviations at the
        record's end ``T``: ``tau = T d / (ln(r) (d - T))`` for a decay time ``d`` and a
        start-to-noise ratio ``r``, at least ``T / 10``.

    Raises
    ------
    InputError
        No impact found above the noise.
    """
    f = np.asarray(force, dtype=float).ravel()
    x = np.atleast_2d(np.asarray(responses, dtype=float))
    n = f.size
    base = float(np.median(f))
    sigma = float(noise_sigma(f[None])[0])
    g = f - base
    peak = float(g.max())
    if not peak > 10 * sigma or peak <= 0:
        raise InputError("no impact stands out of the force's noise: check the force channel")
    level = max(10 * sigma, 0.02 * peak)
    starts = _impacts(g, level, fs)
    gaps = np.diff(starts)
    if gaps.size:  # a double hit's rebound (a soft tip's comes several pulse widths, tens
        # of ms, after the first pulse: past SAME_HIT) is part of its hit, not the spacing
        gaps = np.diff(starts[np.r_[True, gaps >= REBOUND_GAP * np.median(gaps)]])
    spacing = float(np.min(gaps)) / fs if gaps.size else None
    # pulse widths: from first above 10 % of each impact's peak to back under 5 %
    w_n = max(1, round(SAME_HIT * fs))
    seg = g[np.minimum(starts[:, None] + np.arange(w_n), n - 1)]
    _, fall, _ = _pulse_edges(seg, 0.1)
    first = np.argmax(seg > 0.1 * seg.max(axis=-1, keepdims=True), axis=-1)
    width = float(np.median(np.maximum(fall - first, 1))) / fs
    # responses: 50 ms block envelopes (block means removed) against their white noise
    B = max(8, round(0.05 * fs))
    thr = 3 * np.maximum(noise_sigma(x), 1e-300)
    ends = np.r_[starts[1:] - round(SAME_HIT * fs), n]  # clear of the next impact's rise
    decays, ratios, carry = [], [], []
    for s0, s1 in zip(starts.tolist(), ends.tolist(), strict=True):  # few impacts
        nb = (s1 - s0) // B
        if nb < 4:
            continue
        blk = x[:, s0:s0 + nb * B].reshape(x.shape[0], nb, B)
        env = np.sqrt(np.mean((blk - blk.mean(axis=-1, keepdims=True)) ** 2, axis=-1))
        d, r = _decay_time(env, thr, B / fs)
        decays.append(d)
        ratios.append(r)
        if s1 < n:  # another impact follows
            carry.append(float(np.max(env[:, -1] / (thr / 3))))
    decay = float(np.median(decays)) if decays else (n - starts[-1]) / fs
    ratio = float(np.median(ratios)) if ratios else np.e
    limit = (n - starts[-1]) / fs + pretrigger if spacing is None else 0.95 * spacing
    want = wanted_record(decay, pretrigger)
    record = max(min(want, np.floor(limit * 100) / 100), 8 / fs, 2 * pretrigger)
    before, after = ringing(g, starts, sigma)
    return ImpactDefaults(level=base + level, noise=sigma, n_hits=int(starts.size),
                          spacing=spacing, pulse_width=width, decay=decay, record=float(record),
                          exp_tau=exponential_for(record, pretrigger, decay, ratio), ratio=ratio,
                          ring_before=before, ring_after=after,
                          carryover=float(np.median(carry)) if carry else 0.0)
