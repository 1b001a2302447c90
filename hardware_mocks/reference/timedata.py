"""Realistic time records of a reference scenario: hammer tests and shaker tests, with defects.

The responses are exact to the scenario's model: each run's recording (force, then zeros long
enough for the slowest mode to decay under 1e-5 of its start) is transformed, multiplied by
the system's exact accelerance on the FFT's lines (:meth:`.system.ReferenceSystem.accelerance`)
and transformed back; the zeros are dropped. Force and responses both pass the same
anti-alias filter (flat to ``fs / 2.56``, a raised-cosine taper to zero at ``fs / 2``), so
the signals are band-limited and, for a record that holds the whole decay, the ratio of
their DFTs is the model's FRF in the band (hysteretic damping is not causal: its small
response before each impact is cut at the recording's start).

Hammer test (:func:`hammer_test`), per excitation point one run of several hits:

- half-sine pulses of varying width (0.9-1.1 of ``2.56 / fs``: a tip that excites up to the
  analysis band; ``tip`` times that for a softer one) and amplitude (0.5-1.0 of the test's
  force), irregular spacing;
- double hits (a second pulse 2.5-8 pulse widths after the first, 20-60 % of its height)
  and clipped hits (a hit at least twice the run's others, hard enough that three consecutive
  samples of one response channel exceed everything the other hits give it; that channel's
  ADC range is set just under them: a flat top), labelled in :class:`Hit`;
- the force's DC offset and drift, its noise; the responses' IEPE settling (a decaying
  offset from the start of the recording), slow drift and noise;
- the mounts' damping scaled (``damping``: light responses still ring after the next hit).

Shaker test (:func:`shaker_test`): continuous random, burst random or periodic chirp drive
signals through a shaker whose armature mass ``m_a`` loads the structure, so the measured force
is ``F = (I + m_a H_dd)^-1 G V`` (``H_dd`` the accelerance between the drive points): the
force drops out at the structure's resonances. Two shakers at once share part of their drive
signal (correlated references).

A real test's error budget on the recorded channels (:class:`Budget`, all off by default;
``budget=`` of either spec): noise at a fraction of each channel's RMS, each response
channel's time skew against the force (a fraction of a sample, applied on the FFT lines
before the recording is formed), mains hum (50 or 60 Hz and two harmonics) on the
responses, and a converter of a few bits over a fixed input range per channel for the whole
test (the range a headroom over the channel's largest value in the test: quiet channels sit
near the converter's floor), and response channels ranged just under their largest samples,
which clip (every hit reaching a range is labelled clipped).

:func:`write_uff` writes a test as UFF dataset 58/58b time records (ordinate 13 force, 12
acceleration, one load case per run) with units (164) and nodes (2411), written here from
the format's description (no project code), so the project's reader is checked against an
independent writer.

Example
-------
>>> from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario
>>> sc = build_scenario(ScenarioSpec(seed=1, n_forces=6, n_sensors=3, elastic_ratio=None))
>>> t = hammer_test(sc, HammerSpec(seed=1, hits=3, n_double=1))
>>> len(t.runs), sum(h.double for r in t.runs for h in r.hits)
(6, 1)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from hardware_mocks.reference.scenarios import Scenario
from hardware_mocks.reference.system import ReferenceSystem, Truth

__all__ = ["Budget", "HammerSpec", "Hit", "ShakerSpec", "TimeRecording", "TimeTest", "good_and_bad",
           "hammer_test", "shaker_test", "write_uff"]

#: the tail after a recording is followed until the slowest mode is down to this fraction
TAIL_LEFT = 1e-5
#: longest zero tail, s (an undamped model would need an infinite one)
MAX_TAIL = 600.0
#: frequency lines per block of the exact FRF evaluation (bounds its memory)
_BLOCK = 8192


@dataclass(frozen=True)
class Hit:
    """One hammer hit's ground truth.

    Attributes
    ----------
    time : s, start of the pulse from the start of the recording
    peak : N, height of the (first) pulse
    width : s, duration of the half-sine pulse
    double : a second impact follows (the hit must be rejected)
    clipped : a channel of this hit is clipped (the hit must be rejected)
    """

    time: float
    peak: float
    width: float
    double: bool = False
    clipped: bool = False

    @property
    def good(self) -> bool:
        return not (self.double or self.clipped)


@dataclass(frozen=True)
class TimeRecording:
    """One run: measured forces and responses, SI.

    Attributes
    ----------
    load_case : run number (UFF load case), from 1
    excitations : (n_ref,) indices into the scenario's forces driven in this run
    forces : (n_ref, n) measured forces, N
    responses : (n_resp, n) measured accelerations along the scenario's sensors, m/s^2
    hits : hammer runs: every hit in time order (empty for shaker runs)
    """

    load_case: int
    excitations: NDArray[np.int64]
    forces: NDArray[np.float64]
    responses: NDArray[np.float64]
    hits: tuple[Hit, ...] = ()

    @property
    def n_samples(self) -> int:
        return int(self.forces.shape[1])


@dataclass(frozen=True)
class TimeTest:
    """A generated test of a scenario.

    Attributes
    ----------
    scenario : the scenario (reported geometry, sensors, forces)
    system : the system simulated (the scenario's, its mount damping scaled)
    kind : "hammer", "random", "burst" or "chirp"
    fs : sample rate, Hz
    runs : the recordings
    settings : what was drawn (pulse widths, spacing, noise levels, ...) for reports
    ranges : each response channel's input range with a :class:`Budget`'s converter or
        clipping, m/s^2 (what a station file would state), else None
    """

    scenario: Scenario
    system: ReferenceSystem
    kind: Literal["hammer", "random", "burst", "chirp"]
    fs: float
    runs: tuple[TimeRecording, ...]
    settings: dict[str, float] = field(default_factory=dict)
    ranges: NDArray[np.float64] | None = None

    @property
    def truth(self) -> Truth:
        return self.system.truth

    @property
    def hits(self) -> tuple[Hit, ...]:
        return tuple(h for r in self.runs for h in r.hits)

    def exact_frf(self, freq: NDArray[np.float64]) -> NDArray[np.complex128]:
        """Exact accelerance (n_resp, n_exc, n_f) of the simulated system between the
        scenario's true DOFs, (m/s^2)/N."""
        sc = self.scenario
        return self.system.accelerance(freq, sc.sensors.nodes, sc.sensors.vectors,
                                       sc.forces.nodes, sc.forces.vectors)


@dataclass(frozen=True)
class Budget:
    """A real test's errors on the recorded channels (module notes); the defaults add none.

    ``rms_noise``: noise on the force and on each response, the fraction of that channel's
    RMS over the run; ``skew``: each response channel's delay against the force, drawn
    within +-``skew`` samples; ``hum``: mains hum on each response at this fraction of its
    RMS (``mains_hz`` and its 2nd and 3rd harmonics at 0.5 and 0.3 of it, random phases);
    ``bits``: a converter of this many bits over a fixed range per channel (a headroom drawn
    log-uniform in ``headroom`` over the channel's largest value in the test), None for
    none; ``clip_channels``: that many response channels (drawn) ranged under their
    ``clip_samples``-th (drawn) largest sample in the test, so that they clip for that many
    samples, in the run where they peak.
    """

    rms_noise: float = 0.0
    skew: float = 0.0
    hum: float = 0.0
    mains_hz: float = 50.0
    bits: int | None = None
    headroom: tuple[float, float] = (2.0, 100.0)
    clip_channels: int = 0
    clip_samples: tuple[int, int] = (1, 5)


@dataclass(frozen=True)
class HammerSpec:
    """What a hammer test draws.

    ``spacing`` is the mean time between hits (each drawn within ``+-jitter`` of it),
    ``noise_force`` the force noise over the test's force (``offset`` its DC offset and
    drift), ``noise_response`` the responses' noise over their median peak (``settling`` the
    IEPE settling offset at the start, ``drift`` a slow sinusoidal drift, both over it too),
    ``damping`` the factor on the mounts' loss factors, ``tip`` the factor on the pulses'
    widths (2: a soft tip, whose force's first spectral zero, at ``1.5 / width`` = 0.29 fs,
    falls inside the analysis band),
    ``fs`` the sample rate (None: a power of two >= 2.56 times the scenario's span, >= 256 Hz).
    """

    seed: int
    hits: int = 5
    spacing: float = 4.0
    jitter: float = 0.2
    n_double: int = 0
    n_clipped: int = 0
    force: float = 200.0
    noise_force: float = 5e-4
    noise_response: float = 3e-4
    offset: float = 0.005
    settling: float = 0.1
    drift: float = 1e-3
    damping: float = 1.0
    tip: float = 1.0
    fs: float | None = None
    budget: Budget = field(default_factory=Budget)


@dataclass(frozen=True)
class ShakerSpec:
    """What a shaker test draws.

    ``kind``: "random" (continuous), "burst" (random bursts over ``burst`` of each
    ``period``) or "chirp" (a linear sweep over the band every ``period``); ``shakers`` 1 or
    2 (two excitation points driven at once, their drive signals ``correlation`` alike);
    ``armature`` the shaker's moving mass, kg (the force drop-out at resonances); the
    errors as in :class:`HammerSpec`.
    """

    seed: int
    kind: Literal["random", "burst", "chirp"] = "random"
    duration: float = 40.0
    period: float = 4.0
    burst: float = 0.6
    shakers: int = 1
    correlation: float = 0.3
    armature: float = 2.0
    force: float = 20.0
    noise_force: float = 1e-3
    noise_response: float = 1e-3
    offset: float = 0.005
    settling: float = 0.1
    drift: float = 1e-3
    damping: float = 1.0
    fs: float | None = None
    budget: Budget = field(default_factory=Budget)


def _sample_rate(scenario: Scenario, fs: float | None) -> float:
    if fs is not None:
        return float(fs)
    return float(max(256.0, 2.0 ** np.ceil(np.log2(2.56 * scenario.freq[-1]))))


def _tail(system: ReferenceSystem) -> float:
    """Zero tail, s, after which the slowest mode is down to :data:`TAIL_LEFT`."""
    alpha = system.slowest_decay_per_s()
    return MAX_TAIL if alpha <= 0 else min(MAX_TAIL, np.log(1 / TAIL_LEFT) / alpha)


def _through(system: ReferenceSystem, scenario: Scenario, forces: NDArray[np.float64],
             exc: NDArray[np.int64], fs: float, tail: float, armature: float = 0.0,
             delay: NDArray[np.float64] | None = None,
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The forces and the exact responses (n_resp, n) of the system to ``forces``
    (n_ref, n) at the scenario's excitations ``exc``; with ``armature`` > 0, ``forces`` are
    the shakers' blocked forces ``G V`` and the forces applied are ``(I + m_a H_dd)^-1 G V``.
    Both pass the anti-alias filter (:func:`_anti_alias`) as a measurement's would;
    ``delay`` (n_resp,) s: each response recorded that much late (channel skew)."""
    n = forces.shape[1]
    N = scipy.fft.next_fast_len(n + int(np.ceil(tail * fs)), real=True)
    F = scipy.fft.rfft(forces, N, axis=-1)
    freq = np.asarray(np.fft.rfftfreq(N, 1 / fs), dtype=np.float64)
    sens, fc = scenario.sensors, scenario.forces
    X = np.empty((sens.nodes.size, freq.size), dtype=complex)
    for lo in range(0, freq.size, _BLOCK):
        f = freq[lo:lo + _BLOCK]
        H = system.accelerance(f, sens.nodes, sens.vectors, fc.nodes[exc], fc.vectors[exc])
        Fb = F[:, lo:lo + _BLOCK]
        if armature > 0:
            Hdd = system.accelerance(f, fc.nodes[exc], fc.vectors[exc], fc.nodes[exc],
                                     fc.vectors[exc])  # (n_ref, n_ref, n_f)
            Z = np.eye(exc.size)[..., None] + armature * Hdd
            Fb = np.linalg.solve(np.moveaxis(Z, -1, 0), Fb.T[..., None])[..., 0].T
            F[:, lo:lo + _BLOCK] = Fb
        X[:, lo:lo + _BLOCK] = np.einsum("ref,ef->rf", H, Fb)
    G = _anti_alias(freq, fs)
    true_force = scipy.fft.irfft(F * G, N, axis=-1)[:, :n]
    if delay is not None:
        X = X * np.exp(-2j * np.pi * freq[None, :] * np.asarray(delay, float)[:, None])
    return true_force, scipy.fft.irfft(X * G, N, axis=-1)[:, :n]


def _anti_alias(freq: NDArray[np.float64], fs: float) -> NDArray[np.float64]:
    """The acquisition's anti-alias filter, the same on every channel: 1 up to ``fs / 2.56``,
    a raised-cosine taper to 0 at ``fs / 2`` (zero phase)."""
    lo, hi = fs / 2.56, fs / 2
    u = np.clip((freq - lo) / (hi - lo), 0.0, 1.0)
    return np.asarray(0.5 * (1 + np.cos(np.pi * u)), dtype=np.float64)


def _flat_level(x: NDArray[np.float64], k: int = 3) -> NDArray[np.float64]:
    """Per row, the highest level that ``k`` consecutive samples of one sign reach: an ADC
    range just under it clips them into a flat top."""
    lo_pos = np.min(np.lib.stride_tricks.sliding_window_view(x, k, axis=-1), axis=-1)
    lo_neg = np.min(np.lib.stride_tricks.sliding_window_view(-x, k, axis=-1), axis=-1)
    return np.asarray(np.maximum(lo_pos.max(axis=-1), lo_neg.max(axis=-1)), dtype=np.float64)


def _pulse(t: NDArray[np.float64], start: float, width: float, peak: float,
           ) -> NDArray[np.float64]:
    """Half-sine pulse sampled at ``t``."""
    u = (t - start) / width
    return np.where((u > 0) & (u < 1), peak * np.sin(np.pi * np.clip(u, 0, 1)), 0.0)


def _sensor_errors(x: NDArray[np.float64], fs: float, rng: np.random.Generator, noise: float,
                   settling: float, drift_level: float) -> NDArray[np.float64]:
    """Responses with IEPE settling (a decaying offset from t = 0), slow drift and noise,
    each relative to the responses' median peak."""
    n_ch, n = x.shape
    t = np.arange(n) / fs
    level = float(np.median(np.max(np.abs(x), axis=1)))
    settle = (settling * level * rng.uniform(-1, 1, (n_ch, 1))
              * np.exp(-t / rng.uniform(0.2, 0.6, (n_ch, 1))))
    drift = (drift_level * level * rng.uniform(-1, 1, (n_ch, 1))
             * np.sin(2 * np.pi * rng.uniform(0.01, 0.05, (n_ch, 1)) * t
                      + rng.uniform(0, 2 * np.pi, (n_ch, 1))))
    return x + settle + drift + noise * level * rng.normal(size=x.shape)


def _force_errors(f: NDArray[np.float64], fs: float, rng: np.random.Generator, scale: float,
                  noise: float, offset: float) -> NDArray[np.float64]:
    """Force with a DC offset, a linear drift of the same size and noise (relative to
    ``scale``, N)."""
    t = np.arange(f.shape[-1]) / fs
    off = offset * scale * rng.uniform(-1, 1, (f.shape[0], 1))
    drift = offset * scale * rng.uniform(-1, 1, (f.shape[0], 1)) * t / max(t[-1], 1e-12)
    return f + off + drift + noise * scale * rng.normal(size=f.shape)


def _delays(budget: Budget, n_resp: int, fs: float, rng: np.random.Generator) -> (
    NDArray[np.float64] | None
):
    """Each response channel's skew against the force, s (None without)."""
    if not budget.skew:
        return None
    return np.asarray(rng.uniform(-budget.skew, budget.skew, n_resp) / fs, dtype=np.float64)


#: samples before a hit's start that its recorded responses already reach: the zero-phase
#: anti-alias filter's precursor (:func:`_anti_alias`) and up to a sample of channel skew
HIT_LEAD = 8


def _clipped_hits(hits: tuple[Hit, ...], full: NDArray[np.bool_], fs: float,
                  ) -> tuple[Hit, ...]:
    """``hits`` with those labelled clipped whose own samples reach a range (``full``, per
    sample): from :data:`HIT_LEAD` samples before the hit's start to as many before the
    next hit's (a sample at a range just before a hit is that hit's, not the last one's)."""
    at = [max(round(h.time * fs) - HIT_LEAD, 0) for h in hits] + [full.size]
    return tuple(replace(h, clipped=h.clipped or bool(np.any(full[a:z])))
                 for h, a, z in zip(hits, at[:-1], at[1:], strict=True))


def _apply_budget(runs: list[TimeRecording], b: Budget, fs: float,
                  rng: np.random.Generator) -> tuple[list[TimeRecording],
                                                     NDArray[np.float64] | None]:
    """The runs as the test's channels record them under ``b`` (the skew is applied when the
    responses are formed), and the response channels' input ranges (None without a
    converter or clipping); hits reaching a channel's range are labelled clipped."""
    if b == Budget():
        return runs, None
    forces, resps = [], []
    for r in runs:
        f, x = r.forces.copy(), r.responses.copy()
        rms_x = np.sqrt(np.mean(x**2, axis=1, keepdims=True))
        if b.hum:
            t = np.arange(r.n_samples) / fs
            ph = rng.uniform(0, 2 * np.pi, (x.shape[0], 3))
            x += b.hum * rms_x * sum(a * np.sin(2 * np.pi * k * b.mains_hz * t + ph[:, k - 1:k])
                                     for k, a in ((1, 1.0), (2, 0.5), (3, 0.3)))
        if b.rms_noise:
            f += (b.rms_noise * np.sqrt(np.mean(f**2, axis=1, keepdims=True))
                  * rng.normal(size=f.shape))
            x += b.rms_noise * rms_x * rng.normal(size=x.shape)
        forces.append(f)
        resps.append(x)
    n_resp = resps[0].shape[0]
    lo, hi = np.log(b.headroom)
    top_x = np.max([np.max(np.abs(x), axis=1) for x in resps], axis=0)
    top_f = max(float(np.max(np.abs(f))) for f in forces)
    range_x = top_x * np.exp(rng.uniform(lo, hi, n_resp))
    range_f = top_f * float(np.exp(rng.uniform(lo, hi)))
    for c in rng.choice(n_resp, size=min(b.clip_channels, n_resp), replace=False):
        # ranged under the test's m-th largest sample: m samples clip, in the run where the
        # channel peaks (and wherever else the test comes as near the top)
        m = int(rng.integers(b.clip_samples[0], b.clip_samples[1] + 1))
        every = np.sort(np.concatenate([np.abs(x[c]) for x in resps]))
        range_x[c] = min(range_x[c], float(every[-m]))
    out = []
    for r, f, x in zip(runs, forces, resps, strict=True):
        if b.bits is not None:  # the converter's codes, its range its last code
            lsb_x = 2 * range_x[:, None] / 2**b.bits
            x = np.round(x / lsb_x) * lsb_x
            lsb_f = 2 * range_f / 2**b.bits
            f = np.round(f / lsb_f) * lsb_f
        x = np.clip(x, -range_x[:, None], range_x[:, None])
        f = np.clip(f, -range_f, range_f)
        hits = r.hits
        if hits:  # a hammer run's: which reach a range
            full = (np.any(np.abs(x) >= range_x[:, None] * (1 - 1e-12), axis=0)
                    | np.any(np.abs(f) >= range_f * (1 - 1e-12), axis=0))
            hits = _clipped_hits(hits, full, fs)
        out.append(replace(r, forces=f, responses=x, hits=hits))
    ranged = b.bits is not None or b.clip_channels > 0
    return out, (np.asarray(range_x, dtype=np.float64) if ranged else None)


def hammer_test(scenario: Scenario, spec: HammerSpec) -> TimeTest:
    """One hammer test of ``scenario``: per excitation point one run of ``spec.hits`` hits.

    ``spec.n_double`` double hits and ``spec.n_clipped`` clipped hits are spread over
    distinct runs (at most one defect a run), at random hits; :class:`Hit` labels them.
    """
    rng = np.random.default_rng([spec.seed, 58])
    rng_b = np.random.default_rng([spec.seed, 60])  # the budget's draws: a stream of its own
    fs = _sample_rate(scenario, spec.fs)
    skew = _delays(spec.budget, scenario.sensors.nodes.size, fs, rng_b)
    system = (scenario.system if spec.damping == 1.0
              else scenario.system.with_mount_damping(spec.damping))
    tail = _tail(system)
    n_exc = scenario.forces.nodes.size
    if spec.n_double + spec.n_clipped > n_exc:
        raise ValueError(f"{spec.n_double + spec.n_clipped} defects for {n_exc} runs: at most "
                         "one a run")
    defect = np.array(["double"] * spec.n_double + ["clipped"] * spec.n_clipped
                      + [""] * (n_exc - spec.n_double - spec.n_clipped))
    rng.shuffle(defect)
    runs = []
    widths = []
    for e in range(n_exc):
        gaps = spec.spacing * rng.uniform(1 - spec.jitter, 1 + spec.jitter, spec.hits)
        lead = rng.uniform(1.0, 2.0)
        times = lead + np.concatenate([[0.0], np.cumsum(gaps[:-1])])
        n = int(np.ceil((times[-1] + gaps.max()) * fs))  # the longest gap after the last hit
        t = np.arange(n) / fs
        width = rng.uniform(0.9, 1.1, spec.hits) * 2.56 * spec.tip / fs
        peak = spec.force * rng.uniform(0.5, 1.0, spec.hits)
        which = int(rng.integers(spec.hits))
        kind = defect[e]
        if kind == "clipped":
            peak[which] = 2.0 * peak.max()
        f = np.zeros((2, n))  # row 1: the clipped hit alone (scaled below)
        for k in range(spec.hits):  # few hits: one pulse each
            f[int(kind == "clipped" and k == which)] += _pulse(
                t, times[k] + rng.uniform(0, 1 / fs), width[k], peak[k])
        if kind == "double":
            delay = width[which] * rng.uniform(2.5, 8.0)
            f[0] += _pulse(t, times[which] + delay, width[which],
                           peak[which] * rng.uniform(0.2, 0.6))
        tf0, x0 = _through(system, scenario, f[:1], np.array([e]), fs, tail, delay=skew)
        ch, scale, top = 0, 1.0, np.inf
        if kind == "clipped":  # the hit, the channel and the ADC range: a flat top of 3+
            seg = (t >= times[which]) & (t < times[which] + gaps[which])
            tf1, x1 = _through(system, scenario, f[1:], np.array([e]), fs, tail, delay=skew)
            others = np.max(np.abs(x0[:, ~seg] + x1[:, ~seg]), axis=1)
            flat = _flat_level(x0[:, seg] + x1[:, seg])
            ch = int(np.argmax(flat / others))
            scale = max(1.0, 1.2 * others[ch] / flat[ch])
            top = 0.97 * _flat_level(x0[ch:ch + 1, seg] + scale * x1[ch:ch + 1, seg])[0]
            tf0, x0 = tf0 + scale * tf1, x0 + scale * x1
            peak[which] *= scale
        true_force, x = tf0, x0
        resp = _sensor_errors(x, fs, rng, spec.noise_response, spec.settling,
                              spec.drift)
        resp[ch] = np.clip(resp[ch], -top, top)
        force = _force_errors(true_force, fs, rng, spec.force, spec.noise_force, spec.offset)
        hits = tuple(Hit(float(times[k]), float(peak[k]), float(width[k]),
                         double=kind == "double" and k == which,
                         clipped=kind == "clipped" and k == which) for k in range(spec.hits))
        runs.append(TimeRecording(e + 1, np.array([e]), force, resp, hits))
        widths.append(width)
    runs, ranges = _apply_budget(runs, spec.budget, fs, rng_b)
    return TimeTest(scenario, system, "hammer", fs, tuple(runs),
                    {"spacing": spec.spacing, "pulse_width": float(np.median(widths)),
                     "tail": tail, "damping": spec.damping}, ranges)


def _drive(kind: str, n: int, fs: float, fmax: float, spec: ShakerSpec,
           rng: np.random.Generator) -> NDArray[np.float64]:
    """One unit-RMS drive signal (n,) band-limited to ``fmax``."""
    t = np.arange(n) / fs
    if kind == "chirp":
        p = spec.period
        tau = np.mod(t, p)
        f0 = 1.0 / p
        v = np.sin(2 * np.pi * (f0 * tau + 0.5 * (fmax - f0) / p * tau**2))
        return np.asarray(v / np.sqrt(np.mean(v**2)), dtype=np.float64)
    V = scipy.fft.rfft(rng.normal(size=n))
    fr = np.fft.rfftfreq(n, 1 / fs)
    V[fr > fmax] = 0.0
    v = scipy.fft.irfft(V, n)
    if kind == "burst":
        v = v * (np.mod(t, spec.period) < spec.burst * spec.period)
    return np.asarray(v / np.sqrt(np.mean(v**2)), dtype=np.float64)


def shaker_test(scenario: Scenario, spec: ShakerSpec) -> TimeTest:
    """One shaker test of ``scenario``: each excitation point driven once (``shakers=1``), or
    pairs of points driven together (``shakers=2``; an odd last point alone)."""
    rng = np.random.default_rng([spec.seed, 59])
    rng_b = np.random.default_rng([spec.seed, 61])  # the budget's draws: a stream of its own
    fs = _sample_rate(scenario, spec.fs)
    fmax = fs / 2.56
    skew = _delays(spec.budget, scenario.sensors.nodes.size, fs, rng_b)
    system = (scenario.system if spec.damping == 1.0
              else scenario.system.with_mount_damping(spec.damping))
    tail = _tail(system)
    n_exc = scenario.forces.nodes.size
    groups = [np.arange(i, min(i + spec.shakers, n_exc)) for i in range(0, n_exc, spec.shakers)]
    runs = []
    n = round(spec.duration * fs)
    for k, exc in enumerate(groups):
        v = np.vstack([_drive(spec.kind, n, fs, fmax, spec, rng) for _ in exc])
        if exc.size == 2:  # correlated references: part of one drive in the other
            c = spec.correlation
            v[1] = c * v[0] + np.sqrt(1 - c**2) * v[1]
        true_force, x = _through(system, scenario, spec.force * v, exc, fs, tail, spec.armature,
                                 skew)
        resp = _sensor_errors(x, fs, rng, spec.noise_response, spec.settling,
                              spec.drift)
        force = _force_errors(true_force, fs, rng, spec.force, spec.noise_force, spec.offset)
        runs.append(TimeRecording(k + 1, exc, force, resp))
    runs, ranges = _apply_budget(runs, spec.budget, fs, rng_b)
    return TimeTest(scenario, system, spec.kind, fs, tuple(runs),
                    {"tail": tail, "damping": spec.damping, "armature": spec.armature}, ranges)


# ---- UFF (dataset 164, 2411, 58/58b), written from the format's description ----

def _ds(number: int, body: bytes) -> bytes:
    return b"    -1\n" + f"{number:6d}".ljust(80).encode() + b"\n" + body + b"    -1\n"


def _dof(direction: NDArray[np.float64]) -> int:
    """UFF direction code (+-1 X, +-2 Y, +-3 Z) of a global axis with sign."""
    i = int(np.argmax(np.abs(direction)))
    if not np.isclose(abs(direction[i]), 1.0):
        raise ValueError(f"direction {direction} is not a global axis")
    return int((i + 1) * np.sign(direction[i]))


def _record58(func_id: int, load_case: int, node: int, dof: int, ref: tuple[int, int],
              fs: float, y: NDArray[np.float64], force: bool, binary: bool) -> bytes:
    """One dataset 58 (ASCII, 4E20.12) or 58b (little-endian doubles) time record, even
    abscissa from 0 s."""
    head = "    58" + (f"b{1:6d}{2:6d}{11:12d}{y.size * 8:12d}{0:6d}{0:6d}{0:12d}{0:12d}"
                       if binary else "")
    what = "Force" if force else "Acceleration"
    ids = [f"{what} {node}:{dof:+d}", "reference model", "NONE", f"load case {load_case}",
           "NONE"]
    lines = [head.ljust(80)] + [s.ljust(80) for s in ids]
    lines.append(f"{1:5d}{func_id:10d}{0:5d}{load_case:10d} {'NONE':>10s}{node:10d}{dof:4d}"
                 f" {'NONE':>10s}{ref[0]:10d}{ref[1]:4d}")
    lines.append(f"{4:10d}{y.size:10d}{1:10d}{0.0:13.5e}{1 / fs:13.5e}{0.0:13.5e}")

    def axis(kind: int, length: int, forc: int, label: str, unit: str) -> str:
        return f"{kind:10d}{length:5d}{forc:5d}{0:5d} {label:<20s} {unit:<20s}"

    lines += [axis(17, 0, 0, "Time", "s"),
              axis(13, 0, 1, "Force", "N") if force else axis(12, 1, 0, "Acceleration",
                                                              "m/s^2"),
              axis(0, 0, 0, "NONE", "NONE"), axis(0, 0, 0, "NONE", "NONE")]
    text = ("\n".join(lines) + "\n").encode("ascii")
    if binary:
        data = np.asarray(y, dtype="<f8").tobytes()
    else:
        full = y.size // 4 * 4
        rows = y[:full].reshape(-1, 4)
        data = "".join(f"{a:20.11e}{b:20.11e}{c:20.11e}{d:20.11e}\n"
                       for a, b, c, d in rows.tolist()).encode()
        if y.size > full:
            data += ("".join(f"{v:20.11e}" for v in y[full:].tolist()) + "\n").encode()
    return b"    -1\n" + text + data + b"    -1\n"


def write_uff(test: TimeTest, path: str | Path, *, binary: bool = True) -> None:
    """Write ``test`` as a UFF file: SI units (164), the reported nodes (2411), then per run
    its force record (ordinate 13) and acceleration records (12), sharing the run's load case.

    Directions are the reported global axes with sign (DOF codes +-1..3). A run with two
    forces cannot be written (a load case holds one force record): ValueError.
    """
    sc = test.scenario
    ids, xyz = sc.geometry()
    units = (f"{1:10d}{'SI':>20s}{1:10d}\n"
             + "".join(f"{v:25.16e}".replace("e", "D") for v in (1.0, 1.0, 1.0)) + "\n"
             + f"{273.15:25.16e}".replace("e", "D") + "\n").encode()
    nodes = "".join(f"{n:10d}{0:10d}{0:10d}{1:10d}\n"
                    + "".join(f"{v:25.16e}".replace("e", "D") for v in p) + "\n"
                    for n, p in zip(ids.tolist(), xyz.tolist(), strict=True)).encode()
    s_dofs = [_dof(d) for d in sc.sensors.reported_dirs]
    out = [_ds(164, units), _ds(2411, nodes)]
    func_id = 0
    for r in test.runs:
        if r.excitations.size != 1:
            raise ValueError(f"run {r.load_case} has {r.excitations.size} forces: a UFF load "
                             "case holds one force record")
        e = int(r.excitations[0])
        ref = (int(sc.forces.ids[e]), _dof(sc.forces.reported_dirs[e]))
        func_id += 1
        out.append(_record58(func_id, r.load_case, ref[0], ref[1], ref, test.fs, r.forces[0],
                             True, binary))
        for k in range(r.responses.shape[0]):
            func_id += 1
            out.append(_record58(func_id, r.load_case, int(sc.sensors.ids[k]), s_dofs[k], ref,
                                 test.fs, r.responses[k], False, binary))
    tmp = Path(f"{path}.part{os.getpid()}")
    tmp.write_bytes(b"".join(out))
    tmp.replace(path)


def good_and_bad(hits: Sequence[Hit]) -> tuple[int, int]:
    """How many hits are good and how many must be rejected (double or clipped)."""
    bad = sum(1 for h in hits if not h.good)
    return len(hits) - bad, bad
