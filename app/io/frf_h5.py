"""FRF files (HDF5): FRFs, coherence, DOFs, geometry and their provenance.

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

from app.io.replace import replacing
from processing.data import FRFSet, Geometry
from processing.measurement import Measurement, Provenance

__all__ = ["FORMAT", "READ_VERSIONS", "SCHEMA_VERSION", "FRFFileError", "h5_format",
           "read_frf_h5", "read_frf_measurement", "write_frf_h5"]

SCHEMA_VERSION = 2
#: versions read: 1 kept the provenance in a JSON ``/meta``, 2 in ``/provenance``
READ_VERSIONS = (1, 2)
FORMAT = "insitu-frf"

#: dataset -> units attribute (``/H``: accelerance, response unit per force unit)
_UNITS = {
    "freq": "Hz", "H": "m/s^2/N", "coherence": "1", "resp_nodes": "1", "resp_dirs": "1",
    "exc_nodes": "1", "exc_dirs": "1", "geometry/node_ids": "1", "geometry/xyz": "m",
}


class FRFFileError(ValueError):
    """The FRF file is missing, foreign, of another schema version or damaged (one line)."""


def _str(v: Any) -> str:
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def h5_format(path: str | Path) -> str:
    """The root ``format`` attribute of an HDF5 file (``"insitu-frf"``, ``"insitu-run"``).

    Returns ``""`` when the file cannot be opened plainly (not HDF5, missing, or a run
    file whose writer is still active) or has no such attribute.
    """
    import h5py  # HDF5 loads for HDF5 files only (11 MB a UFF's identification never needs)

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
    frf : FRFs (m/s^2/N) with their DOFs, geometry (m), optional coherence; a
        measurement's provenance is kept whole in the attributes of ``/provenance`` (the
        per-hit or per-block spectra and the reports are not kept; bare FRFs: given)
    source : what the FRFs were computed from (root attribute ``source``)

    Raises
    ------
    FRFFileError
        The file cannot be written.
    """
    import h5py

    p = Path(path)
    prov = frf.provenance if isinstance(frf, Measurement) else Provenance()
    frf = frf.frf if isinstance(frf, Measurement) else frf
    try:
        with replacing(p) as tmp, h5py.File(tmp, "w") as f:
            f.create_group("provenance").attrs.update(prov.stored())
            f.attrs.update({
                "format": FORMAT, "schema_version": SCHEMA_VERSION, "source": source,
                "estimator": prov.estimator,
                "created": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            })
            values: dict[str, Any] = {
                "freq": frf.freq, "H": frf.H, "resp_nodes": frf.resp_nodes,
                "resp_dirs": frf.resp_dirs, "exc_nodes": frf.exc_nodes,
                "exc_dirs": frf.exc_dirs, "geometry/node_ids": frf.geometry.node_ids,
                "geometry/xyz": frf.geometry.xyz,
            }
            if frf.coherence is not None:
                values["coherence"] = frf.coherence
            for name, data in values.items():
                f.create_dataset(name, data=data).attrs["units"] = _UNITS[name]
    except OSError as err:
        why = os.strerror(err.errno) if err.errno else str(err).splitlines()[0]
        raise FRFFileError(f"{p}: cannot write the FRF file: {why}") from err


def read_frf_measurement(path: str | Path) -> Measurement:
    """Read an FRF file written by :func:`write_frf_h5`: the FRFs and the provenance kept
    with them (``/provenance``; a version-1 file: its ``/meta`` entries ``from_time_records``,
    ``exponential_tau``, ``force_band_top``, ``n_averages``, ``estimator``, ``excitation``).

    Raises
    ------
    FRFFileError
        Missing, not HDF5, no ``format="insitu-frf"`` attribute, another schema version,
        or a dataset missing or inconsistent; one line naming the file and the problem.
    """
    p = Path(path)
    if not p.is_file():
        raise FRFFileError(f"{p}: no such FRF file")
    import h5py

    try:
        f = h5py.File(p, "r")
    except OSError as err:
        raise FRFFileError(f"{p}: not a readable HDF5 file (truncated or damaged?): "
                           f"{str(err).splitlines()[0]}") from err
    with f:
        if _str(f.attrs.get("format", "")) != FORMAT:
            raise FRFFileError(f"{p}: not an insitu FRF file (no format={FORMAT!r} attribute)")
        version = int(f.attrs.get("schema_version", -1))
        if version not in READ_VERSIONS:
            raise FRFFileError(f"{p}: FRF-file schema version {version}; this insitu reads "
                               f"versions {', '.join(map(str, READ_VERSIONS))}")
        try:
            geometry = Geometry(f["geometry/node_ids"][()], f["geometry/xyz"][()])
            frf = FRFSet(
                f["freq"][()], f["H"][()], f["resp_nodes"][()], f["resp_dirs"][()],
                f["exc_nodes"][()], f["exc_dirs"][()], geometry,
                f["coherence"][()] if "coherence" in f else None,
            )
            attrs = (dict(f["provenance"].attrs) if "provenance" in f
                     else _old_provenance(json.loads(_str(f["meta"][()]))))
            return Measurement(frf, Provenance.restored(attrs), p.name)
        except (KeyError, ValueError, TypeError) as err:
            raise FRFFileError(f"{p}: damaged FRF file: {str(err).splitlines()[0]}") from err


def _old_provenance(meta: object) -> dict[str, object]:
    """The provenance a version-1 file kept in its ``/meta`` JSON object."""
    meta = meta if isinstance(meta, dict) else {}
    attrs = {k: v for k in ("exponential_tau", "force_band_top", "n_averages", "estimator",
                            "excitation") if (v := meta.get(k)) is not None}
    attrs["origin"] = "estimated" if meta.get("from_time_records") else "given"
    if isinstance(attrs.get("n_averages"), int):
        attrs["n_averages"] = [attrs["n_averages"]]
    return attrs


def read_frf_h5(path: str | Path) -> FRFSet:
    """The FRFs of an FRF file (:func:`read_frf_measurement` without the provenance)."""
    return read_frf_measurement(path).frf
