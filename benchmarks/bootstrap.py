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

Speed (``--speed``): the bootstrap as :func:`processing.identify.fit` runs it
(:func:`processing.bootstrap.resample`, the resamples solved as array operations) against a
plain per-resample loop kept here (:func:`reference_resample`: each resample's FRFs formed
and identified alone with the fit's own stages, :class:`processing.stages.StiffnessStep`,
:class:`processing.massline.MassLineProblem` and :func:`processing.stages.iterate`, as the
bootstrap did before), on the same resamples, taking turns, medians of the wall clock over
repeats; and how far their resamples and statistics differ. Cases: the first hammer test of
the calibration, and a run file (``--run RUN.h5``, e.g. ``insitu acquire --mock --hits 3``).

Run: ``.venv/bin/python benchmarks/bootstrap.py [--tests 40] [--kind hammer|shaker|both]``;
``.venv/bin/python benchmarks/bootstrap.py --speed [--run RUN.h5] [--repeats 5] [--out
benchmarks/results/bootstrap-speed.md]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import datetime  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from hardware_mocks.reference.scenarios import Scenario, ScenarioSpec, build_scenario  # noqa: E402
from hardware_mocks.reference.timedata import (  # noqa: E402
    HammerSpec,
    ShakerSpec,
    hammer_test,
    shaker_test,
)
from processing.bootstrap import (  # noqa: E402
    Bootstrap,
    about_the_data,
    resample,
    resampled_frfs,
    weighted_accelerances,
)
from processing.data import FRFSet, Geometry  # noqa: E402
from processing.identify import IdentifyOptions, Stages, bootstrap_identify, fit, stages  # noqa: E402
from processing.impact import ImpactSettings, merge_results, process_impacts  # noqa: E402
from processing.inertia import mass_matrix  # noqa: E402
from processing.massline import MassLineProblem, stack_real  # noqa: E402
from processing.measurement import Measurement, Provenance  # noqa: E402
from processing.physical import constrain_physical  # noqa: E402
from processing.spectral import SpectralAccumulator, frf  # noqa: E402
from processing.stages import StiffnessStep, iterate, leakage_shapes, upper_residual  # noqa: E402
from processing.stiffness import line_operators  # noqa: E402
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


def reference_resample(st: Stages, units: TimeUnits, boot: Bootstrap) -> tuple[
    np.ndarray, np.ndarray, np.ndarray
]:
    """The resamples of ``boot`` solved one at a time: each one's FRFs and accelerances
    formed alone, then the fit's iteration (:func:`processing.stages.iterate`, from the
    main fit's solution, tolerance at least 1e-9) with its lines, weights, leakage shapes
    and damping model held fixed. theta (n, 10), K, C (n, 6, 6)."""
    problem, bands, weights, fitted = st.problem, st.bands, st.weights, st.fitted
    used = weights.mass_lines | weights.stiffness_lines
    idx = np.flatnonzero(used)
    mass = np.isin(idx, np.flatnonzero(weights.mass_lines))
    stiff = np.isin(idx, np.flatnonzero(weights.stiffness_lines))
    msel, ins = weights.mass_lines, bands.in_stiffness
    modelled = fitted.mass_line is not None and fitted.mass_line.shapes is not None
    shapes = (leakage_shapes(problem, bands) or [upper_residual(problem.w)]) if modelled else []
    stacked = np.array([stack_real(sh[msel]) for sh in shapes]) if shapes else None
    solver = dataclasses.replace(problem.solver, tol=max(problem.solver.tol, 1e-9))
    counts = np.split(boot.counts, np.cumsum(boot.units)[:-1], axis=1)
    nominal = resampled_frfs(units, problem.freq[used], [np.ones((1, c.shape[1]))
                                                          for c in counts])
    assert nominal is not None
    out = []
    for r in range(boot.n):  # one resample at a time
        drawn = resampled_frfs(units, problem.freq[used], [c[r:r + 1] for c in counts])
        assert drawn is not None
        X, colw = weighted_accelerances(problem, used,
                                        *about_the_data(problem, used, nominal, drawn))
        Xb = problem.X.copy()
        Xb[..., used] = np.transpose(X[0], (1, 2, 0))
        wb = dataclasses.replace(weights, mass=colw[0][..., mass] * (weights.mass > 0),
                                 stiffness=colw[0][..., stiff] * (weights.stiffness > 0))
        pb = dataclasses.replace(problem, X=Xb, solver=solver)
        ops = (fitted.operators if problem.improved
               else line_operators(Xb[..., ins], problem.T, problem.w[ins]))
        step = StiffnessStep(pb, wb, ops, wb.stiffness_lines[ins])
        step.model = fitted.damping_model
        ml = MassLineProblem(Xb[..., msel], weights=wb.mass, row_scale=problem.row_scale,
                             shapes=stacked)
        _, theta, K, C, _D, Xc, _, _ = iterate(pb, wb, ml, step, shapes,
                                               (fitted.theta, step.lines))
        if problem.options.physical:
            theta = constrain_physical(theta, ml.normal)
            K, C, _D = step(mass_matrix(theta), Xc)
        out.append((theta, K, C))
    return tuple(np.array([o[k] for o in out]) for k in range(3))  # type: ignore[return-value]


def _statistics(theta: np.ndarray, K: np.ndarray, C: np.ndarray) -> dict[str, np.ndarray]:
    """Std and 2.5 / 97.5 percentiles over the resamples of every derived number."""
    out = {}
    for k, v in derived_of_draws(theta, K, C).items():
        out[f"std {k}"] = np.std(v, axis=0, ddof=1)
        out[f"q {k}"] = np.percentile(v, [2.5, 97.5], axis=0)
    return out


def speed(m: Measurement, n: int = 200, repeats: int = 5) -> dict[str, Any]:
    """Wall-clock medians over ``repeats`` (taking turns) of the bootstrap's ``n``
    resamples, vectorised and by the reference loop, the same resamples (seed 0), and the
    largest differences of their resamples and statistics (relative to each number's
    largest magnitude over the resamples)."""
    st = stages(m, IdentifyOptions())
    units = m.time_units
    assert units is not None
    times: dict[str, list[float]] = {"vectorised": [], "reference loop": []}
    boot = ref = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        boot = resample(st.problem, st.bands, st.weights, st.fitted, units, n)
        times["vectorised"].append(time.perf_counter() - t0)
        assert isinstance(boot, Bootstrap), boot
        t0 = time.perf_counter()
        ref = reference_resample(st, units, boot)
        times["reference loop"].append(time.perf_counter() - t0)
    assert isinstance(boot, Bootstrap) and ref is not None
    diff = {}
    for name, a, b in (("theta", boot.theta, ref[0]), ("K", boot.K, ref[1]),
                       ("C", boot.C, ref[2])):
        diff[f"resamples {name}"] = float(np.max(np.abs(a - b)) / np.max(np.abs(b)))
    got, want = _statistics(boot.theta, boot.K, boot.C), _statistics(*ref)
    diff["statistics"] = max(float(np.max(np.abs(got[k] - want[k])) / max(
        float(np.max(np.abs(want[k]))), 1e-300)) for k in want)
    med = {k: float(np.median(v)) for k, v in times.items()}
    shapes = st.fitted.mass_line is not None and st.fitted.mass_line.shapes is not None
    return {"times": med, "ratio": med["reference loop"] / med["vectorised"], "diff": diff,
            "path": "iterated (leakage shapes)" if shapes else "affine (no leakage shapes)",
            "size": f"{m.frf.H.shape[0]} x {m.frf.H.shape[1]} FRFs, "
                    f"{min(boot.units)}-{max(boot.units)} {boot.kind}s a point"}


def speed_report(run: Path | None, repeats: int, n: int = 200) -> str:
    """The speed comparison of each case, as markdown."""
    cases: list[tuple[str, Measurement]] = [
        ("reference scenario, hammer test 0 (5 hits a point)", hammer_frfs(scenario(), 0))]
    if run is not None:
        from app.pipeline import RUN_FILE, load

        cases.append((f"run file {run.name}", load(run, fmt=RUN_FILE)))
    load1, load5, _ = os.getloadavg()
    lines = [f"`benchmarks/bootstrap.py --speed{' --run ' + str(run) if run else ''} "
             f"--repeats {repeats}`, {datetime.date.today().isoformat()}, "
             f"{platform.machine()} {os.cpu_count()} cores, load average "
             f"{load1:.2f} (1 min) {load5:.2f} (5 min) at the end, one BLAS thread",
             "", "```"]
    for label, m in cases:
        r = speed(m, n, repeats)
        t = r["times"]
        lines += [f"{label}: {r['size']}, {r['path']}, {n} resamples",
                  f"  vectorised {t['vectorised']:.3f} s, reference loop "
                  f"{t['reference loop']:.3f} s (medians of {repeats}, taking turns): "
                  f"{r['ratio']:.1f}x",
                  "  largest relative difference: " + ", ".join(
                      f"{k} {v:.1e}" for k, v in r["diff"].items())]
    load1, load5, _ = os.getloadavg()
    lines[0] = lines[0].rsplit(", load", 1)[0] + (
        f", load average {load1:.2f} (1 min) {load5:.2f} (5 min) at the end, one BLAS thread")
    return "\n".join([*lines, "```", ""])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tests", type=int, default=40)
    ap.add_argument("--kind", choices=("hammer", "shaker", "both"), default="both")
    ap.add_argument("--clean", action="store_true",
                    help="white noise only (no force offset, response drift, IEPE settling)")
    ap.add_argument("--no-cost", action="store_true", help="calibration only")
    ap.add_argument("--speed", action="store_true",
                    help="vectorised bootstrap against the per-resample loop only")
    ap.add_argument("--run", type=Path, help="with --speed: a run file as a further case")
    ap.add_argument("--repeats", type=int, default=5, help="with --speed: repeats")
    ap.add_argument("--out", type=Path, help="with --speed: also write the output here")
    args = ap.parse_args()
    if args.speed:
        text = speed_report(args.run, args.repeats)
        print(text)
        if args.out is not None:
            args.out.write_text(text)
        return
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
