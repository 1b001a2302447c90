"""``insitu --help`` lists every verb without loading any: numpy, scipy and the verbs'
modules load only for the verb that runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

_HELP = """
import contextlib, io, sys
from app.cli.main import main
with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):
    main(sys.argv[1:])
loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("numpy", "scipy", "processing")
                or m.startswith("app.cli."))
print(" ".join(loaded))
print(out.getvalue().count("\\n    "), file=sys.stderr)
"""


def _loaded(*argv: str) -> tuple[set[str], str]:
    out = subprocess.run([sys.executable, "-c", _HELP, *argv], capture_output=True, text=True,
                         timeout=120, cwd=Path(__file__).parents[2], check=True)
    return set(out.stdout.split()), out.stderr


def test_help_lists_the_verbs_without_loading_them() -> None:
    loaded, listed = _loaded("--help")
    assert loaded == {"app.cli.common", "app.cli.main"}, loaded
    assert int(listed) == 14  # one line each


def test_a_verb_loads_what_it_uses() -> None:
    loaded, _ = _loaded("repair", "--help")
    assert "app.cli.repair" in loaded and "app.cli.identify" not in loaded
    assert not any(m.startswith("scipy.signal") for m in loaded)


def test_identify_of_frfs_loads_no_spectra(tmp_path: Path) -> None:
    """FRFs given: the numba spectra and the record processing stay unloaded (they are
    compiled code that takes a second to load); they load for time data."""
    from app.io.uff import write_frf_uff
    from hardware_mocks.benches import get_bench

    path = tmp_path / "engine.uff"
    write_frf_uff(path, get_bench("engine-rigid").frfset(noise=0.01, seed=3), binary=True)
    code = _HELP.replace('m.split(".")[0] in (', 'm.split(".")[0] in ("numba", "h5py", ').replace(
        'm.startswith("app.cli.")', 'm.startswith(("app.cli.", "app.acquire"))')
    out = subprocess.run([sys.executable, "-c", code, "identify", str(path)], capture_output=True,
                         text=True, timeout=300, cwd=Path(__file__).parents[2], check=True)
    loaded = set(out.stdout.split())
    assert "processing.identify" in loaded  # it did identify
    assert not {"numba", "processing.spectral", "app.acquire"} & loaded, loaded
    assert "h5py" not in loaded  # HDF5 (11 MB) for HDF5 files only
    # scipy.signal and scipy.stats take 0.3 s to import; scipy.optimize 0.1 s, needed only
    # for a residual peak's fit or a non-physical estimate (neither on this rigid bench)
    assert not {"scipy.signal", "scipy.stats", "scipy.optimize"} & loaded, loaded


def test_reading_a_run_file_loads_no_device_drivers() -> None:
    """Replay, identify and report of a run file read it through ``app.pipeline``: the
    procedures and their drivers (python-can pulls asammdf and pandas when they are
    installed: half a second) stay unloaded."""
    code = ("import sys, app.cli.replay, app.pipeline.runs\n"
            "from app.pipeline import load\n"
            "print(' '.join(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, cwd=Path(__file__).parents[2], check=True)
    loaded = set(out.stdout.split())
    assert "app.acquire.analysis" in loaded  # the run's records are analysed
    assert not {"can", "serial", "drivers.transports", "app.acquire.hammer",
                "app.acquire.shaker", "pandas"} & loaded, loaded


def test_the_acquisition_api_names_are_the_lazy_ones() -> None:
    """``app.acquire``'s public names, its lazy table and what each resolves to agree (the
    names are listed three times there: for mypy, for the lazy loading and in __all__)."""
    import app.acquire as acquire

    where = acquire._WHERE
    assert sorted(acquire.__all__) == sorted(where)
    for name, module in where.items():
        assert getattr(acquire, name).__module__ == f"app.acquire.{module}", name


def test_acquiring_imports_python_can_without_asammdf() -> None:
    """The procedures and the mock bench import python-can; with asammdf installed (the
    ``mdf`` extra) python-can would import it and pandas at once (app/can_import.py). They
    stay out, CAN frames still pass, and asammdf is importable afterwards (MDF files)."""
    code = ("import sys, app.acquire.hammer, app.mockbench.bench, can\n"
            "print('asammdf' in sys.modules, 'pandas' in sys.modules)\n"
            "with can.Bus(interface='virtual', channel='t') as a, "
            "can.Bus(interface='virtual', channel='t') as b:\n"
            "    a.send(can.Message(arbitration_id=0x123, data=b'\\x01\\x02'))\n"
            "    print(b.recv(5).data.hex())\n"
            "import asammdf\n"
            "print(asammdf.MDF is not None)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, cwd=Path(__file__).parents[2], check=True)
    assert out.stdout.split() == ["False", "False", "0102", "True"], out.stdout + out.stderr
