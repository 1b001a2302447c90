"""Benchmark: sustained acquisition through each transport, and hammer hit -> updated FRF.

1. Together, for ``--duration`` s: 24 accelerometer channels at 4096 Hz over CAN FD
   (two FE-16 mocks, 16 + 8 inputs, python-can ``virtual`` bus) and the hammer at
   16384 Hz over serial (HD-1 mock on a pseudo-terminal), each read by its driver in
   0.1 s blocks. Frames sent by the mocks and received, lost samples, bad frames,
   and the CPU time of the receiving side: the drivers' reader threads plus the
   thread calling ``read_block`` (per-thread times from ``/proc/self/task``; the
   mocks' threads are not counted).
2. The same for 12 accelerations + force at 1024 Hz over socketcand (TCP, classic
   frames: python-can's socketcand client has no CAN FD).
3. Hammer hit -> updated FRF: a front end at 1024 Hz (12 accelerations + force,
   CAN FD) read in 50 ms blocks; after each hit, as soon as its 1 s record is in,
   ``processing.impact.process_impacts`` and ``merge_results`` give the averaged H1.
   Latency = time the H1 is updated - host time of the record's last sample.
4. Shaker block analysis, live and rebuilt (``app.acquire.blocks.BlockAnalysis``, the
   spectral kernel the offline path uses): ``--blocks`` blocks of 1 force + 12 and of
   1 force + 48 accelerations (``nperseg`` 2048), each judged, added and its point's
   H1 read, one block every ``--block-gap`` s as a shaker run delivers them (the
   kernel's threads go idle in between); one thread and two take turns on each block.
   Then each point rebuilt from its stored blocks (a verdict changed, a replay), one
   thread and two in turn. The sums of one and two threads are compared bit for bit.

``--only blocks`` runs part 4 alone (no mock devices).

Run: ``.venv/bin/python benchmarks/acquire.py`` (``--duration 5`` for a quick look).
The mocks run in the same process (the virtual bus works within one process only),
so on a loaded machine they compete with the drivers for the cores.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from drivers.base import AcquisitionFrontEnd, ChannelConfig
from drivers.frontend_can import CanFrontEnd
from drivers.hammer_serial import SerialHammer
from hardware_mocks.benches import get_bench
from hardware_mocks.frontend_device import FORCE, FrontEndDevice
from hardware_mocks.hammer_device import HammerDevice
from hardware_mocks.physics import BenchPhysics
from hardware_mocks.socketcand import SocketcandServer
from processing.impact import ImpactResult, ImpactSettings, merge_results, process_impacts

TICK = os.sysconf("SC_CLK_TCK")


def thread_cpu(native_ids: Sequence[int]) -> float:
    """User + system CPU seconds of this process's threads with these ids."""
    total = 0
    for tid in native_ids:
        try:
            with open(f"/proc/self/task/{tid}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += int(fields[11]) + int(fields[12])  # utime, stime (fields 14, 15)
    return total / TICK


def reader_ids(drivers: Sequence[AcquisitionFrontEnd]) -> list[int]:
    names = {f"{d.name}-reader" for d in drivers}
    return [t.native_id for t in threading.enumerate() if t.name in names and t.native_id]


def accel_channels(n: int, force_at: int | None = None) -> list[ChannelConfig]:
    chans = [ChannelConfig(f"a{i}", i, "acceleration", 10.2, range_v=5.0) for i in range(n)]
    if force_at is not None:
        chans.append(ChannelConfig("F", force_at, "force", 2.25, range_v=5.0))
    return chans


def stream(drivers: Sequence[AcquisitionFrontEnd], duration: float, block_s: float = 0.1
           ) -> tuple[float, dict[str, int]]:
    """Read every driver in turn for ``duration`` s; (receiving CPU s, samples per driver)."""
    me = threading.get_native_id()
    ids = [*reader_ids(drivers), me]
    cpu0 = thread_cpu(ids)
    got = dict.fromkeys((d.name for d in drivers), 0)
    t_end = time.monotonic() + duration
    while time.monotonic() < t_end:
        for d in drivers:
            n = round(d.fs * block_s)
            d.read_block(n, timeout=5.0)
            got[d.name] += n
    return thread_cpu(ids) - cpu0, got


def row(table: Table, transport: str, d: AcquisitionFrontEnd, dev: Any, samples: int,
        duration: float, cpu: str) -> None:
    h = d.health
    table.add_row(transport, d.name, str(len(d.channels)), f"{d.fs:g}",
                  f"{samples / duration:,.0f}", f"{dev.frames_sent:,}", f"{h.frames:,}",
                  str(h.lost_samples), str(h.bad_frames), cpu)


def concurrent(duration: float, table: Table) -> None:
    physics = BenchPhysics(get_bench("engine"))
    fe_devs = [FrontEndDevice(physics, channel=f"bench-fe{i}", wiring=[*range(12), 0, 1, 2, 3])
               for i in (1, 2)]
    hammer_dev = HammerDevice(physics, frame_len=128)
    drivers: list[AcquisitionFrontEnd] = [
        CanFrontEnd("fe1", accel_channels(16), fs=4096, bus_kwargs={
            "interface": "virtual", "channel": "bench-fe1"}),
        CanFrontEnd("fe2", accel_channels(8), fs=4096, bus_kwargs={
            "interface": "virtual", "channel": "bench-fe2"}),
        SerialHammer("hammer", hammer_dev.path, [ChannelConfig("F", 0, "force", 2.25)],
                     fs=16384),
    ]
    try:
        for d in drivers:
            d.open()
            d.start()
        stream(drivers, 0.5)  # warm up
        cpu, got = stream(drivers, duration)
        cores = f"{cpu / duration:.2f} (all three)"
        for d, dev in zip(drivers, [*fe_devs, hammer_dev], strict=True):
            row(table, "CAN FD virtual" if isinstance(d, CanFrontEnd) else "serial pty", d,
                dev, got[d.name], duration, cores)
    finally:
        for d in drivers:
            d.shutdown()
        for dev in (*fe_devs, hammer_dev):
            assert isinstance(dev, FrontEndDevice | HammerDevice)
            dev.shutdown()


def over_socketcand(duration: float, table: Table) -> None:
    physics = BenchPhysics(get_bench("engine"))
    with FrontEndDevice(physics, channel="bench-sc", wiring=[*range(12), FORCE]) as dev, \
            SocketcandServer({"can0": "bench-sc"}) as server:
        fe = CanFrontEnd("fe-sc", accel_channels(12, force_at=12), fs=1024, frame="classic",
                         bus_kwargs={"interface": "socketcand", "host": "127.0.0.1",
                                     "port": server.port, "channel": "can0"})
        try:
            fe.open()
            fe.start()
            stream([fe], 0.5)
            cpu, got = stream([fe], duration)
            row(table, "socketcand TCP (classic)", fe, dev, got[fe.name], duration,
                f"{cpu / duration:.2f}")
        finally:
            fe.shutdown()


def hit_to_frf(n_hits: int) -> list[float]:
    """Latencies (s) from each hit's last record sample to its updated averaged H1."""
    fs, record, pre = 1024, 1024, 32
    physics = BenchPhysics(get_bench("engine"))
    settings = ImpactSettings(level=20.0, record_length=record, pretrigger=pre)
    latencies: list[float] = []
    with FrontEndDevice(physics, channel="bench-hit") as dev:
        fe = CanFrontEnd("fe-hit", accel_channels(12, force_at=12), fs=fs, bus_kwargs={
            "interface": "virtual", "channel": "bench-hit"})
        try:
            fe.open()
            fe.start()
            buf = np.zeros((13, 0))
            merged: ImpactResult | None = None
            for _ in range(n_hits):
                hit = physics.hit(exc=0, peak=200.0, delay=0.2)[0]
                t_last = hit.t0 + (record - pre) / fs  # host time of the record's last sample
                while True:
                    block = fe.read_block(fs // 20, timeout=5.0)
                    buf = np.concatenate([buf, block.data], axis=1)[:, -4 * record:]
                    force = buf[12]
                    k = np.flatnonzero((force[:-1] < settings.level)
                                       & (force[1:] >= settings.level))
                    if k.size and buf.shape[1] - (k[-1] + 1 - pre) >= record:
                        start = int(k[-1]) + 1 - pre
                        rec = np.vstack([buf[12:13, start:start + record],
                                         buf[:12, start:start + record]])
                        result = process_impacts(rec, fs, settings)
                        merged = result if merged is None else merge_results([merged, result])
                        assert merged.H is not None
                        latencies.append(time.monotonic() - t_last)
                        buf = buf[:, start + record:]
                        break
            assert merged is not None and merged.n_accepted == n_hits, merged
            assert dev.frames_sent > 0
        finally:
            fe.shutdown()
    return latencies


def block_analysis(n_ch: int, n_blocks: int, gap: float, repeat: int
                   ) -> tuple[dict[int, list[float]], dict[int, list[float]], bool]:
    """Per-block live times and per-block rebuild times (s) by number of threads, and
    whether the sums of one and two threads are identical."""
    from app.acquire.blocks import BlockAnalysis
    from app.mockbench.bench import plan_for_bench

    nps = 2048
    plan = plan_for_bench("engine-rigid", points=[0], fs=1024.0, method="shaker", shaker={
        "waveform": "random", "nperseg": nps, "averages": n_blocks})
    rng = np.random.default_rng(0)
    blocks = [rng.standard_normal((n_ch, nps)) for _ in range(n_blocks)]
    names = [f"c{i}" for i in range(n_ch)]
    anas = {w: BlockAnalysis(plan, names, None, workers=w,
                             loader=lambda ids: ((i, blocks[i]) for i in ids)) for w in (1, 2)}
    for a in anas.values():  # kernels loaded, threads started
        a.warm_up()
    live: dict[int, list[float]] = {1: [], 2: []}
    for i, b in enumerate(blocks):
        for w in ((1, 2) if i % 2 else (2, 1)):
            time.sleep(gap)
            t0 = time.perf_counter()
            v = anas[w].add(i, 0, b)
            anas[w].set_used(i, v is not None and v[0])
            res = anas[w].point(0)
            live[w].append(time.perf_counter() - t0)
            assert res is not None and res.n_accepted == i + 1
    rebuild: dict[int, list[float]] = {1: [], 2: []}
    sums = {}
    for k in range(repeat):
        for w in ((1, 2) if k % 2 else (2, 1)):
            time.sleep(gap)
            t0 = time.perf_counter()
            res = anas[w].point(0, max_averages=n_blocks)
            rebuild[w].append((time.perf_counter() - t0) / n_blocks)
            assert res is not None
            sums[w] = res.spectra
    same = all(np.array_equal(getattr(sums[1], f), getattr(sums[2], f))
               for f in ("Sff", "Sfx", "Sxx"))
    return live, rebuild, same


def print_block_analysis(console: Console, n_blocks: int, gap: float, repeat: int) -> None:
    t = Table(title=f"Shaker block analysis: {n_blocks} blocks of 2048 samples, one every "
                    f"{gap:g} s; ms per block, median (95th percentile)")
    for col in ("channels", "live, 1 thread", "live, 2 threads", "2/1",
                "rebuild, 1 thread", "rebuild, 2 threads", "2/1 ", "identical sums"):
        t.add_column(col, justify="right")
    for n_ch in (13, 49):
        live, rebuild, same = block_analysis(n_ch, n_blocks, gap, repeat)
        lv = {w: np.array(v) * 1e3 for w, v in live.items()}
        rb = {w: np.array(v) * 1e3 for w, v in rebuild.items()}
        t.add_row(str(n_ch),
                  *(f"{np.median(lv[w]):.2f} ({np.percentile(lv[w], 95):.2f})" for w in (1, 2)),
                  f"{np.median(lv[2]) / np.median(lv[1]):.2f}",
                  *(f"{np.median(rb[w]):.2f} ({np.percentile(rb[w], 95):.2f})" for w in (1, 2)),
                  f"{np.median(rb[2]) / np.median(rb[1]):.2f}", "yes" if same else "NO")
    console.print(t)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per rate test")
    parser.add_argument("--hits", type=int, default=8, help="hits for the latency test")
    parser.add_argument("--blocks", type=int, default=40,
                        help="shaker blocks for the block-analysis test")
    parser.add_argument("--block-gap", type=float, default=0.05,
                        help="s between blocks in the block-analysis test")
    parser.add_argument("--repeat", type=int, default=5, help="rebuilds per thread count")
    parser.add_argument("--only", choices=("blocks",), help="run one part alone")
    args = parser.parse_args()
    console = Console(width=170)
    load = os.getloadavg()
    console.print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} "
                  f"{load[2]:.2f} at start (shared machine: other processes compete)")
    if args.only == "blocks":
        print_block_analysis(console, args.blocks, args.block_gap, args.repeat)
        return
    table = Table(title=f"Sustained acquisition, {args.duration:g} s")
    for col in ("transport", "device", "channels", "fs Hz", "samples/s per ch",
                "frames sent", "frames received", "lost samples", "bad frames",
                "receiving CPU, cores"):
        table.add_column(col, justify="left" if col in ("transport", "device") else "right")
    concurrent(args.duration, table)
    over_socketcand(args.duration, table)
    console.print(table)
    lat = np.array(hit_to_frf(args.hits)) * 1000
    t2 = Table(title=f"Hammer hit -> averaged H1 updated ({args.hits} hits, 1 s records, "
                     f"1024 Hz, 13 channels, CAN FD, 50 ms reads)")
    for col in ("median ms", "max ms", "min ms", "target ms"):
        t2.add_column(col, justify="right")
    t2.add_row(f"{np.median(lat):.1f}", f"{lat.max():.1f}", f"{lat.min():.1f}", "100")
    console.print(t2)
    print_block_analysis(console, args.blocks, args.block_gap, args.repeat)


if __name__ == "__main__":
    main()
