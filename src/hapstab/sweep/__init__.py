"""Design sweeps at scale: the exact K_max (and the passivity limit, the paper's closed
form, a verdict at given K, the best damping) over millions of loops, in Parquet chunks,
resumable, on local processes or a Dask cluster (:func:`hapstab.sweep.run.sweep`).

Nothing here imports Dask or pyarrow until a sweep runs (``pip install 'hapstab[sweep]'``).
"""

import sys
import types
from typing import Any

from hapstab.sweep.axes import Axis, Points, SweepError, parse_axis
from hapstab.sweep.result import SweepResult
from hapstab.sweep.run import sweep

__all__ = ["sweep", "SweepResult", "SweepError", "Axis", "Points", "parse_axis"]


class _CallableModule(types.ModuleType):
    """This package, callable as :func:`sweep`: importing a submodule (``from
    hapstab.sweep.axes import ...``) makes Python bind ``hapstab.sweep`` to this package,
    which would otherwise hide the function ``hapstab.sweep`` (PEP 562 lazy names)."""

    def __call__(self, *args: Any, **kwargs: Any) -> SweepResult:
        return sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
