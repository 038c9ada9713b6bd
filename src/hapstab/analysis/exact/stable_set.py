"""The stable set in K of one loop, from the events the crossing search found: the
crossings (K, angle, direction, multiplicity) and the zones it could not resolve,
each in units of the loop's K scale.

An event is ``(a, b, theta, direction, multiplicity)``: a crossing has ``a = b`` and
multiplicity >= 1; an unresolved zone has ``a < b`` and multiplicity 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from hapstab.errors import AnalysisError

__all__ = ["StableSet", "first_only", "stable_set"]


@dataclass(frozen=True)
class StableSet:
    """The exact stable set in K of one loop (what :func:`analyse` finds).

    Attributes
    ----------
    kmax : float
        K_max in N/m: the end of the stable interval that starts at K = 0 (0 if
        none, inf if unbounded).
    intervals : tuple of (float, float)
        Every stable interval of K in N/m (only ``((0, kmax),)`` when asked for
        K_max alone).
    theta : float
        Angle (rad/sample) of the crossing at K_max; nan if none.
    rigid : int
        Rigid-body modes divided out (0 or 1).
    outside_small_K : int
        Poles outside the unit circle as K -> 0+ (-1: not certifiable).
    uncertain : tuple of (float, float)
        K-intervals (N/m) the numerics could not resolve.
    events : tuple of (float, float, float, int, int)
        What the float search found, in N/m: ``(K_a, K_b, theta, direction,
        multiplicity)``, a crossing (K_a = K_b) or an unresolved zone (multiplicity 0):
        the candidates the ball-arithmetic proof (:mod:`~hapstab.analysis.exact.proof`)
        starts from.
    proof : object, optional
        The ball-arithmetic proof of this stable set (None: the float enclosures alone).
    """

    kmax: float
    intervals: tuple[tuple[float, float], ...]
    theta: float
    rigid: int
    outside_small_K: int
    uncertain: tuple[tuple[float, float], ...]
    events: tuple[tuple[float, float, float, int, int], ...] = ()
    proof: Any = None


def first_only(events: list[Any], anchor: int, s: float) -> dict[str, Any]:
    """K_max alone: the first event above a loop stable at small K.

    Parameters
    ----------
    events : list of tuple
        The events in increasing K (see the module notes).
    anchor : int
        Poles outside the circle as K -> 0+.
    s : float
        The K scale: an event's K times ``s`` is in N/m.

    Returns
    -------
    dict
        ``kmax``, ``intervals``, ``theta``, ``uncertain`` of a :class:`StableSet`.

    Raises
    ------
    AnalysisError
        The first crossing of a loop stable at small K points inwards (a bug).
    """
    if anchor > 0:
        return {"kmax": 0.0, "intervals": (), "theta": math.nan, "uncertain": ()}
    if not events:
        return {"kmax": math.inf, "intervals": ((0.0, math.inf),), "theta": math.nan,
                "uncertain": ()}
    a, b, t, d, m = events[0]
    if d < 0:
        raise AnalysisError("crossing analysis: the first crossing points inwards while no "
                            "pole is outside; please report this loop")
    kmax = a * s
    uncertain: tuple[tuple[float, float], ...] = ((a * s, b * s),) if m == 0 else ()
    return {"kmax": kmax, "intervals": ((0.0, kmax),) if kmax > 0 else (), "theta": t,
            "uncertain": uncertain}


def stable_set(events: list[Any], counts: list[int | None], s: float) -> dict[str, Any]:
    """The gaps with no pole outside, merged into intervals of K; K_max is the first
    if it starts at 0; the unresolved zones that border a stable (or unknown) gap.

    Parameters
    ----------
    events : list of tuple
        The events in increasing K (see the module notes).
    counts : list of int or None
        Poles outside in each gap: before the first event, then after each (None:
        not certifiable).
    s : float
        The K scale: an event's K times ``s`` is in N/m.

    Returns
    -------
    dict
        ``kmax``, ``intervals``, ``theta``, ``uncertain`` of a :class:`StableSet`.
    """
    edges_lo = [0.0] + [b * s for a, b, *_ in events]
    edges_hi = [a * s for a, b, *_ in events] + [math.inf]
    thetas = [t for _, _, t, _, _ in events]
    intervals: list[tuple[float, float]] = []
    upper: list[int] = []
    kmax, theta = 0.0, math.nan
    for g, cnt in enumerate(counts):
        if cnt == 0:
            lo, hi = edges_lo[g], edges_hi[g]
            if intervals and intervals[-1][1] == lo:
                intervals[-1] = (intervals[-1][0], hi)
                upper[-1] = g
            else:
                intervals.append((lo, hi))
                upper.append(g)
    if intervals and intervals[0][0] == 0.0:
        kmax = intervals[0][1]
        theta = thetas[upper[0]] if upper[0] < len(thetas) else math.nan
    uncertain = tuple((a * s, b * s) for g, (a, b, t, d, m) in enumerate(events)
                      if m == 0 and (counts[g] in (0, None) or counts[g + 1] in (0, None)))
    return {"kmax": float(kmax), "intervals": tuple(intervals), "theta": theta,
            "uncertain": uncertain}
