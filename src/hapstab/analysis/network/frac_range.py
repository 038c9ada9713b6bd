"""The certified minimum of K_max over a continuum of constant delays that act between
the sampling instants (the HVE, and the PEB with the same one-way delay both ways), and
the worst delay.

**The model.** The controller acts at kT on the position sampled at kT - tau: e[k] =
x(kT - tau) with tau = (n + f)T any constant delay of [tau_lo, tau_hi] (the engine's
fractional delay; :mod:`~hapstab.analysis.network.modified_z` for the HVE as a
modified z-transform, :mod:`~hapstab.analysis.network.modified_z_peb` for the PEB, each
direction's delayed position sampled at kT - tau: chi monic of degree 2n + 8, K entering
as a quadratic; :func:`fraction_model` picks the model by the loop's number of ports).
K_max(tau) is continuous in tau and not monotone, so no finite
set of delays answers; the range is cut at the whole samples into segments
{n} x [f_a, f_b] and each is covered by a proof.

**The answer for one segment** (:func:`fraction_range_minimum`):

1. *Where the minimum is* (doubles, nothing proved): the first crossing of the float
   model on a grid of fractions, refined by a bounded scalar search.
2. *An upper end, proved*: at that fraction f_w a real crossing of G
   (:func:`~hapstab.analysis.network.frac_bound.proved_crossing`), so K_max(f_w) is at
   most it; and the exact core's K_max at the point (n + f_w), reported beside it.
3. *The lower end, proved* (:func:`~hapstab.analysis.network.frac_bound.crossing_lower_bound`):
   no real crossing K in [K_0, K_low) for f in [f_a, f_b].
4. *Stability below it*: the exact core proves the whole delay n (both ways, for the
   PEB) stable on [K_0, K_max(n)] in ball arithmetic (f = 0 of the segment); a second
   bound proves no crossing at K in [K_0, 2 K_0) for f in [0, f_a], so the path
   (K_0, 0) -> (K_0, f_a) meets no crossing; the roots of chi (monic of fixed degree
   n + 4, the PEB's 2n + 8, continuous in (K, f)) then cannot leave the unit disc
   anywhere on [K_0, K_low) x [f_a, f_b], which is connected to that path. Every delay
   of the segment is stable for K in [K_0, K_low).

The range's answer is the smallest K_low over its segments (a proved lower bound of
min K_max) with the smallest upper end as the enclosure's top. When a segment's gap stays
open, the float search is run again on the fractions of the branch and bound's lowest box
(up to :data:`RESEEDS` times: the scan may have stepped over a narrow dip) and the bound
redone with the lower target; a gap still open within the budget is reported with the
lower end, *uncertain*.
K_0 is the exact core's base point (:func:`hapstab.engine.arb_loop.base_point`): what
holds for K in (0, K_0) is not proved, as for every certified K_max.

References
----------
E. I. Jury, *Theory and Application of the z-Transform Method*, Wiley 1964, ch. 2;
K. J. Astrom and B. Wittenmark, *Computer-Controlled Systems*, 3rd ed., sec. 2.7
(fractional delays, the modified z-transform); R. E. Moore, R. B. Kearfott and
M. J. Cloud, *Introduction to Interval Analysis*, SIAM 2009, ch. 6 and 8.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.analysis.network.modified_z import fractional_plant
from hapstab.analysis.network.modified_z_peb import peb_fractional_plant

__all__ = ["Segment", "fraction_range_minimum", "fraction_model", "segments_of", "RTOL",
           "MAX_BOXES"]

#: The gap at which a segment's enclosure is closed: K_low >= upper (1 - RTOL). The
#: acceptance asks 1e-6 of the grid's minimum; the branch and bound's second-order
#: bounds reach 1e-9 in a few thousand boxes.
RTOL = 1e-9
#: Boxes per segment (each ~0.25 ms of ball arithmetic) before the gap is reported open.
MAX_BOXES = 40000
#: Fractions of the float scan of a segment (plus the bounded search after it).
SCAN_FRACTIONS = 33
#: Searches of the float model where the branch and bound's lowest box is, when a gap
#: stays open (the scan may step over a narrow dip of K_max)
RESEEDS = 2
#: Seconds a segment costs besides the exact core's K_max at its whole delay, and per
#: sample of delay (the angle pieces 8 (n + 1) of the branch and bound and the float
#: scan's 64 (n + 1) angles). Measured on the shared 2-core machine (load 3-6): the
#: paper's HVE over 5-15 ms 0.67-1.8 s (estimate 2.4 s), 95-100 ms 1.8 s (2.3 s), a
#: hand-held device over 998-1000 ms 4.9 s (5.6 s)
SEGMENT_SECONDS, SEGMENT_SECONDS_PER_SAMPLE = 0.2, 2.5e-3


@dataclass(frozen=True)
class Segment:
    """One whole part n of the range and its fractions, with its proved answer.

    Parameters
    ----------
    whole : int
        n.
    f_lo, f_hi : float
        The fractions, 0 <= f_lo <= f_hi <= 1 (f = 1 is the whole delay n + 1).
    lower : float
        Proved: stable for K in [K_0, lower) at every fraction of the segment (N/m).
    upper : float
        Proved: K_max at ``worst_fraction`` is at most this (N/m; inf if not proved).
    worst_fraction : float
        Where the float search put the segment's minimum.
    kmax_at_worst : float
        The exact core's K_max at n + worst_fraction (N/m).
    boxes : int
        Boxes the proofs spent.
    """

    whole: int
    f_lo: float
    f_hi: float
    lower: float
    upper: float
    worst_fraction: float
    kmax_at_worst: float
    boxes: int


def segments_of(lo: float, hi: float) -> list[tuple[int, float, float]]:
    """The range [lo, hi] (samples) cut at the whole samples: (n, f_a, f_b) with
    n + f in it for f in [f_a, f_b]. An end within the one snap rule
    (:data:`~hapstab.tolerances.DELAY_SNAP`) of a whole number is moved onto it only
    outwards (lo down, hi up: the range covered is a superset, so its minimum stays at
    or below the asked range's); inwards it keeps its fraction (10 - 9e-9 samples is
    (9, 1 - 9e-9, 1) and (10, 0, ...): snapping it to 10 left a sliver of delays out of
    the proof, and a K_max 1.2e-8 above the truth was reported certified).

    Parameters
    ----------
    lo, hi : float
        The range in samples, 0 <= lo <= hi.

    Returns
    -------
    list of (int, float, float)
    """
    from hapstab.models.delays import split_delay
    n_lo, f_lo = split_delay(lo)
    if n_lo + f_lo > lo:        # snapped up: [lo, n_lo) would be left out of the proof
        n_lo = math.floor(lo)
        f_lo = lo - n_lo        # exact (Sterbenz)
    n_hi, f_hi = split_delay(hi)
    if n_hi + f_hi < hi:        # snapped down: (n_hi, hi] would be left out
        n_hi = math.floor(hi)
        f_hi = hi - n_hi
    if (n_lo, f_lo) == (n_hi, f_hi):
        return [(n_lo, f_lo, f_lo)]
    out = []
    for n in range(n_lo, n_hi + 1):
        a = f_lo if n == n_lo else 0.0
        b = f_hi if n == n_hi else 1.0
        if b > a or (n == n_lo and n == n_hi):
            out.append((n, a, b))
    return out


def fraction_model(loop: Any, whole: int) -> Any:
    """The loop's float model with a fractional delay, by its number of ports: one, the
    HVE's (:mod:`~hapstab.analysis.network.modified_z`); two, the PEB's with the same
    delay both ways (:mod:`~hapstab.analysis.network.modified_z_peb`). Its ``balls()``
    is the ball evaluator the proofs use.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (its delay is replaced).
    whole : int
        n.

    Returns
    -------
    FractionalPlant or PebFractionalPlant

    Raises
    ------
    AnalysisError
        A loop outside both models, naming what.
    """
    make = {2: peb_fractional_plant}.get(len(loop.port_names), fractional_plant)
    return make(loop, whole)


def _float_worst(plant: Any, f_lo: float, f_hi: float, k0: float
                 ) -> tuple[float, float, float]:
    """(K, theta, f) of the smallest float first crossing over [f_lo, f_hi]: a scan of
    :data:`SCAN_FRACTIONS` fractions and a bounded search around its best."""
    from scipy.optimize import minimize_scalar
    if f_hi == f_lo:
        k, th = plant.first_crossing(f_lo, k0)
        return k, th, f_lo
    fs = np.linspace(f_lo, f_hi, SCAN_FRACTIONS)
    got = [plant.first_crossing(float(f), k0) for f in fs]
    i = int(np.argmin([g[0] for g in got]))
    best = (got[i][0], got[i][1], float(fs[i]))
    if not math.isfinite(best[0]):
        return best
    a, b = float(fs[max(i - 1, 0)]), float(fs[min(i + 1, fs.size - 1)])
    res = minimize_scalar(lambda f: plant.first_crossing(float(f), k0)[0], bounds=(a, b),
                          method="bounded", options={"xatol": 1e-12})  # 1e-12: f to rounding
    if res.fun < best[0]:
        k, th = plant.first_crossing(float(res.x), k0)
        best = (k, th, float(res.x))
    return best


def _base_is_stable(loop: Any, whole: int, k0: float) -> bool:
    """Whether the exact core proves the whole delay ``whole`` stable at K_0 in ball
    arithmetic (its proved range starts at K_0 and ends above it)."""
    from hapstab.analysis.methods import critical_stiffness
    res = critical_stiffness(loop.with_whole_delay(whole))
    rng = res.details.get("proved_range_N_per_m")
    return (str(res.details.get("proof", "")).startswith("ball")
            and rng is not None and rng[0] <= k0 < rng[1])


def _core_kmax(loop: Any, whole: int, f: float) -> float:
    """The exact core's K_max at the delay n + f (f = 1: the whole delay n + 1)."""
    from hapstab.analysis.methods import critical_stiffness
    at = (loop.with_whole_delay(whole + 1) if f >= 1.0
          else loop.with_whole_delay(whole).replace(fractional_delay=f))
    return float(critical_stiffness(at).critical_stiffness)


@dataclass
class _Work:
    """One segment while its bound is refined."""

    whole: int
    f_lo: float
    f_hi: float
    plant: Any
    balls: Any
    worst: tuple[float, float, float]        # float (K, theta, f)
    upper: float = math.inf                  # proved crossing at worst's f
    boxes: int = 0


def _prepare(loop: Any, segs: list[tuple[int, float, float]], k0: float) -> list[_Work]:
    """Each segment's plant, balls, float worst point and proved crossing there."""
    out = []
    for n, a, b in segs:
        plant = fraction_model(loop, n)
        w = _Work(n, a, b, plant, plant.balls(), _float_worst(plant, a, b, k0))
        if math.isfinite(w.worst[0]):
            w.upper = w.balls.proved_crossing(w.worst[1], w.worst[2])
        out.append(w)
    return out


def _base(loop: Any, w: _Work, k0: float, max_boxes: int) -> bool:
    """Step 4 of the module docstring: the whole delay n proved stable at K_0 and no
    crossing at K_0 for f in [0, f_a]."""
    from hapstab.analysis.network.frac_bound import crossing_lower_bound
    if not _base_is_stable(loop, w.whole, k0):
        return False
    if w.f_lo > 0.0:
        path = crossing_lower_bound(w.balls, 0.0, w.f_lo, k0, 2.0 * k0, max_boxes)
        w.boxes += path.boxes
        return path.closed
    return True


def _reseed(w: _Work, box: tuple[float, float], k0: float) -> bool:
    """Search the float model on the fractions ``box`` of the branch and bound's lowest
    box (widened by a scan step); True, with the segment's worst point and proved
    crossing updated, if it finds a lower crossing than the one it had."""
    half = (w.f_hi - w.f_lo) / (2 * SCAN_FRACTIONS)
    got = _float_worst(w.plant, max(w.f_lo, box[0] - half), min(w.f_hi, box[1] + half), k0)
    if not got[0] < w.worst[0]:
        return False
    up = w.balls.proved_crossing(got[1], got[2])
    if not up < w.upper:
        return False
    w.worst, w.upper = got, up
    return True


def _bound(w: _Work, k0: float, target: float, max_boxes: int
           ) -> tuple[float, tuple[float, float] | None]:
    """Step 3 of the module docstring: (the segment's proved lower end, the fractions
    of its lowest box left: None when closed)."""
    from hapstab.analysis.network.frac_bound import crossing_lower_bound
    got = crossing_lower_bound(w.balls, w.f_lo, w.f_hi, k0, target, max_boxes)
    w.boxes += got.boxes
    return got.lower, (None if got.closed else got.worst_fractions)


def fraction_range_minimum(loop: Any, lo: float, hi: float, *, rtol: float = RTOL,
                           max_boxes: int = MAX_BOXES
                           ) -> tuple[list[Segment], float, float, float]:
    """Proved enclosure of min K_max over every delay n + f of [lo, hi] samples (HVE,
    module docstring).

    Parameters
    ----------
    loop : HapticLoop
        The loop (its delay is replaced).
    lo, hi : float
        The range in samples, 0 <= lo <= hi (fractions allowed).
    rtol : float
        The relative gap at which a segment's bound stops refining.
    max_boxes : int
        Boxes per segment and proof.

    Returns
    -------
    (segments, lower, upper, K_0)
        Each :class:`Segment`; ``lower``: proved, every delay of the range is stable for
        K in [K_0, lower); ``upper``: proved, some delay of the range has K_max <= upper;
        the base point K_0 (N/m).
    """
    from hapstab.engine.arb_loop import arb_parameters, base_point
    segs = segments_of(lo, hi)
    fraction_model(loop, segs[0][0])                 # refuses a loop outside the model
    _check_cost(segs, len(loop.port_names))
    k0 = base_point(arb_parameters(loop.with_whole_delay(segs[0][0])))   # type: ignore[arg-type]
    work = _prepare(loop, segs, k0)
    upper = min(w.upper for w in work)
    lowers = []
    for w in work:
        lower = 0.0
        for _ in range(RESEEDS + 1) if _base(loop, w, k0, max_boxes) else ():
            target = upper * (1.0 - rtol) if math.isfinite(upper) else math.inf
            lower, box = _bound(w, k0, target, max_boxes)
            # a gap left open: the float search may have missed where the minimum is
            if box is None or not _reseed(w, box, k0):
                break
            upper = min(upper, w.upper)
        lowers.append(min(lower, upper))
    best = min(work, key=lambda w: w.upper)
    out = []
    for w, lower in zip(work, lowers, strict=True):
        core = _core_kmax(loop, w.whole, w.worst[2]) if w is best else math.nan
        out.append(Segment(w.whole, w.f_lo, w.f_hi, lower, w.upper, w.worst[2], core, w.boxes))
    return out, min(s.lower for s in out), upper, k0


def _check_cost(segs: list[tuple[int, float, float]], ports: int) -> None:
    """Refuse, before any work, a range over the budget: per segment the exact core's
    K_max at its whole delay (:func:`hapstab.budget.exact_search_cost`) plus
    :data:`SEGMENT_SECONDS` and :data:`SEGMENT_SECONDS_PER_SAMPLE` per sample of delay
    and port (the PEB's degree 2n + 8 is twice the HVE's)."""
    from hapstab.budget import Cost, check, exact_search_cost
    n = segs[-1][0] + 1
    one = exact_search_cost(n, ports)
    check(Cost(f"delay range between the samples: {len(segs)} segment(s) up to {n} samples",
               one.memory_bytes,
               len(segs) * (one.seconds + SEGMENT_SECONDS
                            + SEGMENT_SECONDS_PER_SAMPLE * n * ports)))
