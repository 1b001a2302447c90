"""Campaigns and large Monte Carlo on Dask distributed.

- :mod:`app.batch.cluster`: :func:`~app.batch.cluster.open_client`, a local cluster of worker
  processes by default or a running scheduler by address;
- :mod:`app.batch.campaign`: many files identified, one row per file (``insitu batch``);
- :mod:`app.batch.montecarlo`: a pure ``draw(seed) -> vector`` mapped over a cluster.
"""

from app.batch.campaign import identify_file, run_campaign, write_tables
from app.batch.cluster import SchedulerError, open_client
from app.batch.montecarlo import MassLineDraw, map_draws, monte_carlo

__all__ = ["MassLineDraw", "SchedulerError", "identify_file", "map_draws", "monte_carlo",
           "open_client", "run_campaign", "write_tables"]
