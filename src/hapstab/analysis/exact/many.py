"""K_max of many loops at once."""

from __future__ import annotations

from collections.abc import Sequence

from hapstab.analysis.methods import critical_stiffness
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.results import CriticalStiffnessResult

__all__ = ["critical_stiffness_many"]


def critical_stiffness_many(loops: Sequence[HapticLoop | TeleoperationLoop]
                            ) -> list[CriticalStiffnessResult]:
    """The exact K_max of every loop: ``[critical_stiffness(loop) for loop in loops]``.

    Parameters
    ----------
    loops : sequence of HapticLoop or TeleoperationLoop
        The loops, in any order (kinds and structures may be mixed).

    Returns
    -------
    list of CriticalStiffnessResult
        One per loop, in the order given, each equal to ``critical_stiffness(loop)``.

    Raises
    ------
    HapstabError
        As :func:`~hapstab.analysis.methods.critical_stiffness` for the first loop it
        refuses.
    """
    return [critical_stiffness(loop) for loop in loops]
