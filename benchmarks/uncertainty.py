"""Cost of the uncertainty: the covariance part against the plain identification, and the
Monte Carlo of stated test uncertainties (1,000 draws), in the same run.

Cases: the built-in engine bench (1 % noise, +-2 mm location errors) and the largest
scenarios of the reference suite (6 triaxial sensors, 24 forces). Per case: the median of
``--repeat`` runs of ``identify`` without the uncertainty, with the covariance part (the
default), and the draws alone (:func:`processing.montecarlo.simulate` on the fit's model,
model building included). BLAS single-threaded (as the CLI runs on a loaded 2-core
machine); the draws run in one process.

Run: ``.venv/bin/python benchmarks/uncertainty.py [--draws 1000] [--repeat 5]``
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from hardware_mocks.benches import get_bench  # noqa: E402
from hardware_mocks.reference.scenarios import Scenario, build_scenario, suite  # noqa: E402
from processing import identify as idm  # noqa: E402
from processing.data import FRFSet, Geometry, InputError  # noqa: E402
from processing.measurement import Measurement  # noqa: E402
from processing.montecarlo import StatedUncertainty, simulate  # noqa: E402
from processing.problem import IdentifyOptions  # noqa: E402
from processing.stages import monte_carlo_model  # noqa: E402


def frfset_of(sc: Scenario) -> FRFSet:
    """The scenario's measured FRFs as an FRFSet (reported geometry)."""
    ids, xyz = sc.geometry()
    return FRFSet(freq=sc.freq, H=sc.H, resp_nodes=sc.sensors.ids,
                  resp_dirs=sc.sensors.reported_dirs, exc_nodes=sc.forces.ids,
                  exc_dirs=sc.forces.reported_dirs, geometry=Geometry(ids, xyz),
                  coherence=sc.coherence)


def _median_time(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def cases() -> list[tuple[str, FRFSet]]:
    """(name, FRF set) of the benchmark's cases."""
    out = [("engine bench, 1 % noise, 2 mm", get_bench("engine").frfset(0.01, 0.002, seed=1))]
    big = [s for s in suite(200, 2026) if s.n_sensors == 6 and s.n_forces >= 20]
    kept = 0
    for spec in big:  # the first two the identification answers
        spec = replace(spec, elastic_ratio=8.0)
        frf = frfset_of(build_scenario(spec))
        try:
            idm.identify(frf, IdentifyOptions(uncertainty=False))
        except InputError as err:
            print(f"scenario {spec.name} skipped: {err}")
            continue
        out.append((f"scenario {spec.name} ({3 * spec.n_sensors} ch x {spec.n_forces} exc, "
                    f"{spec.n_lines} lines)", frf))
        kept += 1
        if kept == 2:
            break
    return out


def draws_time(frf: FRFSet, stated: StatedUncertainty, repeat: int) -> float:
    """Median seconds of building the Monte Carlo model of the fit and running the draws."""
    st = idm.stages(Measurement(frf), IdentifyOptions(uncertainty=False))  # the fit's stages

    def run() -> None:
        simulate(monte_carlo_model(st.problem, st.weights, st.fitted,
                                   (frf.resp_nodes, frf.exc_nodes)), stated)

    return _median_time(run, repeat)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--draws", type=int, default=1000)
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args(argv)
    stated = StatedUncertainty(location=0.002, angle=np.deg2rad(1.0), gain=0.01,
                               draws=args.draws)
    print(f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"load {os.getloadavg()[0]:.1f}")
    for name, frf in cases():
        def plain(f: FRFSet = frf) -> object:
            return idm.identify(f, IdentifyOptions(uncertainty=False))

        def with_cov(f: FRFSet = frf) -> object:
            return idm.identify(f)

        t_plain = _median_time(plain, args.repeat)
        t_cov = _median_time(with_cov, args.repeat)
        t_mc = draws_time(frf, stated, args.repeat)
        print(f"{name}: identify {t_plain:.3f} s, with covariance {t_cov:.3f} s "
              f"({t_cov / t_plain:.2f}x); Monte Carlo {args.draws} draws {t_mc:.2f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
