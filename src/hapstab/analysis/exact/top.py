"""The top of the K range the proof examines, raised above every crossing it can find.

The float search (:mod:`~hapstab.analysis.exact.crossings`) looks for crossings up to
``U_HI`` times the loop's K scale m/T^2. A loop whose damping dwarfs its mass (an HVE
device with b = 1e13 N s/m at T = 1 ms: K_max ~ 2 b/T = 2e16 N/m, above U_HI m/T^2 =
1.05e16 N/m) has its first crossing above that, and a proof that stopped there would
call it "stable for every K > 0". Here the examined range is raised in ball
arithmetic (:func:`raise_top`): above the highest float crossing, then segment by
segment by exclusion (:func:`~hapstab.analysis.exact.proof.exclude`); a segment the
exclusion cannot clear holds a pole on (or within the balls' width of) the circle,
whose crossing Newton's method polishes from the boxes left
(:func:`~hapstab.analysis.exact.proof.polish`) so that the proof gets a window for it.

Above the top nothing is claimed unless the *tail* is proved (:func:`prove_tail`): in
u = K_T / K in [0, 1], ``u^D det M(e^{j theta}, K_T / u)`` (D the degree of det M in K)
is a polynomial in u whose value at u = 0 is the leading coefficient; when its balls
exclude 0 on [0, pi] x [0, 1], no pole is on the circle for any K >= K_T, and a stable
interval reaching K_T is stable for every larger K. Otherwise the range above the top
is reported uncertain and K_max is the (finite) top: never K_max = inf unproved.
"""

from __future__ import annotations

import heapq
import math

from hapstab.analysis.exact.polish import polish
from hapstab.analysis.exact.proof import Exclusion, exclude
from hapstab.analysis.exact.winding import FLOOR, start_pieces, theta_ball
from hapstab.engine.arb_loop import ArbLoop, working_precision

__all__ = ["raise_top", "prove_tail", "RAISE_STEP", "RAISE_STEPS", "TAIL_PIECES"]

#: Factor by which each segment examined above the float search's top is wider
#: than the last: 16 keeps the segments few (each one exclusion) and a crossing's
#: boxes narrow enough for Newton's method to start from.
RAISE_STEP = 16.0
#: Segments tried above the float search's top: 16^12 ~ 3e14 more, i.e. up to
#: K = 3e24 m/T^2, beyond any device; above that the range is reported uncertain.
RAISE_STEPS = 12
#: Boxes one segment's exclusion may try before its failures are polished (a crossing
#: shows up as a few boxes left at the floor; the valve keeps a wide segment cheap).
SEGMENT_PIECES = 1500
#: Boxes the tail's exclusion may try.
TAIL_PIECES = 4000


def _events_above(al: ArbLoop, ex: Exclusion, lo: float, hi: float) -> list[tuple]:
    """Crossings polished from the boxes an exclusion left, as float-search events
    ``(K, K, theta, 0, 1)`` in [lo, hi] (N/m). Newton's method is not a proof: it
    only places the windows, which the proof then checks."""
    found: set[tuple[float, float]] = set()
    for a, b, ka, kb in ex.failed[:64]:   # the lowest boxes: the first crossing is among them
        km = math.sqrt(ka * kb)
        tries = [(0.5 * (a + b), False)]
        if a == 0.0:
            tries.append((0.0, True))
        if b == math.pi:
            tries.append((math.pi, True))
        for th, real in tries:
            got = polish(al, th, km, real)
            # 1e-6: Newton may land just outside its segment's float ends; the window proves it
            if got is not None and lo * (1 - 1e-6) <= got[1] <= hi * (1 + 1e-6):
                found.add((got[1], got[0]))
    return [(k, k, t, 0, 1) for k, t in sorted(found)]


def raise_top(al: ArbLoop, events: tuple, k_top: float) -> tuple[float, tuple]:
    """The top of the examined range and the events to add for crossings above the
    float search's top (module doc).

    Parameters
    ----------
    al : ArbLoop
        The loop in balls.
    events : tuple
        The float search's events (N/m; ``StableSet.events``).
    k_top : float
        The float search's top (N/m).

    Returns
    -------
    top : float
        16 times the highest crossing known (the float search's or a polished one),
        at least ``k_top``; or the end of the last segment cleared when no crossing
        was found above (N/m).
    extra : tuple
        Events for the crossings found above the float search's top.
    """
    ks = [e[0] for e in events if e[4] != 0 and math.isfinite(e[2]) and math.isfinite(e[0])]
    lo = max([k_top] + [RAISE_STEP * k for k in ks])
    for _ in range(RAISE_STEPS):
        hi = lo * RAISE_STEP
        ex = exclude(al, lo, hi, SEGMENT_PIECES)
        if ex.failed:
            extra = _events_above(al, ex, lo, hi)
            if extra:
                return RAISE_STEP * max(e[0] for e in extra), tuple(extra)
            return hi, ()       # boxes left but no crossing placed: the proof decides there
        lo = hi
    return lo, ()


def _degree(al: ArbLoop) -> int:
    """The degree of det M in K (1 for one port, 2 for two: exact zeros in the balls)."""
    P, Q, _ = al.parts(theta_ball(1.0, 1.0))
    return 2 if not (P[2].is_zero() and Q[2].is_zero()) else 1


def _tail_box(al: ArbLoop, deg: int, k_from: float, a: float, b: float, ua: float,
              ub: float) -> bool:
    """Whether u^D det M(theta, k_from / u) has no zero on [a, b] x [ua, ub]."""
    from flint import arb
    P, Q, w = al.parts(theta_ball(a, b))
    with working_precision(al.prec):
        u = arb(ua).union(arb(ub))
        K = arb(k_from)
        # u^D (c0 + c1 K/u + c2 K^2/u^2) = c0 u^D + c1 K u^(D-1) + c2 K^2 u^(D-2)
        coef = [P[i] + w * Q[i] for i in range(3)]
        val = coef[deg] * K ** deg
        for i in range(deg - 1, -1, -1):
            val = val + coef[i] * K ** i * u ** (deg - i)
        return not val.contains(0)


def prove_tail(al: ArbLoop, k_from: float, max_pieces: int = TAIL_PIECES) -> bool:
    """Whether no pole of the closed loop is on the unit circle for any K >= k_from
    (module doc), by exclusion of [0, pi] x u in [0, 1], u = k_from / K.

    Parameters
    ----------
    al : ArbLoop
    k_from : float
        The lower end of the tail (N/m, > 0).
    max_pieces : int
        Safety valve on the boxes tried (beyond it: not proved).

    Returns
    -------
    bool
        True: proved; False: not proved (the tail is then uncertain).
    """
    deg = _degree(al)
    heap = [(0.0, a, b, 1.0) for a, b in start_pieces()]
    heapq.heapify(heap)
    tried = 0
    while heap:
        ua, a, b, ub = heapq.heappop(heap)
        tried += 1
        if tried > max_pieces:
            return False
        if _tail_box(al, deg, k_from, a, b, ua, ub):
            continue
        th_ok, u_ok = (b - a) > FLOOR * b, (ub - ua) > FLOOR * ub
        if not (th_ok or u_ok):
            return False        # a box at the floor keeps 0: not proved
        if th_ok and ((b - a) / math.pi >= ub - ua or not u_ok):
            m = 0.5 * (a + b)
            heapq.heappush(heap, (ua, a, m, ub))
            heapq.heappush(heap, (ua, m, b, ub))
        else:
            m = 0.5 * (ua + ub)
            heapq.heappush(heap, (ua, a, b, m))
            heapq.heappush(heap, (m, a, b, ub))
    return True
