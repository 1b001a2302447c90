"""From a file to its FRFs: the one path every view (command line, GUI, report) takes.

``open_frfs(path, settings) -> (FRFSet, [RunReport])`` reads any of the four input formats
(:mod:`app.pipeline.formats`), computes FRFs from time records (:mod:`app.pipeline.time_uff`)
or a run file's stored records (:mod:`app.pipeline.runs`), cuts them to their usable lines
and returns what it found on the way as reports instead of printing them.
"""

from app.pipeline.formats import (
    FORMATS,
    FRF_H5,
    FRF_UFF,
    RUN_FILE,
    SUFFIXES,
    TIME_UFF,
    detect_format,
    open_frfs,
)
from app.pipeline.settings import OpenError, RunReport, Settings, n_skipped

__all__ = ["FORMATS", "FRF_H5", "FRF_UFF", "RUN_FILE", "SUFFIXES", "TIME_UFF", "OpenError",
           "RunReport", "Settings", "detect_format", "n_skipped", "open_frfs"]
