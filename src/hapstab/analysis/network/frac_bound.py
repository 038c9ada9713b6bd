"""A proved lower bound of the smallest crossing gain over a box of fractions, by branch
and bound over (theta, f) boxes, and a proved crossing above it.

The branch and bound asks each box for its bound (``box.lower(K_floor, target)``): the
HVE's G below (:mod:`~hapstab.analysis.network.frac_balls`); the PEB's two roots of a
quadratic in K, each analytic on a box and bounded by the same mean-value forms
(:func:`mean_value_lower`; :mod:`~hapstab.analysis.network.frac_balls_peb`).

**What is proved.** :func:`crossing_lower_bound` returns ``lower`` such that for every
f in [f_lo, f_hi], every theta in [0, pi] and every real K in [K_floor, lower), the
characteristic function det M(e^{j theta}, K, f) of
:mod:`~hapstab.analysis.network.modified_z` is not zero (by conjugate symmetry the
angles (pi, 2 pi) add nothing). Since K enters det M linearly, a zero at a real K is
the point where G(theta, f) = K is real; a box of (theta, f) is settled when the
mean-value enclosure of G on it (:mod:`~hapstab.analysis.network.frac_balls`)

* has an imaginary part without 0 (G is not real on the box), or
* has a real part below K_floor (its real values are crossings below the range), or
* has every real value at or above the target (its lower bound, below).

A box's lower bound is the largest of K_floor, the enclosure's real lower end and,
for lambda = Re G_t / Im G_t and Re G_f / Im G_f (any real lambda is valid),
the lower end of the mean-value form of L = Re G - lambda Im G, which equals Re G
where G is real; chosen so, L is stationary at a constrained minimum and its bound
is of second order in the box's radii (the "preconditioning" that closes the gap).
The bound is the smallest lower bound over the boxes left: no real crossing lies below
it. A box whose Nt_f ball contains 0 (a possible pole of G, where a zero of the modified
z-transform crosses the circle as f varies) gets |d|_lo / |Nt|_hi - 2 |beta|, since
|d| = |Nt| |H| <= |Nt| (K + 2 |beta|) at a crossing (and K_floor if that is lower).

**Stability.** The crossing bound alone says no pole meets the circle for K in
[K_floor, lower) and f in the interval. The roots of chi(z) (monic, degree n + 4 for
every f) are continuous in (K, f), so the number outside the circle is constant on that
connected set, and it is 0 there if it is 0 at one of its points (K_floor, f_0); see
:func:`~hapstab.analysis.network.frac_range.fraction_range_minimum` for the point and the
path to it.

References
----------
R. E. Moore, R. B. Kearfott and M. J. Cloud, *Introduction to Interval Analysis*, SIAM
2009, ch. 6 and 8 (mean-value forms, branch and bound); E. R. Hansen and G. W. Walster,
*Global Optimization Using Interval Analysis*, 2nd ed., Dekker 2004, ch. 12 (bounds on
a constrained minimum from the Lagrangian).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Any

from hapstab.analysis.network.frac_balls import BoxGain, FractionBalls
from hapstab.engine.arb_loop import working_precision

__all__ = ["CrossingBound", "crossing_lower_bound", "proved_crossing", "box_lower", "double_below",
           "double_above"]


@dataclass(frozen=True)
class CrossingBound:
    """The outcome of :func:`crossing_lower_bound`.

    Parameters
    ----------
    lower : float
        Proved: no real crossing K in [K_floor, lower) for f in the interval (inf: none
        at all).
    closed : bool
        Every box left has a lower bound at or above the target.
    boxes : int
        Boxes evaluated.
    worst : tuple of (float, float, float)
        (lower bound, theta, f) of the box with the smallest lower bound at the end:
        where the minimum lies.
    worst_fractions : tuple of (float, float)
        That box's fractions.
    """

    lower: float
    closed: bool
    boxes: int
    worst: tuple[float, float, float]
    worst_fractions: tuple[float, float] = (math.nan, math.nan)


def double_below(x: Any) -> float:
    """A double at or below the exact value of the arb point ``x``."""
    return math.nextafter(float(x), -math.inf)


def double_above(x: Any) -> float:
    """A double at or above the exact value of the arb point ``x``."""
    return math.nextafter(float(x), math.inf)


def box_lower(bx: BoxGain, k_floor: float) -> float | None:
    """The lower bound of a box (module docstring), or None when G is not real on it
    or only below K_floor."""
    if bx.nt.contains(0) or not (bx.centre.is_finite() and bx.d_theta.is_finite()
                                 and bx.d_f.is_finite()):
        # |d| = |Nt| |H| <= |Nt| (K + 2 |beta|) at a crossing
        nt_hi = bx.nt.abs_upper()
        if not nt_hi.is_zero() and nt_hi.is_finite():
            bound = bx.d.abs_lower() / nt_hi - 2 * bx.beta.abs_upper()
            if bound.is_finite():
                return max(k_floor, double_below(bound.lower()))
        return k_floor
    return mean_value_lower(bx.centre, bx.d_theta, bx.d_f, bx.r_theta, bx.r_f, k_floor)


def mean_value_lower(centre: Any, d_theta: Any, d_f: Any, r_theta: Any, r_f: Any,
                     k_floor: float) -> float | None:
    """A lower bound of the real values >= ``k_floor`` of an analytic function over a box
    from its mean-value form (module docstring: the enclosure and the preconditioned forms
    L = Re - lambda Im), or None when it is not real on the box or only below K_floor.

    Parameters
    ----------
    centre : acb
        Its value at the box's centre.
    d_theta, d_f : acb
        Its derivatives over the box.
    r_theta, r_f : arb
        The box's radii.
    k_floor : float
        Values below it are not examined.

    Returns
    -------
    float or None
    """
    from flint import acb, arb
    ht, hf = arb(0, r_theta), arb(0, r_f)
    enc = centre + d_theta * acb(ht) + d_f * acb(hf)
    if not enc.imag.contains(0) or enc.real < k_floor:
        return None
    best = max(k_floor, double_below(enc.real.lower()))
    for num, den in ((d_theta.real, d_theta.imag), (d_f.real, d_f.imag)):
        dm = float(den.mid())
        if dm == 0.0 or not math.isfinite(dm):
            continue
        lam = arb(float(num.mid()) / dm)
        form = (centre.real - lam * centre.imag + (d_theta.real - lam * d_theta.imag) * ht
                + (d_f.real - lam * d_f.imag) * hf)
        if form.is_finite():
            best = max(best, double_below(form.lower()))
    return best


def disc_lower(a0: Any, a1: Any, a2: Any, k_floor: float) -> float | None:
    """A lower bound of the real roots K >= ``k_floor`` of a_2 K^2 + a_1 K + a_0 for
    coefficients in the acb balls given: both roots lie in the disc of centre
    -a_1 / (2 a_2) and radius sqrt|D| / (2 |a_2|), D = a_1^2 - 4 a_0 a_2. None when the
    disc holds no real K >= ``k_floor``; ``k_floor`` when a_2's ball holds 0.

    Parameters
    ----------
    a0, a1, a2 : acb
        The coefficients' balls.
    k_floor : float
        Roots below it are not examined.

    Returns
    -------
    float or None
    """
    if a2.contains(0):
        return k_floor
    centre = -a1 / (2 * a2)
    rho = (a1 * a1 - 4 * a0 * a2).abs_upper().sqrt() / (2 * a2.abs_lower())
    if not rho.is_finite() or not centre.is_finite():
        return k_floor
    if centre.imag.abs_lower() > rho or centre.real + rho < k_floor:
        return None
    return max(k_floor, double_below((centre.real - rho).lower()))


def crossing_lower_bound(balls: Any, f_lo: float, f_hi: float, k_floor: float,
                         target: float, max_boxes: int = 20000) -> CrossingBound:
    """A proved lower bound of the real crossings K >= ``k_floor`` of G over
    [0, pi] x [f_lo, f_hi] (module docstring), refined until it reaches ``target`` or
    ``max_boxes`` boxes are spent.

    Parameters
    ----------
    balls : FractionBalls or PebFractionBalls
        The loop's ball evaluator.
    f_lo, f_hi : float
        The fractions, 0 <= f_lo <= f_hi <= 1.
    k_floor : float
        The base point K_0 (N/m): crossings below it are not examined.
    target : float
        Boxes whose lower bound is at or above it are not refined (N/m).
    max_boxes : int
        The budget.

    Returns
    -------
    CrossingBound
    """
    with working_precision(balls.prec):      # the same answer whatever Arb's global precision
        return _lower_bound(balls, f_lo, f_hi, k_floor, target, max_boxes)


def _lower_bound(balls: Any, f_lo: float, f_hi: float, k_floor: float,
                 target: float, max_boxes: int) -> CrossingBound:
    """:func:`crossing_lower_bound` at the precision already set."""
    from flint import arb
    pieces = max(32, 8 * balls.n1)
    heap: list[tuple[float, float, float, float, float]] = []
    lowest_settled, count = math.inf, 0

    def push(ta: float, tb: float, fa: float, fb: float) -> None:
        nonlocal lowest_settled, count
        count += 1
        th = arb((ta + tb) / 2, (tb - ta) / 2)
        fr = arb((fa + fb) / 2, (fb - fa) / 2)
        # the balls' centres and radii are rounded: widen to cover [ta, tb] x [fa, fb]
        th, fr = th.union(arb(ta)).union(arb(tb)), fr.union(arb(fa)).union(arb(fb))
        if tb == math.pi:                # the double pi is below pi: cover up to pi itself
            th = th.union(arb.pi())
        lb = balls.box(th, fr, key=(fa, fb)).lower(k_floor, target)
        if lb is None:
            return
        if lb >= target:
            lowest_settled = min(lowest_settled, lb)
        else:
            heapq.heappush(heap, (lb, ta, tb, fa, fb))

    for i in range(pieces):
        push(math.pi * i / pieces, math.pi * (i + 1) / pieces, f_lo, f_hi)
    while heap and count < max_boxes:
        _lb, ta, tb, fa, fb = heap[0]
        wt, wf = tb - ta, fb - fa
        if wt <= 4 * math.ulp(tb) and wf <= 4 * math.ulp(max(fb, 1.0)):
            break                                    # nothing left to split
        heapq.heappop(heap)
        # which side to split (a heuristic, not a proof): its rounded ball is not cached
        # under the piece's key, which must name only the balls push() widens over it
        bx = balls.box(arb((ta + tb) / 2, wt / 2), arb((fa + fb) / 2, wf / 2))
        sf, st = bx.split_scales()
        sf, st = sf * wf, st * wt
        if not (math.isfinite(sf) and math.isfinite(st)):
            sf, st = wf, wt / math.pi          # no derivatives: the wider side, relatively
        split_f = wf > 0 and (sf > st or wt <= 4 * math.ulp(tb))
        if split_f:
            fm = (fa + fb) / 2
            push(ta, tb, fa, fm)
            push(ta, tb, fm, fb)
        else:
            tm = (ta + tb) / 2
            push(ta, tm, fa, fb)
            push(tm, tb, fa, fb)
    lower = min(lowest_settled, heap[0][0] if heap else math.inf)
    worst = ((heap[0][0], (heap[0][1] + heap[0][2]) / 2, (heap[0][3] + heap[0][4]) / 2)
             if heap else (lower, math.nan, math.nan))
    return CrossingBound(lower, not heap, count, worst,
                         (heap[0][3], heap[0][4]) if heap else (math.nan, math.nan))


def proved_crossing(balls: FractionBalls, theta: float, f: float) -> float:
    """An upper bound, proved, of a real crossing of G at the fraction ``f`` near the
    angle ``theta`` (a float root of Im G): G's ball at theta = 0 or pi (real there),
    else Im G of opposite signs at theta (1 -/+ rel), rel = 1e-12 ... 1e-4 (so G is real
    in between) and the upper end of Re G over that interval (its mean-value form). At
    that K a pole of the loop with fraction f lies on the unit circle, so K_max(f) is at
    most it. inf when not proved.

    Parameters
    ----------
    balls : FractionBalls
        The loop's ball evaluator.
    theta, f : float
        The crossing's angle (rad/sample) and fraction.

    Returns
    -------
    float
    """
    with working_precision(balls.prec):
        return _proved_crossing(balls, theta, f)


def _proved_crossing(balls: FractionBalls, theta: float, f: float) -> float:
    """:func:`proved_crossing` at the precision already set."""
    from flint import arb
    fb = arb(f)
    if theta in (0.0, math.pi):
        g = balls.value(arb.pi() if theta else arb(0), fb)
        return double_above(g.real.upper()) if g.is_finite() and g.real > 0 else math.inf
    for rel in (1e-12, 1e-10, 1e-8, 1e-6, 1e-4):    # 1e-12..1e-4: brackets around a
        # float root (wider where G is a small difference of large terms, near K = 0)
        a, b = theta * (1 - rel), min(theta * (1 + rel), math.pi)
        ia, ib = balls.value(arb(a), fb).imag, balls.value(arb(b), fb).imag
        if (ia < 0 < ib) or (ib < 0 < ia):
            span = arb((a + b) / 2, (b - a) / 2).union(arb(a)).union(arb(b))
            bx = balls.box(span, fb)
            g = bx.enclosure() if not bx.nt.contains(0) else balls.value(span, fb)
            if g.is_finite() and g.real > 0:          # a crossing at a K > 0
                return double_above(g.real.upper())
    return math.inf
