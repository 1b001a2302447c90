"""FRF files (HDF5): FRFs, coherence, DOFs, geometry and processing metadata.

Written by ``insitu frf ... --out FRF.h5`` and read by ``insitu identify FRF.h5``.
The layout is documented in ``docs/run-file.md`` ("FRF file"), schema version
:data:`SCHEMA_VERSION`. Every dataset carries a ``units`` attribute. A run file
(``app/io/runfile.py``) and an FRF file are told apart by the root attribute
``format`` (:func:`h5_format`).

Example
-------
>>> write_frf_h5("frf.h5", frfset)  # doctest: +SKIP
>>> read_frf_h5("frf.h5").H.shape  # doctest: +SKIP
(12, 18, 400)
"""

from __future__ import annotations

import datetime
import json
import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from processing.data import FRFSet, Geometry
from processing.measurement import Measurement, Provenance

__all__ = ["FORMAT", "SCHEMA_VERSION", "FRFFileError", "h5_format", "read_frf_h5",
           "read_frf_measurement", "write_frf_h5"]

SCHEMA_VERSION = 1
FORMAT = "insitu-frf"

#: dataset -> units attribute (``/H``: accelerance, response unit per force unit)
_UNITS = {
    "freq": "Hz", "H": "m/s^2/N", "coherence": "1", "resp_nodes": "1", "resp_dirs": "1",
    "exc_nodes": "1", "exc_dirs": "1", "geometry/node_ids": "1", "geometry/xyz": "m",
    "meta": "n/a",
}


class FRFFileError(ValueError):
    """The FRF file is missing, foreign, of another schema version or damaged (one line)."""


def _jsonable(obj: Any) -> Any:
    """numpy scalars and arrays as plain JSON values (for ``/meta``)."""
    if isinstance(obj, np.ndarray | np.generic):
        return obj.tolist()
    return str(obj)


def _str(v: Any) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def h5_format(path: str | Path) -> str:
    """The root ``format`` attribute of an HDF5 file (``"insitu-frf"``, ``"insitu-run"``).

    Returns ``""`` when the file cannot be opened plainly (not HDF5, missing, or a run
    file whose writer is still active) or has no such attribute.
    """
    try:
        with h5py.File(Path(path), "r") as f:
            return _str(f.attrs.get("format", ""))
    except OSError:
        return ""


def write_frf_h5(path: str | Path, frf: FRFSet | Measurement, *, source: str = "") -> None:
    """Write FRFs (a measurement with its provenance) to an HDF5 FRF file (replaced
    atomically).

    Parameters
    ----------
    path : output file (``.h5``)
    frf : FRFs (m/s^2/N) with their DOFs, geometry (m), optional coherence and ``meta``
        (written as JSON; numpy values become lists, anything else its ``str``); a
        measurement's provenance is kept whole in the attributes of ``/provenance`` (the
        per-hit or per-block spectra are not kept)
    source : what the FRFs were computed from (root attribute ``source``)

    Raises
    ------
    FRFFileError
        The file cannot be written.
    """
    p = Path(path)
    prov = frf.provenance if isinstance(frf, Measurement) else Provenance()
    frf = frf.frf if isinstance(frf, Measurement) else frf
    tmp = p.with_name(p.name + ".tmp")
    try:
        with h5py.File(tmp, "w") as f:
            f.create_group("provenance").attrs.update(prov.stored())
            f.attrs.update({
                "format": FORMAT, "schema_version": SCHEMA_VERSION, "source": source,
                "estimator": str(frf.meta.get("estimator", "H1")),
                "created": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            })
            values: dict[str, Any] = {
                "freq": frf.freq, "H": frf.H, "resp_nodes": frf.resp_nodes,
                "resp_dirs": frf.resp_dirs, "exc_nodes": frf.exc_nodes,
                "exc_dirs": frf.exc_dirs, "geometry/node_ids": frf.geometry.node_ids,
                "geometry/xyz": frf.geometry.xyz,
                # the per-hit spectra of time data (the bootstrap's) are not kept
                "meta": json.dumps(frf.meta, default=_jsonable),
            }
            if frf.coherence is not None:
                values["coherence"] = frf.coherence
            for name, data in values.items():
                f.create_dataset(name, data=data).attrs["units"] = _UNITS[name]
        os.replace(tmp, p)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise FRFFileError(f"{p}: cannot write the FRF file: {str(err).splitlines()[0]}") from err


def read_frf_h5(path: str | Path) -> FRFSet:
    """Read an FRF file written by :func:`write_frf_h5`.

    Returns
    -------
    FRFSet
        ``meta`` is the stored JSON object.

    Raises
    ------
    FRFFileError
        Missing, not HDF5, no ``format="insitu-frf"`` attribute, another schema version,
        or a dataset missing or inconsistent; one line naming the file and the problem.
    """
    p = Path(path)
    if not p.is_file():
        raise FRFFileError(f"{p}: no such FRF file")
    try:
        f = h5py.File(p, "r")
    except OSError as err:
        raise FRFFileError(f"{p}: not a readable HDF5 file (truncated or damaged?): "
                           f"{str(err).splitlines()[0]}") from err
    with f:
        if _str(f.attrs.get("format", "")) != FORMAT:
            raise FRFFileError(f"{p}: not an insitu FRF file (no format={FORMAT!r} attribute)")
        version = int(f.attrs.get("schema_version", -1))
        if version != SCHEMA_VERSION:
            raise FRFFileError(f"{p}: FRF-file schema version {version}; this insitu reads "
                               f"version {SCHEMA_VERSION}")
        try:
            geometry = Geometry(f["geometry/node_ids"][()], f["geometry/xyz"][()])
            meta = json.loads(_str(f["meta"][()]))
            return FRFSet(
                f["freq"][()], f["H"][()], f["resp_nodes"][()], f["resp_dirs"][()],
                f["exc_nodes"][()], f["exc_dirs"][()], geometry,
                f["coherence"][()] if "coherence" in f else None,
                meta if isinstance(meta, dict) else {},
            )
        except (KeyError, ValueError, TypeError) as err:
            raise FRFFileError(f"{p}: damaged FRF file: {str(err).splitlines()[0]}") from err


#: keys of ``/meta`` that files written before ``/provenance`` existed used for it
_OLD_PROVENANCE = ("exponential_tau", "force_band_top")


def read_frf_measurement(path: str | Path) -> Measurement:
    """The measurement of an FRF file: :func:`read_frf_h5` and the provenance kept with
    the FRFs (``/provenance``; a file written before it: the ``from_time_records``,
    ``exponential_tau`` and ``force_band_top`` entries of ``/meta``).

    Raises
    ------
    FRFFileError
        As :func:`read_frf_h5`, or a provenance field that is not a number.
    """
    p = Path(path)
    frf = read_frf_h5(p)
    try:
        with h5py.File(p, "r") as f:
            if "provenance" in f:
                attrs = {k: _str(v) for k, v in f["provenance"].attrs.items()}
            else:
                attrs = {k: str(v) for k in _OLD_PROVENANCE
                         if isinstance(v := frf.meta.get(k), int | float)}
                attrs["origin"] = "estimated" if frf.meta.get("from_time_records") else "given"
                attrs["estimator"] = str(frf.meta.get("estimator", "H1"))
        return Measurement(frf, Provenance.restored(attrs), p.name)
    except (OSError, ValueError) as err:
        raise FRFFileError(f"{p}: damaged FRF file: {str(err).splitlines()[0]}") from err
