"""The bootstrap over hits / blocks against the real scatter of independent tests, and its cost.

Calibration: one reference scenario (``hardware_mocks/reference/scenarios.py``, stiff body on
viscous mounts, 6 excitation points, 3 triaxial sensors) is measured many times as time data
by the independent generator (``hardware_mocks/reference/timedata.py``): a hammer test (5 hits
a point) or a continuous-random shaker test, each seed a new test (new hits, new noise). Each
test is processed with fixed settings (trigger, record, Welch segments), identified in fixed
bands (those the first test chooses), and bootstrapped (:func:`processing.identify.
bootstrap_identify`). For each number (mass, CoG, moments about the CoG, K's diagonal) the
ratio of a test's bootstrap std to the std of the estimate over all the tests says whether
the bootstrap measures the real spread: median and quartiles of the ratio over tests. The
fit's covariance std (``fit``'s uncertainty without the bootstrap) is given beside it.

Cost: ``fit`` with the default uncertainty (covariance part) against the same with the
bootstrap of 200 resamples, best of repeats, on the first test of each kind.

Run: ``.venv/bin/python benchmarks/bootstrap.py [--tests 40] [--kind hammer|shaker|both]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario  # noqa: E402
from hardware_mocks.reference.timedata import (  # noqa: E402
    HammerSpec,
    ShakerSpec,
    hammer_test,
    shaker_test,
)
from processing.bootstrap import Bootstrap  # noqa: E402
from processing.data import FRFSet, Geometry  # noqa: E402
from processing.identify import IdentifyOptions, bootstrap_identify, fit  # noqa: E402
from processing.impact import ImpactSettings, merge_results, process_impacts  # noqa: E402
from processing.measurement import Measurement, Provenance  # noqa: E402
from processing.spectral import SpectralAccumulator, frf  # noqa: E402
from processing.uncertainty import derived_of_draws  # noqa: E402
from processing.units import TimeUnits, welch_units  # noqa: E402

#: the numbers compared: (label, key, index)
QUANTITIES: tuple[tuple[str, str, tuple[int, ...]], ...] = (
    ("mass", "mass", ()), ("cog x", "cog", (0,)), ("cog z", "cog", (2,)),
    ("J_xx (CoG)", "inertia_cog", (0, 0)), ("J_zz (CoG)", "inertia_cog", (2, 2)),
    ("K_xx", "stiffness", (0, 0)), ("K_zz", "stiffness", (2, 2)),
    ("K_rxrx", "stiffness", (3, 3)),
)


def scenario() -> Scenario:
    """The reference scenario every test measures."""
    return build_scenario(ScenarioSpec(seed=3, n_forces=6, n_sensors=3, elastic_ratio=None,
                                       damping="viscous"))


def _measurement(sc: Scenario, freq: np.ndarray, H: list[np.ndarray], coh: list[np.ndarray],
                 units: TimeUnits, tau: float | None) -> Measurement:
    """The FRFs estimated from time records, with their per-hit or per-block spectra."""
    ids, xyz = sc.geometry()
    keep = freq > 0
    frf = FRFSet(freq[keep], np.concatenate(H, axis=1)[..., keep], sc.sensors.ids,
                 sc.sensors.reported_dirs, sc.forces.ids, sc.forces.reported_dirs,
                 Geometry(ids, xyz), np.concatenate(coh, axis=1)[..., keep])
    return Measurement(frf, Provenance(origin="estimated", units=units, exponential_tau=tau))


def hammer_frfs(sc: Scenario, seed: int, hits: int = 5, clean: bool = False,
                ) -> Measurement:
    """A hammer test of ``sc`` (seed ``seed``) processed with fixed settings: trigger 20 N,
    2 s records, 10 ms pre-trigger, no exponential window (mounts damped x3: the responses
    have decayed), H1 over the accepted hits, per-hit spectra kept. ``clean``: no force
    offset, response drift or IEPE settling (white noise only)."""
    slow = {"offset": 0.0, "drift": 0.0, "settling": 0.0} if clean else {}
    t = hammer_test(sc, HammerSpec(seed=seed, hits=hits, spacing=3.0, damping=3.0,
                                   noise_force=1e-3, noise_response=1e-3, **slow))
    settings = ImpactSettings(level=20.0, record_length=round(2.0 * t.fs),
                              pretrigger=round(0.01 * t.fs))
    cols = []
    for r in t.runs:
        res = merge_results([process_impacts(np.vstack([r.forces, r.responses]), t.fs,
                                             settings, keep_units=True)])
        assert res.H is not None and res.coherence is not None and res.units is not None
        cols.append(res)
    units = TimeUnits("hit", tuple(c.units for c in cols if c.units is not None),
                      sc.forces.ids, sc.forces.reported_dirs)
    return _measurement(sc, cols[0].freq, [c.H for c in cols if c.H is not None],
                   [c.coherence for c in cols if c.coherence is not None], units, None)


def shaker_frfs(sc: Scenario, seed: int, duration: float = 40.0, clean: bool = False,
                ) -> Measurement:
    """A continuous-random shaker test of ``sc`` processed by Welch (1024-sample Hann
    segments, half overlap), H1, blocks of segments kept (:func:`welch_units`). ``clean``:
    as :func:`hammer_frfs`."""
    slow = {"offset": 0.0, "drift": 0.0, "settling": 0.0} if clean else {}
    t = shaker_test(sc, ShakerSpec(seed=seed, kind="random", duration=duration, damping=3.0,
                                   **slow))
    H, coh, parts = [], [], []
    for r in t.runs:
        sp, u = welch_units(SpectralAccumulator(t.fs, 1024), np.vstack([r.forces, r.responses]))
        assert u is not None
        h, c = frf(sp)
        H.append(h)
        coh.append(c)
        parts.append(u)
    units = TimeUnits("block", tuple(parts), sc.forces.ids, sc.forces.reported_dirs)
    return _measurement(sc, sp.freq, H, coh, units, None)


def _value(v: dict[str, np.ndarray], key: str, idx: tuple[int, ...]) -> np.ndarray:
    return v[key][(slice(None), *idx)]


def calibrate(kind: str, tests: int, resamples: int = 200, clean: bool = False,
              ) -> dict[str, Any]:
    """Per quantity: the std of the estimate over ``tests`` independent tests, and the median
    and quartiles over tests of (bootstrap std / that std) and (covariance std / that std)."""
    sc = scenario()

    def make(s: int) -> Measurement:
        return (hammer_frfs if kind == "hammer" else shaker_frfs)(sc, s, clean=clean)

    first = fit(make(0), IdentifyOptions(bootstrap=0))
    opt = IdentifyOptions(mass_band=first.mass_band, stiffness_band=first.stiffness_band)
    est, boot, cov = [], [], []
    for s in range(tests):
        frfs = make(s)
        fitted, b = bootstrap_identify(frfs, opt, resamples, seed=s)
        assert isinstance(b, Bootstrap), b
        est.append(derived_of_draws(fitted.theta[None], fitted.K[None], fitted.C[None]))
        bv = b.values()
        boot.append({k: np.std(v, axis=0, ddof=1) for k, v in bv.items()})
        u = fit(frfs, dataclasses.replace(opt, bootstrap=0)).uncertainty
        assert u is not None
        cov.append(u.std)
    out: dict[str, Any] = {"kind": kind, "tests": tests, "bands": [first.mass_band,
                                                                  first.stiffness_band]}
    for label, key, idx in QUANTITIES:
        values = np.array([_value(e, key, idx)[0] for e in est])
        spread = float(np.std(values, ddof=1))
        rb = np.array([b[key][idx] for b in boot]) / spread
        rc = np.array([c[key][idx] for c in cov]) / spread
        out[label] = {"scatter": spread, "mean": float(np.mean(values)),
                      "bootstrap": [float(x) for x in np.percentile(rb, [25, 50, 75])],
                      "covariance": [float(x) for x in np.percentile(rc, [25, 50, 75])]}
    return out


def cost(kind: str, repeats: int = 5) -> dict[str, float]:
    """CPU seconds of this process (best of ``repeats``; the machine is shared, so the wall
    clock is not the figure) of the fit without uncertainty, with the covariance part,
    and with the covariance part and 200 resamples."""
    frfs = (hammer_frfs if kind == "hammer" else shaker_frfs)(scenario(), 0)
    times = {}
    for name, opt in (("identify", IdentifyOptions(uncertainty=False)),
                      ("covariance", IdentifyOptions(bootstrap=0)),
                      ("bootstrap 200", IdentifyOptions(bootstrap=200))):
        best = np.inf
        for _ in range(repeats):
            t0 = time.process_time()
            fit(frfs, opt)
            best = min(best, time.process_time() - t0)
        times[name] = best
    times["bootstrap / identify"] = (times["bootstrap 200"] - times["covariance"]) / times[
        "identify"]
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tests", type=int, default=40)
    ap.add_argument("--kind", choices=("hammer", "shaker", "both"), default="both")
    ap.add_argument("--clean", action="store_true",
                    help="white noise only (no force offset, response drift, IEPE settling)")
    ap.add_argument("--no-cost", action="store_true", help="calibration only")
    args = ap.parse_args()
    for kind in ("hammer", "shaker") if args.kind == "both" else (args.kind,):
        if not args.no_cost:
            c = cost(kind)
            print(f"{kind}: cost " + ", ".join(f"{k} {v:.3f}" + ("" if "/" in k else " s")
                                              for k, v in c.items()))
        r = calibrate(kind, args.tests, clean=args.clean)
        print(f"{kind}{' (clean)' if args.clean else ''}: {r['tests']} tests, bands "
              f"{r['bands']}")
        print(f"  {'quantity':12s} {'scatter':>10s}  bootstrap/scatter (q25 med q75)"
              "   covariance/scatter (q25 med q75)")
        for label, _, _ in QUANTITIES:
            q = r[label]
            print(f"  {label:12s} {q['scatter']:10.4g}  "
                  + " ".join(f"{x:5.2f}" for x in q["bootstrap"]) + "         "
                  + " ".join(f"{x:5.2f}" for x in q["covariance"]))


if __name__ == "__main__":
    main()
