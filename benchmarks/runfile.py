"""Cost of the run file's durability policy: each record written, fsync'd and the file closed.

Reference: the file held open for the whole run and flushed (no fsync) after each record,
the policy before, under which a crash left a file that HDF5 tools refused. Both write the
same records (an engine test's hit: 13 channels x 2088 samples) into fresh files.

    .venv/bin/python benchmarks/runfile.py [--records 100]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
from rich.console import Console
from rich.table import Table

from app.io.runfile import RunWriter
from drivers.base import ChannelConfig
from processing.data import Geometry

N_CH, N_S = 13, 2088


def _writer(path: Path) -> RunWriter:
    chans = [ChannelConfig("F", 0, "force", 2.25)] + [
        ChannelConfig(f"a{k}", k, "acceleration", 10.0, node=1, direction=(1.0, 0.0, 0.0))
        for k in range(1, N_CH)]
    return RunWriter.create(path, plan_data={}, station_data={}, channels=chans,
                            devices=["fe"] * N_CH, geometry=Geometry(np.array([1]),
                                                                     np.zeros((1, 3))),
                            fs=1024.0, n_samples=N_S, method="hammer")


def ours(path: Path, records: np.ndarray) -> list[float]:
    w = _writer(path)
    times = []
    for i, rec in enumerate(records):
        t = time.perf_counter()
        w.add_record(i, rec, time=float(i), peak_force=1.0, auto_accepted=True, reason="")
        times.append(time.perf_counter() - t)
    w.finish("finished")
    return times


def held_open(path: Path, records: np.ndarray) -> list[float]:
    """The reference: one SWMR session for the run, a flush per record."""
    _writer(path).close()
    times = []
    with h5py.File(path, "a", libver="latest") as f:
        f.swmr_mode = True
        rec = f["records"]
        for i, r in enumerate(records):
            t = time.perf_counter()
            rec["data"].resize(i + 1, axis=0)
            rec["data"][i] = r
            for name in ("point", "time", "peak_force", "auto_accepted", "override"):
                rec[name].resize(i + 1, axis=0)
                rec[name][i] = i
            f.flush()
            times.append(time.perf_counter() - t)
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=int, default=100)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    records = rng.standard_normal((args.records, N_CH, N_S))
    table = Table(title=f"run file: {args.records} records of {N_CH} x {N_S} samples")
    for col in ("policy", "median ms/record", "95th pct ms", "max ms"):
        table.add_column(col)
    with tempfile.TemporaryDirectory() as d:
        for name, fn in (("held open, flush (reference)", held_open),
                         ("open, write, fsync, close (ours)", ours)):
            ms = 1e3 * np.array(fn(Path(d) / f"{fn.__name__}.h5", records))
            table.add_row(name, f"{np.median(ms):.2f}", f"{np.percentile(ms, 95):.2f}",
                          f"{ms.max():.2f}")
    Console().print(table)


if __name__ == "__main__":
    main()
