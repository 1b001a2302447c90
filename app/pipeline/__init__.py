"""From a file to its measurement: the one path every view (command line, GUI, report,
batch) takes.

``load(path, settings) -> Measurement`` reads any of the six input formats
(:mod:`app.pipeline.formats`), computes FRFs from time records (:mod:`app.pipeline.time_uff`)
or a run file's stored records (:mod:`app.pipeline.runs`), cuts them to their usable lines
and keeps what it found on the way as reports in the measurement's provenance instead of
printing them. Every view then calls :func:`processing.identify.fit` on it.
"""

from app.pipeline.formats import (
    FORMATS,
    FRF_H5,
    FRF_UFF,
    RUN_FILE,
    SUFFIXES,
    TIME_FORMATS,
    TIME_MDF,
    TIME_TDMS,
    TIME_UFF,
    detect_format,
    load,
)
from app.pipeline.settings import OpenError, RunReport, Settings, n_skipped

__all__ = ["FORMATS", "FRF_H5", "FRF_UFF", "RUN_FILE", "SUFFIXES", "TIME_FORMATS", "TIME_MDF",
           "TIME_TDMS", "TIME_UFF", "OpenError",
           "RunReport", "Settings", "detect_format", "load", "n_skipped"]
