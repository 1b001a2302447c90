"""A plain processing of time records, written independently: the baseline the time-data
benchmark holds insitu's defaults against (numpy and scipy only, nothing from
``processing/``).

What an engineer's script does with the same samples, then the article's method with its
band rule (:mod:`hardware_mocks.reference.article`, the system's own rigid-body and elastic
frequencies):

- hammer: every hit averaged (none rejected); each hit's segment from 10 ms before its
  pulse, all segments of a test the same length, the shortest spacing between hits; a
  50 ms rectangular force window; the responses rectangular when they have rung down
  within the segment (the RMS of its last tenth under 1 % of the peak), else an exponential
  window on force and responses that ends at 1 % (the damping it adds left in); H1 over
  the hits of a point; lines up to fs / 2.56 (the converters' anti-alias band);
- shaker: Welch's H1, 2048-sample Hann segments, half overlapping, over the whole record.

Example
-------
>>> from hardware_mocks.reference.scenarios import ScenarioSpec, build_scenario  # doctest: +SKIP
>>> t = hammer_test(build_scenario(ScenarioSpec(seed=1)), HammerSpec(seed=1))  # doctest: +SKIP
>>> plain_identify(t).theta[0]  # doctest: +SKIP
"""

from __future__ import annotations

import numpy as np
import scipy.signal
from numpy.typing import NDArray

from hardware_mocks.reference.article import ArticleResult, article_bands, article_identify
from hardware_mocks.reference.timedata import TimeTest

__all__ = ["ANTI_ALIAS", "FORCE_WINDOW", "PRE_TRIGGER", "WELCH_SEGMENT", "plain_frfs",
           "plain_identify"]

#: s kept before each hit's pulse
PRE_TRIGGER = 0.01
#: s of the rectangular force window from the segment's start
FORCE_WINDOW = 0.05
#: a response has rung down when the RMS of its segment's last tenth is under this x its peak
RUNG_DOWN = 0.01
#: the lines are used up to fs / this (the converters' anti-alias band)
ANTI_ALIAS = 2.56
#: samples of a Welch segment (shaker tests)
WELCH_SEGMENT = 2048


def plain_frfs(t: TimeTest) -> tuple[NDArray[np.float64], NDArray[np.complex128]]:
    """Lines (Hz) and H1 accelerances (n_resp, n_exc, n_f) of every force of the test."""
    n_exc = t.scenario.forces.nodes.size
    if t.kind == "hammer":
        return _hammer(t, n_exc)
    return _welch(t, n_exc)


def plain_identify(t: TimeTest) -> ArticleResult:
    """The article's method with its band rule on :func:`plain_frfs` (ArticleRefusalError
    when it refuses)."""
    freq, H = plain_frfs(t)
    sc = t.scenario
    keep = (freq > 0) & (freq <= t.fs / ANTI_ALIAS)
    freq = freq[keep]
    mass, stiff = article_bands(freq, float(t.system.natural_frequencies_hz()[5]),
                                float(t.system.first_elastic_hz()))
    return article_identify(freq, H[..., keep], sc.sensors.reported_xyz,
                            sc.sensors.reported_dirs, sc.forces.reported_xyz,
                            sc.forces.reported_dirs, mass, stiff)


def _hammer(t: TimeTest, n_exc: int) -> tuple[NDArray[np.float64], NDArray[np.complex128]]:
    fs = t.fs
    pre = round(PRE_TRIGGER * fs)
    starts = [[max(round(h.time * fs) - pre, 0) for h in r.hits] for r in t.runs]
    ends = [[*s[1:], r.n_samples] for s, r in zip(starts, t.runs, strict=True)]
    n = min(e - s for ss, es in zip(starts, ends, strict=True)
            for s, e in zip(ss, es, strict=True))
    force_win = (np.arange(n) < round(FORCE_WINDOW * fs)).astype(float)
    n_resp = t.runs[0].responses.shape[0]
    Sfx = np.zeros((n_resp, n_exc, n // 2 + 1), complex)
    Sff = np.zeros((n_exc, n // 2 + 1))
    for r, ss in zip(t.runs, starts, strict=True):
        seg = np.array(ss)[:, None] + np.arange(n)  # (n_hits, n)
        f = r.forces[0][seg] * force_win  # (n_hits, n)
        x = r.responses[:, seg]  # (n_resp, n_hits, n)
        tail = x[..., -max(n // 10, 1):]
        ringing = np.sqrt(np.mean(tail**2, axis=-1)) > RUNG_DOWN * np.max(np.abs(x), axis=-1)
        expo = np.exp(np.log(RUNG_DOWN) * np.arange(n) / n)
        win = np.where(np.any(ringing, axis=0)[:, None], expo, 1.0)  # (n_hits, n)
        F = np.fft.rfft(f * win, axis=-1)
        X = np.fft.rfft(x * win, axis=-1)
        for e in r.excitations:
            Sfx[:, e] += np.sum(np.conj(F)[None] * X, axis=1)
            Sff[e] += np.sum(np.abs(F) ** 2, axis=0)
    return np.fft.rfftfreq(n, 1 / fs).astype(np.float64), np.asarray(Sfx / Sff[None])


def _welch(t: TimeTest, n_exc: int) -> tuple[NDArray[np.float64], NDArray[np.complex128]]:
    fs = t.fs
    n_resp = t.runs[0].responses.shape[0]
    nper = min(WELCH_SEGMENT, min(r.n_samples for r in t.runs))
    Sfx = np.zeros((n_resp, n_exc, nper // 2 + 1), complex)
    Sff = np.zeros((n_exc, nper // 2 + 1))
    freq = np.fft.rfftfreq(nper, 1 / fs)
    for r in t.runs:
        f = r.forces[0]
        freq, Pfx = scipy.signal.csd(f[None], r.responses, fs, window="hann", nperseg=nper,
                                     noverlap=nper // 2)
        _, Pff = scipy.signal.welch(f, fs, window="hann", nperseg=nper, noverlap=nper // 2)
        for e in r.excitations:
            Sfx[:, e] += Pfx
            Sff[e] += Pff
    return np.asarray(freq, dtype=np.float64), np.asarray(Sfx / Sff[None])
