"""Campaigns and Monte Carlo on Dask distributed: 1 worker against 2 (local cluster).

- campaign: ``N_FILES`` UFF files of the built-in ``engine-rigid`` bench (1 % noise, seeds
  0..N-1, 18 forces x 12 responses x 1024 lines each) identified with the defaults of
  ``insitu identify`` by :func:`app.batch.campaign.run_campaign`, as ``insitu batch`` does;
- Monte Carlo: ``N_DRAWS`` draws of :class:`app.batch.montecarlo.MassLineDraw` (the plain
  mass-line estimate of the ten parameters over the 60-120 Hz lines with the response points
  moved by 2 mm standard deviation) by :func:`app.batch.montecarlo.map_draws`.

Each configuration starts its own local cluster (worker processes, one thread each); the
start (cluster up and every worker having imported the identification) is timed apart from
the work. The machine's load average is printed with the numbers.

Run: ``.venv/bin/python benchmarks/batch.py [N_FILES] [N_DRAWS]`` (default 50 and 10000).
"""

from __future__ import annotations

import importlib
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from app.batch.campaign import run_campaign
from app.batch.cluster import open_client
from app.batch.montecarlo import MassLineDraw, chunk_draws, map_draws
from app.io.uff import write_frf_uff
from app.pipeline import Settings
from hardware_mocks.benches import get_bench
from processing.identify import IdentifyOptions
from processing.inertia import inertia_properties

N_FILES = 50
N_DRAWS = 10_000
WORKERS = (1, 2)


def _warm() -> bool:
    """Import what a task needs (run once on every worker before timing)."""
    for name in ("app.batch.campaign", "app.batch.montecarlo"):
        importlib.import_module(name)
    return True


def campaign_files(folder: Path, n: int) -> list[Path]:
    bench = get_bench("engine-rigid")
    paths = []
    for seed in range(n):
        p = folder / f"engine_{seed:03d}.uff"
        write_frf_uff(p, bench.frfset(noise=0.01, seed=seed))
        paths.append(p)
    return paths


def mass_line_draw() -> MassLineDraw:
    frf = get_bench("engine-rigid").frfset()
    k = (frf.freq >= 60) & (frf.freq <= 120)
    return MassLineDraw(frf.freq[k], frf.H[:, :, k], frf.resp_xyz, frf.resp_dirs,
                        frf.exc_xyz, frf.exc_dirs, 0.002)


def main() -> None:
    n_files = int(sys.argv[1]) if len(sys.argv) > 1 else N_FILES
    n_draws = int(sys.argv[2]) if len(sys.argv) > 2 else N_DRAWS
    con = Console(width=120)
    draw = mass_line_draw()
    t = time.perf_counter()
    chunk_draws(draw, np.arange(100))
    serial_draw = (time.perf_counter() - t) / 100
    table = Table(title=f"insitu batch on Dask (local cluster, {os.cpu_count()} cores)")
    for col in ("work", "workers", "cluster start (s)", "work (s)", "rate", "speed-up",
                "load before/after"):
        table.add_column(col, justify="left" if col == "work" else "right")
    results: dict[tuple[str, int], float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        files = campaign_files(Path(tmp), n_files)
        for w in WORKERS:
            load0 = os.getloadavg()[0]
            t0 = time.perf_counter()
            with open_client(None, w) as client:
                client.run(_warm)
                t_start = time.perf_counter() - t0
                t = time.perf_counter()
                rows = run_campaign(client, files, Settings(), IdentifyOptions())
                results["campaign", w] = time.perf_counter() - t
                bad = [r for r in rows if r["status"] != "ok"]
                assert not bad, bad[0]
                masses = np.array([r["mass_kg"] for r in rows])
                t = time.perf_counter()
                draws = map_draws(client, draw, n_draws)
                results["draws", w] = time.perf_counter() - t
            load1 = os.getloadavg()[0]
            for what, n, unit in (("campaign", n_files, "files/s"), ("draws", n_draws,
                                                                       "draws/s")):
                s = results[what, w]
                label = (f"{n} files" if what == "campaign"
                         else f"{n} Monte Carlo draws")
                table.add_row(label, str(w), f"{t_start:.1f}", f"{s:.1f}",
                              f"{n / s:.1f} {unit}",
                              f"{results[what, 1] / s:.2f}", f"{load0:.1f}/{load1:.1f}")
    con.print(table)
    cog = np.array([inertia_properties(th).cog for th in draws]) * 1e3
    con.print(f"campaign: mass {masses.mean():.3f} kg (spread {masses.std():.3f} kg over "
              f"{n_files} noise seeds); draws: CoG std {np.round(cog.std(axis=0), 2)} mm for "
              f"2 mm location std; one draw alone {serial_draw * 1e3:.1f} ms in this process")


if __name__ == "__main__":
    main()
