"""The proof of a stable set in ball arithmetic: what "certified" means in hapstab.

The float search (:mod:`~hapstab.analysis.exact.crossings`) proposes the K at which a
pole crosses the unit circle. This module proves, on :class:`~hapstab.engine.arb_loop.ArbLoop`
(Arb balls from the loop's numbers alone), a stable set around them:

1. each proposed crossing is polished by Newton's method on det M(e^{j theta}, K) = 0
   at the working precision (not a proof: it only places the windows), and gets a
   *window* [K (1 - DELTA), K (1 + DELTA)];
2. between windows, a *gap* [K_a, K_b] is proved free of poles on the circle: the
   rectangle theta in [0, pi] x K in [K_a, K_b] is cut into pieces, each excluded by
   a ball that does not contain 0 -- either ``|P| > |Q|`` or ``|Q| > |P|`` over the
   piece (det M = P + w Q with |w| = 1: the delay's phase plays no part) or the ball of
   det M itself (:func:`exclude`). theta in [pi, 2 pi] is the mirror image (det M is
   real on real K and conj-symmetric in theta);
3. in each proved gap the number of poles outside is constant and is counted by the
   argument principle at one point, Z_out = q - wind(det M) (:func:`count`), the
   winding summed over pieces whose balls exclude 0 (each increment is then a
   principal argument);
4. the stable set is the union of the proved gaps with count 0; K_max is the upper
   end of the one that starts at the base point K_0 (the safe end of the window of the
   first crossing). The window is an *enclosure* of the true K_max when the count
   after it is proved > 0. A gap that cannot be proved is reported *uncertain* with
   its extent, never as stable.

The base point K_0 (:func:`~hapstab.engine.arb_loop.base_point`: 1e-14 times the
smaller of the loop's K scale m/T^2 and its damping scale b/T) stands for K -> 0+:
what is proved is [K_0, K_max]; what holds for (0, K_0) is not proved (a pole could
only cross the circle there at a stiffness 1e-14 of the device's own scale). Above
the top of the examined range nothing is claimed unless the tail is proved
(:mod:`~hapstab.analysis.exact.top`). The certificate
(:func:`~hapstab.analysis.exact.certificate.certificate`) lists every piece, so anyone
can re-check it (:mod:`hapstab.analysis.verify`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from hapstab.analysis.exact.polish import polish
from hapstab.analysis.exact.winding import (
    FLOOR,
    GEOMETRIC,
    MAX_PIECES,
    Count,
    count,
    k_ball,
    split_theta,
    subdivision_start,
    theta_ball,
)
from hapstab.engine.arb_forms import angle_parts, exclusion_test, stiffness_parts
from hapstab.engine.arb_loop import ArbLoop, working_precision

__all__ = ["Proof", "prove", "prove_base", "count", "exclude", "theta_ball", "DELTA"]

#: Half-width of a crossing's window, relative: far inside the 1e-9 the reported
#: K_max may lie below the truth, and far above the working precision's reach
#: (Newton places the crossing to ~1e-60 at 320 bits), so a window always holds it.
DELTA = 2.0 ** -40
#: The valve for a gap above K_max's window that meets only a zone the float search
#: left unresolved (not its stable set): such zones lie where |P| ~ |Q| over all of
#: [0, pi] (high K on a long delay), where no piece budget short of ~n settles them,
#: and they are reported uncertain either way; a valve on time, not a tolerance.
MAX_PIECES_UNSURE = 400
#: Half-width of the window of a candidate that is not polished (relative): the float
#: search places its crossings to ~1e-13, so the window holds the crossing; a gap
#: beside it that is examined then proves up to 1e-9 below the truth (the safe side).
ROUGH = 1e-9
#: The gap pieces are proved with the angle kernel of precomputed ball polynomials
#: (:mod:`~hapstab.engine.arb_kernel`, certificate version 4); False: forward-mode
#: derivatives (version 3; the checker still reads both).
POLY_KERNEL = True
#: A box the four tests leave is tried by the iterated Krawczyk operator
#: (:mod:`~hapstab.engine.arb_krawczyk`, ``"I"``, certificate version 5, with
#: :data:`POLY_KERNEL`) before it is split: next to a crossing it excludes in a few steps
#: what halving excluded in ~60 boxes. False: version 4 (the checker reads both).
KRAWCZYK = True
#: Version 4's subdivision of a gap (with :data:`POLY_KERNEL`; the angles':
#: :func:`~hapstab.analysis.exact.winding.subdivision_start` and
#: :func:`~hapstab.analysis.exact.winding.split_theta`): a K-range with
#: k1 > K_WIDE k0 is cut at k1 / K_TOP (its top, where the crossing is, peeled off),
#: narrower ones as before (geometric mean above GEOMETRIC, else the midpoint).
#: Choices of where to cut, not tolerances: any cut is replayed by the checker and
#: every piece proved.
K_WIDE = 64
K_TOP = 8
#: Widening of the float search's intervals when choosing which candidates to polish
#: (relative, far above ROUGH: see :func:`_needs_polish`).
HINT_MARGIN = 1e-6


def box_status(al: ArbLoop, a: float, b: float, ka: float, kb: float,
               entries: dict | None = None) -> tuple[str | None, float]:
    """Whether det M has no zero on [a, b] x [ka, kb]; the reason, and the share of
    the ball's width due to theta (to choose the split). ``entries``: the angle pieces'
    kernels (:meth:`~hapstab.engine.arb_loop.ArbLoop.kernel_entry`) formed so far at
    the precision in force, by ends (the boxes of one piece at several K-ranges share
    its ball and kernel without looking them up and comparing balls again).

    Returns
    -------
    status : {"P", "Q", "F", "N", "I"} or None
        ``"P"``: |P| > |Q| on the box; ``"Q"``: |Q| > |P|; ``"F"``: 0 not in the ball
        of P + w Q; ``"N"``: nor in its preconditioned ball; ``"I"``: the iterated
        Krawczyk operator pins every zero the box may hold outside it (:data:`KRAWCZYK`);
        None: not excluded.
    theta_share : float
        In [0, 1]: how much of the ball's width comes from theta rather than K (the
        spreads :meth:`~hapstab.engine.arb_loop.ArbLoop.exclusion` returns; 0 when
        excluded).
    """
    cache = {} if entries is None else entries
    ent, kp = cache.get((a, b)), cache.get((ka, kb, "K"))
    # the balls at the caller's precision (the proof's, set by exclude()), what the tests
    # form of them at the loop's, as ArbLoop.exclusion
    if ent is None:
        th = theta_ball(a, b)
        ent = al.kernel_entry(th, (a, b), POLY_KERNEL)
        with working_precision(al.prec):
            ent = cache[(a, b)] = (*ent, angle_parts(ent[0]))
    if kp is None:
        K = k_ball(ka, kb)
        with working_precision(al.prec):
            kp = cache[(ka, kb, "K")] = (K, stiffness_parts(K))
    with working_precision(al.prec):
        how, s_t, s_k = exclusion_test(ent[1], ent[0], kp[0], ent[2], (ent[3], kp[1]))
    if how is not None:
        return how, 0.0
    if KRAWCZYK and POLY_KERNEL and al.krawczyk_excludes(ent[0], kp[0], (a, b, ka, kb), ent[1]):
        return "I", 0.0
    if not (math.isfinite(s_t) and math.isfinite(s_k)):
        return None, 1.0 if not math.isfinite(s_t) else 0.0
    return None, s_t / (s_t + s_k) if s_t + s_k > 0 else 0.5


def version() -> int:
    """The certificate version the proof's pieces are made for (:data:`POLY_KERNEL`,
    :data:`KRAWCZYK`)."""
    return (5 if KRAWCZYK else 4) if POLY_KERNEL else 3


def split_k(k0: float, k1: float, v4: bool) -> float:
    """Where a gap's K-range [k0, k1] is cut (:data:`K_WIDE`)."""
    if v4 and k1 > K_WIDE * k0:
        return k1 / K_TOP
    return math.sqrt(k0 * k1) if k1 > GEOMETRIC * k0 else 0.5 * (k0 + k1)


@dataclass
class Exclusion:
    """Pieces (a, b, K_a, K_b, how) proved free of zeros, and the boxes that were not."""
    pieces: list[tuple[float, float, float, float, str]] = field(default_factory=list)
    failed: list[tuple[float, float, float, float]] = field(default_factory=list)
    #: per box taken from the stack, in order: "x" excluded (the next piece), "t" halved
    #: in theta, "k" split in K, "f" failed (a certificate has none)
    splits: list[str] = field(default_factory=list)


def exclude(al: ArbLoop, ka: float, kb: float, max_pieces: int = MAX_PIECES) -> Exclusion:
    """Prove det M(e^{j theta}, K) != 0 on [0, pi] x [ka, kb] by pieces (module doc, 2).

    Parameters
    ----------
    al : ArbLoop
    ka, kb : float
        The gap in N/m (0 < ka < kb).
    max_pieces : int
        Safety valve on the number of boxes tried.

    Returns
    -------
    Exclusion
        ``failed`` empty: proved. Otherwise the boxes left (at the floor, or when the
        valve closed).
    """
    # the boxes' balls are formed at the proof's precision too (the checker tries
    # both that and doubles), and the precision is set once, not per box
    with working_precision(al.prec):
        return _exclude(al, ka, kb, max_pieces)


def _exclude(al: ArbLoop, ka: float, kb: float, max_pieces: int) -> Exclusion:
    """:func:`exclude` at the precision already set."""
    import heapq
    out = Exclusion()
    # boxes by their lowest K first: when the valve closes, what is left lies above
    # everything proved, so the proved part of the gap is [ka, lowest K left]
    heap = [(ka, a, b, kb) for a, b in subdivision_start(POLY_KERNEL)]
    heapq.heapify(heap)
    tried = 0
    entries: dict = {}      # balls formed at the proof's precision, set by exclude()
    while heap:
        k0, a, b, k1 = heapq.heappop(heap)
        tried += 1
        if tried > max_pieces:
            out.failed.append((a, b, k0, k1))
            out.failed.extend((x[1], x[2], x[0], x[3]) for x in heap)
            break
        how, share = box_status(al, a, b, k0, k1, entries)
        if how is not None:
            out.pieces.append((a, b, k0, k1, how))
            out.splits.append("x")
            continue
        th_ok = (b - a) > FLOOR * b
        k_ok = (k1 - k0) > FLOOR * k1
        if th_ok and (share >= 0.5 or not k_ok):
            m = split_theta(a, b, POLY_KERNEL)
            heapq.heappush(heap, (k0, a, m, k1))
            heapq.heappush(heap, (k0, m, b, k1))
            out.splits.append("t")
        elif k_ok:
            m = split_k(k0, k1, POLY_KERNEL)
            heapq.heappush(heap, (k0, a, b, m))
            heapq.heappush(heap, (m, a, b, k1))
            out.splits.append("k")
        else:
            # not proved from k0 up; boxes leave the heap by lowest K, so the rest cannot
            # change what the caller keeps: left as the valve leaves it (not split K-ulp by K-ulp)
            out.failed.append((a, b, k0, k1))
            out.failed.extend((x[1], x[2], x[0], x[3]) for x in heap)
            out.splits.append("f")
            break
    return out


# ----------------------------------------------------------------- counting
# ----------------------------------------------------------------- polishing
@dataclass
class Gap:
    """A K-range proved free of poles on the circle (or not: ``proved`` False), with
    its count of poles outside."""
    lo: float
    hi: float
    proved: bool
    outside: int | None
    exclusion: Exclusion
    counted: Count | None
    #: True: only counted at one point (poles outside there), not excluded: an
    #: unstable gap of the full set, where the float search found no crossing
    sampled: bool = False


@dataclass
class Proof:
    """The proof of one loop's stable set (module doc).

    Attributes
    ----------
    params : dict
        The loop's numbers (:func:`~hapstab.engine.arb_loop.arb_parameters`).
    k0 : float
        The base point standing for K -> 0+.
    windows : list of (float, float, float)
        The crossings' windows (K_lo, K_hi) and angles theta.
    gaps : list of Gap
        Between and around the windows, in increasing K.
    intervals : list of (float, float)
        The proved stable intervals of K.
    kmax : float
        Upper end of the proved stable interval from K_0 (0 if none).
    kmax_hi : float
        Proved upper bound of the true K_max (inf if not proved).
    uncertain : list of (float, float)
        K-ranges not proved either way that border a stable interval.
    theta : float
        Angle of the crossing at K_max (nan if none).
    """

    params: dict[str, Any]
    k0: float
    windows: list[tuple[float, float, float]]
    gaps: list[Gap]
    intervals: list[tuple[float, float]]
    kmax: float
    kmax_hi: float
    uncertain: list[tuple[float, float]]
    theta: float
    prec: int = 0
    k_top: float = math.inf
    #: poles outside at K_0, proved (None: the balls could not decide)
    base_outside: int | None = None
    #: no pole on the circle for any K >= k_top, proved
    #: (:func:`~hapstab.analysis.exact.top.prove_tail`): only then does a stable
    #: interval reaching k_top stand for [.., inf)
    tail_proved: bool = False
    #: the certificate version its gap pieces were proved for (:func:`version`)
    version: int = 5


def _windows(al: ArbLoop, events: tuple, k0: float, k_top: float,
             polish_if: Any = None) -> list[tuple[float, float, float]]:
    """Windows around the candidates (merged where they overlap); the zones the float
    search left unresolved are not windows (the exclusion examines them).

    ``polish_if(ka)``: whether the candidate at ``ka`` (N/m, the float search's) is
    polished (default all); the others get the rough window ``ka (1 +- ROUGH)``, as a
    candidate Newton's method does not settle does. A window only bounds the gaps
    either side, so one whose gaps are not examined need not be polished."""
    wins = []
    for ka, _kb, t, _d, m in events:
        if m == 0 or not math.isfinite(t):
            continue        # a zone the float search left: the exclusion decides it
        if ka * (1 + ROUGH) <= k0 or ka * (1 - ROUGH) >= k_top:
            continue
        got = None
        if polish_if is None or polish_if(ka):
            got = polish(al, t, ka, t == 0.0 or t == math.pi)
        if got is None:
            lo, hi, th = ka * (1 - ROUGH), ka * (1 + ROUGH), t
        else:
            th, k = got
            lo, hi = k * (1 - DELTA), k * (1 + DELTA)
        if hi > k0 and lo < k_top:
            wins.append((max(lo, k0), hi, th))
    wins.sort()
    merged: list[tuple[float, float, float]] = []
    for w in wins:
        if merged and w[0] <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], w[1]), merged[-1][2])
        else:
            merged.append(w)
    return merged


def _first_only(events: tuple, k0: float) -> tuple:
    """The candidates K_max alone needs: those up to the first one above K_0 (and any
    within ROUGH of it, which may merge into its window), and every zone below it."""
    cands = sorted(e for e in events if e[4] != 0 and math.isfinite(e[2])
                   and e[0] * (1 + ROUGH) > k0)
    if not cands:
        return events
    top = cands[0][0] * (1 + 4 * ROUGH)
    return tuple(e for e in events if e[0] <= top)


def _needs_polish(events: tuple, hint: tuple, k0: float) -> Any:
    """For the full set: a candidate is polished when a gap beside it may be examined:
    the two lowest (K_max's window, and the gap above it is counted), and those whose
    neighbouring gap meets the float search's stable set or unresolved zones
    (``hint``, widened by HINT_MARGIN so that the windows' final ends, within ROUGH of
    the float ones, cannot bring in a gap that was not foreseen)."""
    ks = sorted(e[0] for e in events if e[4] != 0 and math.isfinite(e[2])
                and e[0] * (1 + ROUGH) > k0)      # those _windows keeps
    need = set(ks[:2])
    wide = [(a * (1 - HINT_MARGIN), b * (1 + HINT_MARGIN)) for a, b in hint]
    edges = [0.0, *ks, math.inf]
    for g in range(1, len(edges) - 1):
        lo, hi = edges[g], edges[g + 1]
        if any(a <= hi and lo <= b for a, b in wide):
            need.update(k for k in (lo, hi) if math.isfinite(k))
    return lambda ka: ka in need


def _inside(lo: float, hi: float) -> float:
    """A point inside [lo, hi] (geometric mean of a wide range, else the midpoint)."""
    return math.sqrt(lo * hi) if hi > 4 * lo else 0.5 * (lo + hi)


def _prove_gap(al: ArbLoop, lo: float, hi: float, base: Count | None,
               above: int = 0, valve: int = MAX_PIECES) -> list[Gap]:
    """Exclusion over [lo, hi]; if it fails, the part below the lowest box left is
    proved again on its own, the zone from there is not proved, and (``above`` > 0
    more times) the part above it is examined; with ``above`` spent, everything from
    the lowest box left up to ``hi`` is the unproved zone. Each proved part is counted (``base``
    when it lies inside). ``valve``: the most pieces of each exclusion and count."""
    ex = exclude(al, lo, hi, valve)
    if not ex.failed:
        c = base if base is not None and lo <= base.K <= hi else \
            count(al, _inside(lo, hi), valve, polys=POLY_KERNEL)
        return [Gap(lo, hi, True, c.outside, ex, c)]
    first = min(f[2] for f in ex.failed)
    top = min(min((f[3] for f in ex.failed if f[2] == first), default=hi), hi)
    gaps: list[Gap] = []
    if first > lo:
        gaps += _prove_gap(al, lo, first, base, 0, valve)
    if above > 0 and top < hi:
        gaps.append(Gap(first, top, False, None, Exclusion(), None))
        gaps += _prove_gap(al, top, hi, base, above - 1, valve)
    else:
        # not examined further: the whole rest of the gap is not proved (and so reported
        # uncertain), not only the zone of the failed box
        gaps.append(Gap(first, hi, False, None, Exclusion(), None))
    return gaps


def prove(params: dict[str, Any], events: tuple, k0: float, k_top: float,
          full: bool, hint: tuple = ((0.0, math.inf),), unsure: tuple = ()) -> Proof:
    """Prove the stable set around the float search's candidates (module doc).

    Parameters
    ----------
    params : dict
        The loop (:func:`~hapstab.engine.arb_loop.arb_parameters`).
    events : tuple
        The float search's crossings and zones in N/m (``StableSet.events``).
    k0, k_top : float
        The base point (K -> 0+) and the top of the K range examined (N/m).
    full : bool
        Every stable interval up to ``k_top`` (True) or K_max alone (then only the
        first candidate is polished and its window proved).
    hint : tuple of (float, float)
        The float search's stable intervals: a gap above the first window that meets
        none of them (nor ``unsure``) is not examined (it is not claimed stable; the
        float search counted poles outside there), which saves the counts of the
        unstable gaps; its candidates are not polished either.
    unsure : tuple of (float, float)
        The zones the float search left unresolved: a gap above the first window that
        meets only these is examined with the smaller valve MAX_PIECES_UNSURE.

    Returns
    -------
    Proof
    """
    al = ArbLoop(params)
    base = count(al, k0, polys=POLY_KERNEL)
    if not full:
        wins = _windows(al, _first_only(events, k0), k0, k_top)
        if base.outside != 0:       # K_max is 0 (or not proved): nothing to exclude
            return _assemble(al, params, k0, k_top, wins,
                             [Gap(k0, k0, True, base.outside, Exclusion(), base)], base)
        gaps = _prove_gap(al, k0, wins[0][0] if wins else k_top, base)
        if wins and all(g.proved and g.outside == 0 for g in gaps):
            after = count(al, wins[0][1], polys=POLY_KERNEL)   # unstable above the window
            gaps.append(Gap(wins[0][1], wins[0][1], True, after.outside, Exclusion(), after))
        return _assemble(al, params, k0, k_top, wins, gaps, base)
    wins = _windows(al, events, k0, k_top, _needs_polish(events, hint + unsure, k0))
    edges = [k0] + [w[1] for w in wins]
    tops = [w[0] for w in wins] + [k_top]
    gaps = []
    for g, (lo, hi) in enumerate(zip(edges, tops, strict=True)):
        if hi <= lo:
            continue
        valve = MAX_PIECES
        if g > 1 and not any(a <= hi and lo <= b for a, b in hint):
            zones = [(a, b) for a, b in unsure if a <= hi and lo <= b]
            if not zones:
                gaps.append(Gap(lo, hi, False, None, Exclusion(), None, True))
                continue
            # only the part the float search left unresolved is examined (it counted
            # poles outside in the rest), with the smaller valve
            valve = MAX_PIECES_UNSURE
            a, b = max(lo, min(z[0] for z in zones)), min(hi, max(z[1] for z in zones))
            if a > lo:
                gaps.append(Gap(lo, a, False, None, Exclusion(), None, True))
            lo, tail = a, (b, hi) if b < hi else None
            hi = b
        else:
            tail = None
        c = base if g == 0 else count(al, lo, valve, polys=POLY_KERNEL)
        if c.outside:       # unstable there: counted, not excluded (see Gap.sampled)
            gaps.append(Gap(lo, hi, False, c.outside, Exclusion(), c, True))
        else:
            gaps += _prove_gap(al, lo, hi, c, 1, valve)
        if tail is not None:
            gaps.append(Gap(*tail, False, None, Exclusion(), None, True))
    return _assemble(al, params, k0, k_top, wins, gaps, base)


def _assemble(al: ArbLoop, params: dict[str, Any], k0: float, k_top: float,
              wins: list[tuple[float, float, float]], gaps: list[Gap], base: Count) -> Proof:
    """Stable intervals, K_max and its enclosure from the proved gaps. A stable
    interval reaching ``k_top`` stands for [.., inf) only when the tail above it is
    proved (:func:`~hapstab.analysis.exact.top.prove_tail`); otherwise it ends at
    ``k_top`` and (k_top, inf) is uncertain."""
    from hapstab.analysis.exact.top import prove_tail
    tail = any(g.proved and g.outside == 0 and g.hi == k_top for g in gaps) and \
        prove_tail(al, k_top)
    intervals: list[tuple[float, float]] = []
    uncertain: list[tuple[float, float]] = []
    for g in gaps:
        if g.proved and g.outside == 0 and g.hi > g.lo:
            if intervals and intervals[-1][1] == g.lo:
                intervals[-1] = (intervals[-1][0], g.hi)
            else:
                intervals.append((g.lo, g.hi))
        elif not g.sampled and (not g.proved or g.outside is None):
            uncertain.append((g.lo, g.hi))
    kmax, kmax_hi, theta = 0.0, math.inf, math.nan
    if intervals and intervals[0][0] == k0:
        kmax = intervals[0][1]
        win = next((w for w in wins if w[0] == kmax), None)
        if win is not None:
            theta = win[2]
            after = next((g for g in gaps if g.lo == win[1]), None)
            if after is not None and after.counted is not None and \
                    after.counted.K == win[1] and after.outside:
                kmax_hi = win[1]
            else:
                uncertain.append((win[0], win[1]))
        elif kmax == k_top:
            kmax = math.inf if tail else kmax
    if not tail and any(g.proved and g.outside == 0 and g.hi == k_top for g in gaps):
        uncertain.append((k_top, math.inf))    # not examined above the top: not claimed
    # a window between two stable gaps: what happens inside is not proved
    stable = [g for g in gaps if g.proved and g.outside == 0]
    tops = {g.hi for g in stable}
    bottoms = {g.lo for g in stable if g.hi > g.lo}
    uncertain += [(lo, hi) for lo, hi, _t in wins if lo in tops and hi in bottoms]
    return Proof(params, k0, wins, gaps, intervals, kmax, kmax_hi, sorted(set(uncertain)),
                 theta, al.prec, k_top, base.outside, tail, version())


def prove_base(params: dict[str, Any], k0: float) -> tuple[ArbLoop, Count]:
    """The loop in balls and its proved count of poles outside at K_0."""
    al = ArbLoop(params)
    return al, count(al, k0, polys=POLY_KERNEL)

