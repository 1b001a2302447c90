"""Benchmark: H1 spectra of 1 force + 24 accelerations, our accumulator against its references.

For each sample rate and sample type, on the same samples (120 s by default):

- ours: :class:`processing.spectral.SpectralAccumulator` fed block by block as the
  signal is generated (the recording is never held whole), ``workers`` threads;
- floor: the bare rfft of the same segments, one core, in groups of GROUP segments; no
  estimator can be faster than this. Timed twice, with ``scipy.fft.rfft`` and with the
  same pocketfft compiled into numba (rocket-fft, what ours calls: about 30 % faster
  here, same bits); the faster of the two is the floor. Ours and the floors take turns
  in going first, second and third on each block as it is generated, so that the
  host's slower spells, and a block already read by another, hit them alike;
- (a) scipy: a per-channel loop of ``scipy.signal.csd`` / ``welch`` on the whole recording;
- (b) pyFRF (if installed): ``pyFRF.FRF(..., window='hann').get_H1()`` on the whole recording;
- ``--against REV``: the accumulator of git revision REV (its ``processing/spectral.py`` and
  ``processing/_welch_kernel.py``, imported from a temporary folder), taking turns with ours
  on each block as the floors do; its sums are compared with ours bit for bit;
- ``--busy N``: every run twice, quiet and beside N processes spinning in a Python loop
  (each takes a core), the two taking turns; ours with one thread also takes turns on
  each block, so that ours (which chooses its threads by the cores free) is compared
  with one thread and with the revision given under the same load.

Peak memory is measured in a fresh child process per method (resident-set high-water mark
above the child's baseline). Results are compared with (a) element by element.

Run: ``.venv/bin/python benchmarks/frf.py`` (``--duration 20`` for a quick look);
``--write-docs`` writes the table, with the date, machine and command, to
``docs/benchmarks.md``; ``--write FILE`` to FILE (``benchmarks/results/frf-under-load.md``
for ``--busy 1 --against REV``).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import rocket_fft  # noqa: F401  (scipy.fft inside numba)
import scipy.fft
import scipy.signal
from numba import njit
from numpy.lib.stride_tricks import sliding_window_view
from rich.console import Console
from rich.table import Table

from processing._welch_kernel import compile_ahead
from processing.spectral import SpectralAccumulator, h1

N_RESP = 24
NPERSEG = 8192
GROUP = 4  # the floor's segments per rfft call
#: the order of the floors (0: scipy, 1: rocket-fft), ours (2) and the revision compared
#: (3, with --against) on a block, every one in turn: each goes first as often, and after
#: each of the others as often (what read a block before, on which core, changes what the
#: next one pays)
ORDERS = {k: tuple(itertools.permutations(range(k))) for k in (3, 4, 5)}
ROOT = Path(__file__).resolve().parents[1]


def blocks(fs: float, duration: float, block_s: float, dtype: str, seed: int = 0) -> Iterator[
    np.ndarray
]:
    """The recording (25, n) block by block: random force, resonant responses plus noise."""
    rng = np.random.default_rng(seed)
    sos = scipy.signal.butter(2, [0.01 * fs, 0.1 * fs], "bandpass", fs=fs, output="sos")
    zi = np.zeros((sos.shape[0], 2))
    gains = np.linspace(0.5, 3.0, N_RESP)
    n_total, n_block = round(duration * fs), round(block_s * fs)
    done = 0
    while done < n_total:  # few temporaries: the generator's memory counts in the peak
        n = min(n_block, n_total - done)
        out = np.empty((N_RESP + 1, n), dtype=dtype)
        rng.standard_normal(dtype=dtype, out=out[0])
        y, zi = scipy.signal.sosfilt(sos, out[0], zi=zi)
        x = out[1:]
        rng.standard_normal(dtype=dtype, out=x)
        x *= 0.05
        for i in range(N_RESP):
            x[i] += gains[i] * y
        yield out
        done += n


def whole(fs: float, duration: float, block_s: float, dtype: str) -> np.ndarray:
    return np.concatenate(list(blocks(fs, duration, block_s, dtype)), axis=-1)


@njit(nogil=True, cache=True)
def _rfft_groups(segs: np.ndarray, group: int) -> None:
    """The floor's transforms through the pocketfft that ours calls (rocket-fft, numba)."""
    for g in range(0, segs.shape[1], group):
        scipy.fft.rfft(segs[:, g : g + group], axis=-1, workers=1)


class Floor:
    """Bare rfft of every segment, GROUP segments of all channels per call, one worker:
    with scipy's rfft (``engine`` 0) and with the same pocketfft compiled in (rocket-fft, 1)."""

    def __init__(self, dtype: str) -> None:
        self.tail = np.empty((N_RESP + 1, 0), dtype=dtype)
        self.segs = self.tail[:, :0, None]

    def next_block(self, block: np.ndarray) -> None:
        """The block's complete segments, to transform next (untimed)."""
        step = NPERSEG // 2
        data = np.concatenate([self.tail, block], axis=-1)
        n_seg = 0 if data.shape[-1] < NPERSEG else (data.shape[-1] - NPERSEG) // step + 1
        self.segs = sliding_window_view(data, NPERSEG, axis=-1)[:, ::step][:, :n_seg]
        self.tail = data[:, n_seg * step:]

    def transform(self, engine: int) -> float:
        """Transform the block's segments with one engine; the seconds it took."""
        segs = self.segs
        t0 = time.perf_counter()
        if engine == 0:
            for g in range(0, segs.shape[1], GROUP):
                scipy.fft.rfft(segs[:, g:g + GROUP], axis=-1, workers=1)
        else:
            _rfft_groups(segs, GROUP)
        return time.perf_counter() - t0


def accumulator_of(rev: str) -> type:
    """``SpectralAccumulator`` of git revision ``rev``, imported from a temporary folder."""
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", rev], check=True,
                         capture_output=True, text=True).stdout.strip()
    folder = Path(tempfile.gettempdir()) / "insitu-frf-against" / sha
    pkg = folder / f"rev_{sha}"
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text("")
    for name in ("spectral", "_welch_kernel"):
        text = subprocess.run(["git", "-C", str(ROOT), "show", f"{sha}:processing/{name}.py"],
                              check=True, capture_output=True, text=True).stdout
        (pkg / f"{name}.py").write_text(text.replace("processing._welch_kernel",
                                                     f"rev_{sha}._welch_kernel"))
    sys.path.insert(0, str(folder))
    importlib.import_module(f"rev_{sha}._welch_kernel").compile_ahead()
    return importlib.import_module(f"rev_{sha}.spectral").SpectralAccumulator  # type: ignore[no-any-return]


def run_ours(fs: float, duration: float, block_s: float, dtype: str, workers: int):
    """Ours alone (the memory child, and the spectra compared with scipy's)."""
    acc = SpectralAccumulator(fs, NPERSEG, workers=workers)
    for b in blocks(fs, duration, block_s, dtype):
        acc.update(b)
    sp = acc.spectra()
    return sp, h1(sp)


def run_paired(fs: float, duration: float, block_s: float, dtype: str, workers: int,
               against: type | None = None, one_thread: bool = False):
    """Ours (and ours with one thread, the revision compared), and the floors on each block
    as it is generated, taking turns in every order (``ORDERS``), so that a slower spell of
    the shared host and a block already read hit them alike.

    Returns (floor with scipy's rfft s, floor with rocket-fft's s, ours s, the revision's
    s or None, whether its sums equal ours bit for bit, ours with one thread s or None);
    ours and the others' include reading the spectra and H1.
    """
    accs = [SpectralAccumulator(fs, NPERSEG, workers=workers)]
    if one_thread:
        accs.append(SpectralAccumulator(fs, NPERSEG, workers=1))
    if against is not None:
        accs.append(against(fs, NPERSEG, workers=workers))
    floor = Floor(dtype)
    t = [0.0] * (2 + len(accs))  # floor scipy, floor rocket, ours, [one thread], [revision]
    orders = ORDERS[2 + len(accs)]
    for i, b in enumerate(blocks(fs, duration, block_s, dtype)):
        floor.next_block(b)
        for which in orders[i % len(orders)]:
            if which < 2:
                t[which] += floor.transform(which)
            else:
                t0 = time.perf_counter()
                accs[which - 2].update(b)
                t[which] += time.perf_counter() - t0
    sps = []
    for k, acc in enumerate(accs):
        t0 = time.perf_counter()
        sps.append(acc.spectra())
        h1(sps[-1])
        t[2 + k] += time.perf_counter() - t0
    same = all(np.array_equal(getattr(sps[0], f), getattr(sp, f))
               for sp in sps[1:] for f in ("Sff", "Sfx", "Sxx"))
    return (t[0], t[1], t[2], (t[-1] if against else None), same,
            (t[3] if one_thread else None))


@contextlib.contextmanager
def busy(n: int) -> Iterator[None]:
    """``n`` processes spinning in a Python loop (each takes a core) while inside."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        if procs:
            time.sleep(0.5)  # started: spinning, not importing
        yield
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()


def paired_under_load(fs: float, duration: float, block_s: float, dtype: str, workers: int,
                      against: type | None, repeat: int, n_busy: int) -> list[dict]:
    """``repeat`` runs of :func:`run_paired`, or with ``n_busy`` > 0 ``repeat`` pairs of
    runs, quiet and beside ``n_busy`` busy processes, the two taking turns in going first;
    each run's times, how many busy processes and the load average (1 min) after it."""
    out = []
    for i in range(repeat):
        for n in ((0, n_busy) if i % 2 == 0 else (n_busy, 0)) if n_busy else (0,):
            with busy(n):
                r = run_paired(fs, duration, block_s, dtype, workers, against, n_busy > 0)
            out.append({"scipy": r[0], "rocket": r[1], "ours": r[2], "against": r[3],
                        "identical": r[4], "one": r[5], "busy": n, "load": os.getloadavg()[0]})
    return out


def run_scipy(x: np.ndarray, fs: float):
    t0 = time.perf_counter()
    kw = {"fs": fs, "nperseg": NPERSEG}
    Pfx = np.array([scipy.signal.csd(x[0], x[i], **kw)[1] for i in range(1, x.shape[0])])
    Pxx = np.array([scipy.signal.welch(x[i], **kw)[1] for i in range(1, x.shape[0])])
    Pff = scipy.signal.welch(x[0], **kw)[1]
    return time.perf_counter() - t0, Pff, Pfx, Pxx


def run_pyfrf(x: np.ndarray, fs: float) -> float:
    import pyFRF  # benchmark-only reference, not a dependency

    t0 = time.perf_counter()
    frf = pyFRF.FRF(int(fs), exc=x[None, :1], resp=x[None, 1:], window="hann",
                    nperseg=NPERSEG, noverlap=NPERSEG // 2, fft_len=NPERSEG)
    with np.errstate(all="ignore"):
        frf.get_H1()
    return time.perf_counter() - t0


def _rss_mb(field: str = "VmRSS") -> float:
    """Resident set (VmRSS) or its high-water mark (VmHWM) of this process, MB.

    Not ``ru_maxrss``: Linux carries that over from the parent across fork and exec.
    """
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"{field} not in /proc/self/status")


def child(method: str, fs: float, duration: float, block_s: float, dtype: str,
          workers: int, repeat: int, against: str | None = None, n_busy: int = 0) -> None:
    """Run one method in this (fresh) process; print its peak memory above baseline, MB,
    or for ``times`` the floor's and our times of the paired runs, s
    (:func:`paired_under_load`)."""
    if method == "times":
        # numba's cache loaded, and one untimed run: on this VM fresh memory costs a page
        # fault per 4 kB; in a fresh process, with glibc's default thresholds, the floor's
        # and our freed arrays went back to the system and came back page by page (the
        # floor measured up to 1.8x slower, ours 1.4x): see in_child for the settings
        compile_ahead()
        other = accumulator_of(against) if against else None
        run_paired(fs, min(duration, 20.0), block_s, dtype, workers, other, n_busy > 0)
        runs = paired_under_load(fs, duration, block_s, dtype, workers, other, repeat, n_busy)
        print(json.dumps(runs))
        return
    x = None
    if method in ("scipy", "pyfrf"):
        x = whole(fs, duration, block_s, dtype)
    base = _rss_mb()
    if method == "ours":
        run_ours(fs, duration, block_s, dtype, workers)
    elif method == "scipy":
        assert x is not None
        run_scipy(x, fs)
    else:
        assert x is not None
        run_pyfrf(x, fs)
    print(json.dumps({"peak_mb": _rss_mb("VmHWM") - base}))


def in_child(method: str, fs: float, args: argparse.Namespace, dtype: str) -> Any:
    """What :func:`child` prints, run in a fresh process (None if it failed)."""
    cmd = [sys.executable, __file__, "--child", method, "--rate", str(fs), "--dtype", dtype,
           "--duration", str(args.duration), "--block", str(args.block),
           "--workers", str(args.workers), "--repeat", str(args.repeat)]
    if args.against and method == "times":
        cmd += ["--against", args.against]
    if args.busy and method == "times":
        cmd += ["--busy", str(args.busy)]
    env = dict(os.environ)
    if method == "times":  # glibc keeps freed memory (no page faults for the next arrays)
        env.update(MALLOC_MMAP_THRESHOLD_=str(1 << 26), MALLOC_TRIM_THRESHOLD_=str(1 << 28))
    out = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
    if out.returncode != 0:
        return None
    return json.loads(out.stdout.strip().splitlines()[-1])


def peak_memory(method: str, fs: float, args: argparse.Namespace, dtype: str) -> float | None:
    out = in_child(method, fs, args, dtype)
    return None if out is None else float(out["peak_mb"])


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    """Largest element-wise relative difference (elements above 1e-12 of the largest)."""
    a, b = np.asarray(a), np.asarray(b)
    m = np.abs(b) > 1e-12 * np.abs(b).max()
    return float(np.max(np.abs(a[m] - b[m]) / np.abs(b[m])))


COLUMNS = ("rate", "dtype", "floor ms scipy", "floor ms rocket", "ours ms", "ours/floor",
           "ours/scipy floor", "real time", "(a) scipy ms", "(a)/ours", "(b) pyFRF ms",
           "(b)/ours", "ours MB", "(a) MB", "(b) MB", "max rel. diff to (a)")
AGAINST = ("against ms", "ours/against", "identical sums")
NOTE = (
    "ours/floor: median (range) over the runs, ours and the floors taking turns on each block, "
    "against the faster floor of the run (ours/scipy floor: against scipy's); ms: best run. "
    "floor: bare rfft of the same segments, one core, groups of {group} segments x 25 "
    "channels, with scipy.fft.rfft and with the same pocketfft compiled into numba "
    "(rocket-fft, which ours calls); real time: recording length / our time; MB: peak "
    "resident memory above the process baseline (fresh process); float32 is transformed in "
    "single precision, so its difference to scipy (which also works in single precision) is "
    "at float32 level. against: the accumulator of the revision given, taking turns with "
    "ours; ours/against: median (range) of the runs' ratios; identical sums: its Sff, Sfx, "
    "Sxx equal ours bit for bit in every run."
)


def measure(fs: float, dtype: str, args: argparse.Namespace) -> list[str]:
    """One row of the table: ``fs`` Hz, ``dtype`` samples."""
    # timed in a fresh process: the references' gigabytes must not weigh on the next row
    runs = in_child("times", fs, args, dtype)
    if runs is None:
        raise SystemExit(f"timing {fs:g} Hz {dtype} failed")
    ours, f_scipy, f_rocket = (np.array([r[k] for r in runs]) for k in ("ours", "scipy", "rocket"))
    t_ours = ours.min()
    sp, H = run_ours(fs, args.duration, args.block, dtype, args.workers)
    mem_ours = peak_memory("ours", fs, args, dtype)
    t_a = t_b = mem_a = mem_b = None
    diff = "-"
    if not args.no_references:
        x = whole(fs, args.duration, args.block, dtype)
        t_a, Pff, Pfx, Pxx = run_scipy(x, fs)
        diff = f"{max(rel_err(sp.Sfx[0], Pfx), rel_err(sp.Sxx, Pxx), rel_err(sp.Sff[0, 0].real, Pff), rel_err(H[:, 0], Pfx / Pff)):.1e}"  # noqa: E501
        del x
        mem_a = peak_memory("scipy", fs, args, dtype)
        if args.pyfrf:
            x = whole(fs, args.duration, args.block, dtype)
            try:
                t_b = run_pyfrf(x, fs)
            except Exception as err:  # a reference failing is reported, not fatal
                print(f"pyFRF failed: {err}", file=sys.stderr)
            del x
            mem_b = peak_memory("pyfrf", fs, args, dtype) if t_b else None

    def ms(t: float | None) -> str:
        return "-" if t is None else f"{1e3 * t:.0f}"

    def ratio(t: float | None) -> str:
        return "-" if t is None else f"{t / t_ours:.1f}x"

    def mb(m: float | None) -> str:
        return "-" if m is None else f"{m:.0f}"

    row = [f"{fs / 1000:g} kHz", dtype, ms(f_scipy.min()), ms(f_rocket.min()), ms(t_ours),
           spread(ours / np.minimum(f_scipy, f_rocket)), spread(ours / f_scipy),
           f"{args.duration / t_ours:.0f}x", ms(t_a), ratio(t_a), ms(t_b), ratio(t_b),
           mb(mem_ours), mb(mem_a), mb(mem_b), diff]
    if args.against:
        other = np.array([r["against"] for r in runs])
        row += [ms(other.min()), spread(ours / other),
                "yes" if all(r["identical"] for r in runs) else "NO"]
    return row


def spread(r: np.ndarray) -> str:
    """Median (range) of ratios."""
    return f"{np.median(r):.2f} ({r.min():.2f}-{r.max():.2f})"


LOAD_COLUMNS = ("rate", "dtype", "busy processes", "load (1 min)", "floor ms", "ours ms",
                "ours/floor", "one thread/floor", "ours/one thread")
LOAD_AGAINST = ("against/floor", "ours/against", "identical sums")
LOAD_NOTE = (
    "Each run twice, quiet and beside the busy processes (each a Python loop taking a core), "
    "the two taking turns in going first; ours, ours with one thread (and the revision "
    "given) and the floors take turns on each block. ratios: median (range) over the runs "
    "of that load, against the faster floor of the run (bare rfft of the same segments, one "
    "core); ms: best run; load (1 min): median of the load average read after each run "
    "(the host is shared: it counts the other users' processes and the busy ones). "
    "against: the accumulator of the revision given, with as many threads as ours may "
    "take, in the same process and so under ours' OpenMP settings (threads asleep at once "
    "after a block unless GOMP_SPINCOUNT is set); identical sums: ours, one thread's and "
    "its Sff, Sfx, Sxx equal bit for bit in every run."
)


def measure_load(fs: float, dtype: str, args: argparse.Namespace) -> list[list[str]]:
    """Two rows of the table under load (``--busy``): quiet, and beside the busy processes."""
    runs = in_child("times", fs, args, dtype)
    if runs is None:
        raise SystemExit(f"timing {fs:g} Hz {dtype} failed")
    rows = []
    for n in (0, args.busy):
        mine = [r for r in runs if r["busy"] == n]
        floor, ours, one = (np.array([min(r["scipy"], r["rocket"]) for r in mine]),
                            *(np.array([r[k] for r in mine]) for k in ("ours", "one")))
        row = [f"{fs / 1000:g} kHz", dtype, str(n),
               f"{np.median([r['load'] for r in mine]):.1f}", f"{1e3 * floor.min():.0f}",
               f"{1e3 * ours.min():.0f}", spread(ours / floor), spread(one / floor),
               spread(ours / one)]
        if args.against:
            other = np.array([r["against"] for r in mine])
            row += [spread(other / floor), spread(ours / other),
                    "yes" if all(r["identical"] for r in mine) else "NO"]
        rows.append(row)
    return rows


def write_docs(path: Path, title: str, columns: tuple[str, ...], rows: list[list[str]],
               note: str) -> None:
    """The table as markdown, with the date, the machine, the command and the load average:
    this script's section of docs/benchmarks.md, or a page of its own at ``path``."""
    from docs_page import PAGE, provenance, write_section

    docs = path == PAGE
    body = [f"## {title}", "", *provenance("benchmarks/frf.py"), "",
            *(["Under a second busy process: `benchmarks/results/frf-under-load.md` "
               "(`benchmarks/frf.py --busy 1`).", ""] if docs else []),
            "| " + " | ".join(columns) + " |", "|" + " --- |" * len(columns),
            *("| " + " | ".join(r) + " |" for r in rows), "", note, ""]
    if docs:
        write_section("benchmarks/frf.py", "\n".join(body))
    else:
        path.write_text("\n".join(["# H1 spectra under load", "", *body]))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=120.0, help="recording length, s")
    p.add_argument("--rates", type=float, nargs="+", default=[25600.0, 51200.0])
    p.add_argument("--dtypes", nargs="+", default=["float64", "float32"])
    p.add_argument("--block", type=float, default=1.0, help="block length, s")
    p.add_argument("--workers", type=int, default=2, help="ours: most threads")
    p.add_argument("--repeat", type=int, default=5, help="runs (floor and ours taking turns)")
    p.add_argument("--no-references", action="store_true", help="skip scipy and pyFRF")
    p.add_argument("--against", metavar="REV", help="also time the accumulator of git REV")
    p.add_argument("--busy", type=int, default=0, metavar="N",
                   help="each run also beside N busy processes (times only)")
    p.add_argument("--write-docs", action="store_true", help="write docs/benchmarks.md")
    p.add_argument("--write", type=Path, metavar="FILE", help="write the table to FILE")
    p.add_argument("--child", help=argparse.SUPPRESS)
    p.add_argument("--rate", type=float, help=argparse.SUPPRESS)
    p.add_argument("--dtype", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(args.child, args.rate, args.duration, args.block, args.dtype, args.workers,
              args.repeat, args.against, args.busy)
        return 0
    try:
        import pyFRF  # noqa: F401

        args.pyfrf = not args.no_references
        pyfrf_note = ""
    except ImportError:
        args.pyfrf = False
        pyfrf_note = "pyFRF is not installed: (b) not measured (pip install pyFRF)"

    console = Console(width=260)
    title = (f"H1 spectra, 1 force + {N_RESP} accelerations, {args.duration:g} s, "
             f"nperseg {NPERSEG}, 50 % overlap, ours with at most {args.workers} threads")
    if args.busy:
        columns = LOAD_COLUMNS + (LOAD_AGAINST if args.against else ())
        note = LOAD_NOTE
    else:
        columns = COLUMNS + (AGAINST if args.against else ())
        note = NOTE.format(group=GROUP) + (f" {pyfrf_note}." if pyfrf_note else "")
    rows = []
    for fs in args.rates:
        for dtype in args.dtypes:
            rows += measure_load(fs, dtype, args) if args.busy else [measure(fs, dtype, args)]
            console.print(f"done {fs:g} Hz {dtype}", style="dim")
    table = Table(title=title)
    for col in columns:
        table.add_column(col, justify="right")
    for row in rows:
        table.add_row(*row)
    console.print(table)
    console.print(note)
    if args.write_docs:
        write_docs(ROOT / "docs" / "benchmarks.md", title, columns, rows, note)
    if args.write:
        write_docs(args.write, title, columns, rows, note)
    return 0


if __name__ == "__main__":
    sys.exit(main())
