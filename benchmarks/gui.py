"""GUI streaming benchmark: frames per second and GUI-thread latency with 25 channels.

The Station view's level meters and traces (:class:`app.gui.views.levels.LevelsWidget`)
are fed by a :class:`app.gui.streaming.StreamThread`, exactly as in the application, and
measured for ``--seconds``:

- frames per second: ticks of the redraw timer, the redraws among them that drew new data
  (the figure that counts: a tick with no new block draws nothing), and paint events of
  the traces' viewport;
- block-to-screen latency: from the moment the stream thread got a block to its redraw;
- GUI-thread latency: lateness of a 10 ms probe timer (how long the event loop is blocked);
- samples drawn against samples streamed (nothing may be dropped).

Sources: ``synthetic`` (25 channels at 1024 Hz, paced in real time: the front end's rate,
50 blocks a second) or ``mock`` (26 real channels over the real drivers: the in-process
mock bench's front end, 12 accelerometers and the force, on virtual CAN, a second mock
front end with 12 more accelerometers on the same bench on another virtual CAN channel,
and the hammer's digitiser on a pseudo-terminal; read as the Station view reads them, 25
times a second).

Run: ``.venv/bin/python benchmarks/gui.py [--source synthetic|mock] [--seconds 10]``
(off screen unless ``QT_QPA_PLATFORM`` says otherwise). The redraw timer asks for ``--fps``
(30); frames with *new* data are bounded by the stream's reads a second.
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from collections.abc import Callable

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.gui.streaming import BlockSource, DeviceSource, StreamThread, SyntheticSource
from app.gui.views.levels import LevelsWidget
from app.report.figures import configure


def _mock_source(hit_every: float = 0.5) -> tuple[BlockSource, Callable[[], None]]:
    """26 real channels from the mock devices (see the module doc), a hit every
    ``hit_every`` s; returns the source and a function that stops the mocks."""
    from app.mockbench.bench import InProcessBench
    from drivers.base import AcquisitionFrontEnd
    from drivers.registry import create_device
    from drivers.station import parse_station
    from hardware_mocks.frontend_device import FrontEndDevice

    bench = InProcessBench("engine-rigid", accel_noise=0.05, force_noise=0.5)
    second = FrontEndDevice(bench.physics, channel="insitu-bench-gui-2", accel_noise=0.05,
                            wiring=list(range(12)), tail=4.0)
    extra = parse_station({"station": {"name": "second front end"}, "devices": {"frontend2": {
        "backend": "frontend-can", "fs": 1024.0,
        "transport": {"interface": "virtual", "channel": "insitu-bench-gui-2", "fd": True},
        "channels": [{"name": f"b{k}", "input": k, "quantity": "acceleration",
                      "sensitivity": 10.2, "range": 10.0} for k in range(12)]}}}, "bench")
    configs = [*bench.station.devices.values(), *extra.devices.values()]
    devs = [create_device(d) for d in configs]
    src = DeviceSource([d for d in devs if isinstance(d, AcquisitionFrontEnd)])
    stop = threading.Event()

    def hits() -> None:
        k = 0
        while not stop.wait(hit_every):
            bench.hammer.hit(exc=k % 18, peak=150.0)
            k += 1

    hitter = threading.Thread(target=hits, daemon=True)
    hitter.start()

    def close() -> None:
        stop.set()
        hitter.join(2.0)
        second.shutdown()
        bench.shutdown()

    return src, close


class _PaintCounter(QtCore.QObject):
    def __init__(self) -> None:
        super().__init__()
        self.paints = 0

    def eventFilter(self, obj: QtCore.QObject, event: QtCore.QEvent) -> bool:
        if event.type() == QtCore.QEvent.Type.Paint:
            self.paints += 1
        return False


def run(source: str, seconds: float, channels: int, fps: float = 30.0) -> dict[str, float]:
    """Stream for ``seconds`` and return the measured figures."""
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(["insitu-bench-gui"])
    configure()
    close: Callable[[], None] | None = None
    if source == "mock":
        src, close = _mock_source()
    else:
        # 50 blocks a second, so that the data never limit the frame rate
        src = SyntheticSource(channels, 1024.0, block=0.02)
    widget = LevelsWidget(fps=fps)
    widget.resize(1200, 800)
    widget.show()
    counter = _PaintCounter()
    widget.traces_plot.viewport().installEventFilter(counter)
    stream = StreamThread(src)
    lateness: list[float] = []
    probe = QtCore.QTimer()
    probe.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
    last = [time.monotonic()]

    def tick() -> None:
        now = time.monotonic()
        lateness.append(now - last[0] - 0.010)
        last[0] = now

    probe.timeout.connect(tick)
    widget.attach(stream)
    stream.start()
    probe.start(10)
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        app.processEvents(QtCore.QEventLoop.ProcessEventsFlag.AllEvents, 50)
    elapsed = time.monotonic() - t0
    probe.stop()
    stream.stop()
    widget.update_once(catch_up=True)  # the blocks still queued
    widget.detach()
    if close is not None:
        close()
    lat = np.array(widget.latencies[1:]) * 1e3
    late = np.clip(np.array(lateness[1:]), 0, None) * 1e3
    n_block = stream.blocks
    return {
        "channels": float(len(src.names)),
        "fs": src.fs,
        "seconds": elapsed,
        "fps_ticks": widget.frames / elapsed,
        "fps_new_data": widget.frames_new / elapsed,
        "fps_paints": counter.paints / elapsed,
        "latency_block_to_screen_median_ms": float(np.median(lat)),
        "latency_block_to_screen_p95_ms": float(np.percentile(lat, 95)),
        "gui_thread_lateness_median_ms": float(np.median(late)),
        "gui_thread_lateness_p99_ms": float(np.percentile(late, 99)),
        "gui_thread_lateness_max_ms": float(late.max()),
        "blocks_streamed": float(n_block),
        "samples_drawn": float(widget.ring.shown if widget.ring is not None else 0),
        "samples_streamed": float(stream.samples),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--source", choices=("synthetic", "mock"), default="synthetic")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--channels", type=int, default=25, help="synthetic source only")
    parser.add_argument("--fps", type=float, default=30.0, help="redraw timer rate asked")
    args = parser.parse_args()
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    r = run(args.source, args.seconds, args.channels, args.fps)
    print(f"source {args.source}: {int(r['channels'])} channels at {r['fs']:g} Hz for "
          f"{r['seconds']:.1f} s")
    print(f"  frames per second: {r['fps_new_data']:.1f} redraws with new data (target >= 20)"
          f" of {r['fps_ticks']:.1f} timer ticks; {r['fps_paints']:.1f} paints of the traces")
    print(f"  block-to-screen latency: median {r['latency_block_to_screen_median_ms']:.1f} ms, "
          f"95th percentile {r['latency_block_to_screen_p95_ms']:.1f} ms")
    print(f"  GUI-thread lateness (10 ms probe timer): median "
          f"{r['gui_thread_lateness_median_ms']:.1f} ms, 99th percentile "
          f"{r['gui_thread_lateness_p99_ms']:.1f} ms, max {r['gui_thread_lateness_max_ms']:.1f} ms")
    dropped = int(r["samples_streamed"] - r["samples_drawn"])
    print(f"  samples per channel: {int(r['samples_streamed'])} streamed in "
          f"{int(r['blocks_streamed'])} blocks, {int(r['samples_drawn'])} drawn "
          f"({dropped} dropped)")


if __name__ == "__main__":
    main()
