"""Design sweeps at scale: the exact K_max (and the passivity limit, the paper's closed
form, a verdict at given K, the best damping) over millions of loops, in Parquet chunks,
resumable, on local processes or a Dask cluster (:func:`hapstab.sweep.run.sweep`).

Nothing here imports Dask or pyarrow until a sweep runs (``pip install 'hapstab[sweep]'``).
"""

from hapstab.sweep.axes import Axis, Points, SweepError, parse_axis
from hapstab.sweep.result import SweepResult
from hapstab.sweep.run import sweep

__all__ = ["sweep", "SweepResult", "SweepError", "Axis", "Points", "parse_axis"]
