"""The input formats and the one dispatch from a file to its measurement.

Time records come as a time UFF, or as a TDMS or MDF file read through a channel map
(``docs/time-files.md``); the three go through one code to their FRFs
(:func:`app.pipeline.time_uff.open_time_records`).

A fifth format is added here: a name in :data:`FORMATS`, its test in :func:`detect_format`
(headers only) and its reader (``(path, Settings) -> Measurement``) in :data:`READERS`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from app.io.frf_h5 import FORMAT as FRF_H5_FORMAT
from app.io.frf_h5 import h5_format, read_frf_measurement
from app.io.uff import read_frf_measurement_uff
from app.io.uff_time import uff_holds_time_data
from app.pipeline.settings import OpenError, Settings
from processing.blas import one_blas_thread
from processing.data import InputError, finite_frfs
from processing.measurement import Measurement, Report

if TYPE_CHECKING:
    from app.io.time_channels import MappedTimeFile, RawFile

__all__ = ["FORMATS", "FRF_H5", "FRF_UFF", "H5_SUFFIXES", "MDF_SUFFIXES", "READERS", "RUN_FILE",
           "SUFFIXES", "TDMS_SUFFIXES", "TIME_FORMATS", "TIME_MDF", "TIME_TDMS", "TIME_UFF",
           "UFF_SUFFIXES", "detect_format", "load"]

FRF_UFF = "frf-uff"
TIME_UFF = "time-uff"
RUN_FILE = "run-file"
FRF_H5 = "frf-h5"
TIME_TDMS = "time-tdms"
TIME_MDF = "time-mdf"
#: the formats of time records (FRFs computed from them by one code, the time options apply)
TIME_FORMATS = (TIME_UFF, TIME_TDMS, TIME_MDF)

#: format -> what it is, for messages and file dialogs
FORMATS = {
    FRF_UFF: "UFF file of FRFs (dataset 58, function type 4) with geometry",
    TIME_UFF: "UFF file of time records (dataset 58, function type 1) with geometry",
    RUN_FILE: "run file (.h5) written by insitu acquire",
    FRF_H5: "FRF file (.h5) written by insitu frf",
    TIME_TDMS: "TDMS file of time records (NI) with a channel map",
    TIME_MDF: "MDF file of time records (ASAM MDF 4) with a channel map",
}
UFF_SUFFIXES = (".uff", ".unv")
H5_SUFFIXES = (".h5", ".hdf5")
TDMS_SUFFIXES = (".tdms",)
MDF_SUFFIXES = (".mf4", ".mdf")
#: every suffix some format is read from
SUFFIXES = UFF_SUFFIXES + H5_SUFFIXES + TDMS_SUFFIXES + MDF_SUFFIXES

Reader = Callable[[Path, Settings], Measurement]


def _lead_in(p: Path) -> bytes:
    """The file's first 8 bytes (empty when it cannot be read: its reader then says why)."""
    try:
        with p.open("rb") as f:
            return f.read(8)
    except OSError:
        return b""


def detect_format(path: str | Path) -> str:
    """The format of ``path``: a TDMS file (lead-in ``TDSm``) or an MDF file (``MDF     ``)
    by its first bytes, else by its suffix (its reader then refuses a file that is not one);
    an HDF5 file (by suffix) is an FRF file or a run file by its root attribute ``format``;
    any other file is UFF, of time records or of FRFs."""
    p = Path(path)
    head, suffix = _lead_in(p), p.suffix.lower()
    if head.startswith(b"TDSm") or (suffix in TDMS_SUFFIXES and not head.startswith(b"MDF ")):
        return TIME_TDMS
    if head == b"MDF     " or suffix in MDF_SUFFIXES:
        return TIME_MDF
    if suffix in H5_SUFFIXES:
        return FRF_H5 if h5_format(p) == FRF_H5_FORMAT else RUN_FILE
    return TIME_UFF if uff_holds_time_data(p) else FRF_UFF


def _frf_uff(path: Path, _: Settings) -> Measurement:
    return read_frf_measurement_uff(path)  # given: their coherence stands for their noise


def _frf_h5(path: Path, _: Settings) -> Measurement:
    return read_frf_measurement(path)


def _time_uff(path: Path, settings: Settings) -> Measurement:
    from app.pipeline.time_uff import open_time_uff  # the spectra: loaded when time data come

    return open_time_uff(path, settings)


def _run_file(path: Path, settings: Settings) -> Measurement:
    from app.pipeline.runs import open_run_file  # the record processing, likewise

    return open_run_file(path, settings)


def _time_tdms(path: Path, settings: Settings) -> Measurement:
    from app.io.tdms import TdmsRaw  # npTDMS (an extra): loaded when such a file comes
    from app.pipeline.time_uff import open_time_records

    return open_time_records(_mapped(TdmsRaw(path), settings), settings)


def _time_mdf(path: Path, settings: Settings) -> Measurement:
    from app.io.mdf import MdfRaw  # asammdf (an extra): loaded when such a file comes
    from app.pipeline.time_uff import open_time_records

    return open_time_records(_mapped(MdfRaw(path), settings), settings)


def _mapped(raw: RawFile, settings: Settings) -> MappedTimeFile:
    """A TDMS or MDF file's runs through its channel map (``settings.channel_map``, else the
    map beside the file)."""
    from app.io.channel_map import default_map_path, read_channel_map
    from app.io.time_channels import MappedTimeFile

    given = settings.channel_map
    path = given if given is not None else default_map_path(raw.path)
    if given is None and not path.is_file():
        raise OpenError(f"{raw.path.name} needs a channel map (which channel is the force, "
                        "which node and direction each response measures): give --channels "
                        f"MAP.toml or put {path.name} beside it (docs/time-files.md)")
    return MappedTimeFile(raw, read_channel_map(path))


#: format -> reader
READERS: dict[str, Reader] = {
    FRF_UFF: _frf_uff,
    TIME_UFF: _time_uff,
    RUN_FILE: _run_file,
    FRF_H5: _frf_h5,
    TIME_TDMS: _time_tdms,
    TIME_MDF: _time_mdf,
}


@one_blas_thread
def load(path: str | Path, settings: Settings | None = None, *,
         fmt: str | None = None) -> Measurement:
    """The measurement of a file of any format: every view's one way in.

    Parameters
    ----------
    path : the file
    settings : how FRFs are computed from time data and run files (default: the command
        line's defaults)
    fmt : the format, when the caller knows it (default: :func:`detect_format`)

    Returns
    -------
    Measurement
        Accelerance FRFs, (m/s^2)/N, with coherence when the format has it, and their
        provenance: given or estimated here, the per-hit or per-block spectra, the
        exponential window, the hammer's usable band, and the reports (one line per run or
        point: verdicts, runs left out, ``skipped``; the coherence gate and rigidity check of
        FRFs computed from records; NaN or infinite FRF values of any format:
        :func:`processing.data.finite_frfs`, their lines left out of every FRF, their
        coherence counted as 0, one line each naming the FRFs and frequencies).

    Raises
    ------
    OpenError, InputError, OSError
        One line naming the problem and what to do (an :class:`OpenError` carries the
        reports gathered before it); FRFs undefined on every line, or on more lines than
        :data:`processing.data.MAX_UNDEFINED_SHARE`, are refused, naming them.

    Examples
    --------
    >>> m = load("run.h5")  # doctest: +SKIP
    >>> fit(m).properties.mass  # doctest: +SKIP
    """
    p = Path(path)
    m = READERS[fmt or detect_format(p)](p, settings or Settings())
    try:
        frf, said = finite_frfs(m.frf, p.name)
    except InputError as err:
        raise OpenError(str(err), m.provenance.reports) from err
    if not said:
        return m
    return dataclasses.replace(m, frf=frf, provenance=dataclasses.replace(
        m.provenance, reports=(*m.provenance.reports, *(Report(s) for s in said))))
