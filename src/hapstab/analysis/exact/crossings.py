"""The certain crossing analysis behind the exact critical stiffness: every K > 0 at
which a closed-loop pole is on |z| = 1, and the stable set in K.

A pole is on the unit circle at (theta, K) exactly where the characteristic
function det M(e^{j theta}, K) = F0 + u F1 + u^2 F2 vanishes (u = K / scale; see
:mod:`hapstab.loopfreq`). The set of such points in the box
theta in [0, pi] x u in [U_LO, U_HI] is found by branch and prune on
boxes (theta-cell x u-interval) with verified enclosures (:mod:`hapstab.discs`):

* **exclusion** -- if the enclosure of F over a box does not contain 0, no
  crossing is in the box;
* **isolation** -- if the Krawczyk operator of the real 2x2 system
  (Re F, Im F) = 0 in (theta, u) maps the box into its interior, the box holds
  exactly one crossing, and the (interval) Jacobian is regular on it, so the
  sign of its determinant is the direction of the crossing (Im(F_u / F_theta) > 0:
  the pole moves outwards as K grows); Newton's method then polishes it. Boxes
  centred on theta = 0 or pi (symmetric, F(-theta) = conj F(theta)) hold the real
  crossings through z = +-1;
* otherwise the box is split (in theta or u, whichever dominates the enclosure).

**Why nothing is missed.** Every point of the (theta, u) box lies in a box that
was excluded by a proof (0 not in an enclosure of F), or in a box proved to hold
exactly one zero, or in a box left *unresolved* at the rounding floor, which is
reported as an uncertain K-interval, never dropped. The enclosures are sound for
every point of a cell (derivative bounds, circular arithmetic, a rounding
allowance per operation), so a lightly damped resonance whose crossings lie close
together is still separated: the boxes are split until each crossing is alone.

**Counting.** The number of poles outside the circle at u = U_LO comes from the
argument principle, Z_out = q - wind(det M) (:func:`winding`), certified the same
way (each cell's enclosure excludes 0, so the argument's increment across it is
the principal value). Each crossing then changes the count by its direction
times 2 (complex pair) or 1 (z = +-1); counts are cross-checked by windings in
gaps. The cost grows with the number of crossings (about the delay) and not with
the number of states: the delay is a phase.

References
----------
R. Krawczyk, "Newton-Algorithmen zur Bestimmung von Nullstellen mit
Fehlerschranken", Computing 4 (1969) 187-201; R. E. Moore, R. B. Kearfott and
M. J. Cloud, *Introduction to Interval Analysis*, SIAM 2009, ch. 8.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hapstab.analysis.exact.boxes import (
    THETA_FLOOR,
    U_FLOOR,
    U_HI,
    U_LO,
    Cells,
    Found,
    _box_test,
    _dpoly,
    _estimate_lowest,
    _initial_cells,
    _polish,
    _split_cells,
    _theta_floor,
    _trim,
)
from hapstab.analysis.exact.stable_set import StableSet, first_only, stable_set
from hapstab.engine.frequency import LoopResponse
from hapstab.errors import AnalysisError

__all__ = ["analyse", "winding", "U_LO", "U_HI"]

#: Phase turn of the delay per first cell (rad): the full analysis needs every crossing
#: and starts fine; for K_max alone (small K, where the delayed part of F is small)
#: coarse cells exclude as well and fewer are split. Measured, not a tolerance.
TURN_FULL, TURN_KMAX = 1.2, 3.0
#: Safety valve on the number of boxes in one round (memory), far above real needs.
MAX_BOXES = 2_000_000
#: Safety valve on the rounds of splitting: 50 halvings of theta per decade of u and
#: 60 of u reach both floors from the initial boxes several times over.
MAX_ROUNDS = 600


@dataclass
class _Search:
    """The state of one branch-and-prune search (:func:`_boxes`)."""

    resp: LoopResponse
    c: Cells
    found: Found
    lowest_only: np.ndarray     # (L,) only the lowest crossing is wanted
    cap: np.ndarray             # (L,) the u above which nothing is of interest (yet)
    guess: np.ndarray           # (L,) the cap is a guess that may have to be raised
    deferred: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    rounds: int = 0
    #: a family of loops (coefficient enclosures over a box of parameters): a crossing
    #: is recorded at its box's lower end and keeps the boxes below its upper end
    robust: bool = False


def _boxes(resp: LoopResponse, items: np.ndarray, u_cap: np.ndarray, polish: bool = True,
           estimate: bool = True, start: tuple[Cells, np.ndarray] | None = None,
           robust: bool = False) -> Found:
    """Branch and prune over (theta, u) for the given items (see module doc).

    ``u_cap[item]`` bounds the u of interest (inf: all); it is lowered to each
    crossing found when only the lowest crossing is wanted (finite caps).
    ``start``: cells already built (and the indices of a partition of [0, pi] per item).
    ``robust``: each item is a family of loops (see :class:`_Search`); the boxes that
    isolate crossings are returned too (``Found.boxes``).
    """
    L = resp.size
    if start is None:
        c = Cells()
        cells = c.add(resp, *_initial_cells(resp, items))
    else:
        c, cells = start
        cells = cells[np.isin(c.item[cells], items)]
    lowest_only = np.isfinite(u_cap)
    srch = _Search(resp, c, Found([[] for _ in range(L)], [[] for _ in range(L)]), lowest_only,
                   np.where(lowest_only, u_cap, np.inf).astype(float), np.zeros(L, bool), [],
                   robust=robust)
    if robust:
        srch.found.boxes = [[] for _ in range(L)]
    if estimate and lowest_only.any():
        # a first cap from the near-real roots u at the cells' centres: with it the
        # high-u boxes are never refined. A cap below the true lowest crossing finds
        # nothing; the boxes above it are then taken up, so the result does not
        # depend on the guess.
        est = _estimate_lowest(c, cells, L)
        srch.guess = lowest_only & np.isfinite(est) & (est < srch.cap)
        srch.cap = np.where(srch.guess, est, srch.cap)
    box: tuple[np.ndarray, np.ndarray, np.ndarray] | None = (
        cells, np.full(cells.size, U_LO), np.full(cells.size, U_HI))
    while box is not None:
        cell, ua, ub = box
        box = _round(srch, cell, ua, ub, polish) if cell.size else _resume(srch)
    return srch.found


def _resume(srch: _Search) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Every box below the caps is settled: items whose guessed cap found nothing
    take up the boxes above it, with a cap 16 times higher (U_HI at last); None
    when nothing is left."""
    found, c = srch.found, srch.c
    ran_dry = srch.guess & np.array([not found.cross[i] and not found.unsure[i]
                                     for i in range(srch.cap.size)])
    if not ran_dry.any() or not srch.deferred:
        return None
    dc_, da_, db_ = (np.concatenate(x) for x in zip(*srch.deferred, strict=True))
    srch.deferred = []
    back = ran_dry[c.item[dc_]]
    srch.cap = np.where(ran_dry, np.where(srch.cap * 16 < U_HI, srch.cap * 16, U_HI), srch.cap)
    srch.guess &= ~(ran_dry & (srch.cap >= U_HI))
    return dc_[back], da_[back], db_[back]


def _below_caps(srch: _Search, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The boxes cut at their item's cap; the part above a guessed cap waits (it
    matters only if nothing is below)."""
    cp = srch.cap[srch.c.item[cell]]
    over = ub > cp
    if over.any():
        g = over & srch.guess[srch.c.item[cell]]
        srch.deferred.append((cell[g], np.maximum(ua[g], cp[g]), ub[g]))
    keep = ua < cp
    return cell[keep], ua[keep], np.minimum(ub[keep], cp[keep])


def _round(srch: _Search, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray,
           polish: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One round: cut at the caps, trim, test every box; record the isolated
    crossings and the unresolved boxes; split the rest (the next round's boxes)."""
    cell, ua, ub = _below_caps(srch, cell, ua, ub)
    if cell.size:
        cell, ua, ub = _trim(srch.c, cell, ua, ub)
    if not cell.size:
        return cell, ua, ub
    if cell.size > MAX_BOXES:
        T = ", ".join(f"{t:g}" for t in np.unique(srch.resp.periods[srch.c.item[cell]]))
        raise AnalysisError(f"period = {T} s: the crossing analysis needs more than {MAX_BOXES} "
                            "boxes for this loop at this sampling period; it is beyond what it "
                            "can certify (a shorter period or delay may be; so may a mass, "
                            "damping or stiffness nearer a device's usual range, when the "
                            "loop's poles crowd z = 1 to within rounding)")
    status, w_th, w_u, f_abs, noise = _box_test(srch.c, cell, ua, ub)
    one = np.flatnonzero(status == 1)
    if one.size:
        _record(srch, cell[one], ua[one], ub[one], polish)
    rest = np.flatnonzero(status == 2)
    if not rest.size:
        return cell[:0], ua[:0], ub[:0]
    cell, ua, ub, w_th, w_u = cell[rest], ua[rest], ub[rest], w_th[rest], w_u[rest]
    go, split_th = _give_up(srch, cell, ua, ub, w_th, w_u, f_abs[rest], noise[rest])
    return _split(srch, cell[go], ua[go], ub[go], split_th)


def _record(srch: _Search, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray,
            polish: bool) -> None:
    """Boxes proved to hold one crossing each: polish it, record it, lower the cap."""
    c = srch.c
    res = _polish(srch.resp, c, cell, ua, ub) if polish or srch.robust else None
    for k in range(cell.size):
        i = int(c.item[cell[k]])
        u, t, dirn = res[k] if res is not None else (0.5 * (ua[k] + ub[k]), c.th[cell[k]], 0)
        u_rec = u_cap = u
        if srch.robust:       # every loop of the family has its crossing in [ua, ub]
            assert srch.found.boxes is not None
            srch.found.boxes[i].append((float(ua[k]), float(ub[k]), int(cell[k]), u, t))
            u_rec, u_cap = float(ua[k]), float(ub[k])
        srch.found.cross[i].append((u_rec, t, dirn, 1 if c.kind[cell[k]] else 2))
        if srch.lowest_only[i]:
            srch.cap[i] = min(srch.cap[i], u_cap)


def _give_up(srch: _Search, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray,
             w_th: np.ndarray, w_u: np.ndarray, f_abs: np.ndarray, noise: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Record the boxes no split can resolve as unsure; return which go on and,
    of those, which are split in theta."""
    th_small = _theta_floor(srch.c, cell)
    u_small = (ub - ua) <= U_FLOOR * ub
    # at the theta floor, splitting u cannot help once theta alone spans 0; nor
    # can any split once the box adds less than the error of F itself (the
    # numerics cannot tell this box from a zero); nor can a non-finite enclosure
    th_done = th_small | (w_th <= noise)          # theta splits cannot help any more
    stuck = (th_done & (u_small | (w_u <= noise)) | th_small & (w_th >= f_abs)
             | ~np.isfinite(f_abs + w_th + w_u))
    srch.rounds += 1
    if srch.rounds > MAX_ROUNDS:
        stuck[:] = True
    for k in np.flatnonzero(stuck):
        i = int(srch.c.item[cell[k]])
        srch.found.unsure[i].append((float(ua[k]), float(ub[k])))
        if srch.lowest_only[i]:
            srch.cap[i] = min(srch.cap[i], ua[k])
    go = ~stuck
    # u is treated exactly by _trim, so splitting u only helps once theta cannot
    return go, ~th_done[go]


def _split(srch: _Search, cell: np.ndarray, ua: np.ndarray, ub: np.ndarray,
           split_th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Halve each box: in theta (new cells) where that helps, else in u (at the
    geometric mean of wide intervals, else the midpoint)."""
    su = np.flatnonzero(~split_th)
    mid = np.where(ub[su] > 4 * ua[su], np.sqrt(ua[su] * ub[su]), 0.5 * (ua[su] + ub[su]))
    new_cell, new_ua, new_ub = [cell[su], cell[su]], [ua[su], mid], [mid, ub[su]]
    st = np.flatnonzero(split_th)
    if st.size:
        parents, inv = np.unique(cell[st], return_inverse=True)
        kids = srch.c.add(srch.resp, *_split_cells(srch.c, parents))
        left, right = kids[:parents.size], kids[parents.size:]
        new_cell += [left[inv], right[inv]]
        new_ua += [ua[st], ua[st]]
        new_ub += [ub[st], ub[st]]
    return np.concatenate(new_cell), np.concatenate(new_ua), np.concatenate(new_ub)


# ------------------------------------------------------------------ the winding
def _winding_cells(resp: LoopResponse, c: Cells, leaves: np.ndarray, u: np.ndarray,
                   robust: bool = False) -> np.ndarray:
    """:func:`winding` at u[item] on cells already built (a partition of [0, pi] per
    item, centred cells, the ends centred on 0 and pi): cells whose disc holds 0 at u
    are split. Between the centres of neighbouring cells the argument changes by
    Arg(w / F_i) + Arg(F_(i+1) / w) for any w in both discs (each disc excludes 0 and
    holds the value at the shared edge), so no further evaluation is needed. ``robust``
    (a family of loops): a cell whose centre's own enclosure holds 0 is not split (no
    split can exclude 0 there), and its item's count is not certified."""
    L = resp.size
    bad_item = np.zeros(L, bool)
    for _ in range(200):
        it = c.item[leaves]
        fc, fr = _dpoly(c.vc[:, leaves], c.vr[:, leaves], u[it], np.zeros(leaves.size))
        holds0 = ~(np.abs(fc) > fr)
        if not holds0.any():
            break
        floor = holds0 & _theta_floor(c, leaves)
        if robust:
            pc, pr = _dpoly(c.pc[:, leaves], c.pr[:, leaves], u[it], np.zeros(leaves.size))
            floor |= holds0 & ~(np.abs(pc) > pr)
        bad_item[it[floor]] = True
        split = leaves[holds0 & ~floor]
        keep = leaves[~holds0 | floor]
        if not split.size:
            break
        kids = c.add(resp, *_split_cells(c, split))
        leaves = np.concatenate([keep, kids])
    else:
        bad_item[c.item[leaves]] = True
    it = c.item[leaves]
    order = np.lexsort((c.th[leaves], it))
    leaves, it = leaves[order], it[order]
    fc, fr = _dpoly(c.vc[:, leaves], c.vr[:, leaves], u[it], np.zeros(leaves.size))
    F, _ = _dpoly(c.pc[:, leaves], c.pr[:, leaves], u[it], np.zeros(leaves.size))
    same = it[1:] == it[:-1]
    ri, rj = fr[:-1], fr[1:]
    with np.errstate(all="ignore"):
        t = np.where(ri + rj > 0, ri / (ri + rj), 0.5)
        w = fc[:-1] + (fc[1:] - fc[:-1]) * t
        inc = np.angle(w / F[:-1]) + np.angle(F[1:] / w)
    total = np.zeros(L)
    np.add.at(total, it[:-1][same], inc[same])
    turns = total / np.pi
    # F is real at theta = 0 and pi, so the turns are whole up to the rounding of the
    # end values' arguments (~1e-15); 1e-6 off means something is wrong: not certified
    bad = bad_item | ~np.isfinite(turns) | (np.abs(turns - np.round(turns)) > 1e-6)
    return np.where(bad, -1, resp.q - np.round(np.where(np.isfinite(turns), turns, 0)).astype(int))


def winding(resp: LoopResponse, items: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Poles outside the unit circle at u = K/scale for each item, by the argument
    principle, certified: ``Z_out = q - wind(det M)``. -1 where a pole is within
    the rounding floor of the circle (the count cannot be certified)."""
    items, u = np.asarray(items, int), np.asarray(u, float)
    m = max(8, int(np.ceil(np.pi * resp.phase_rate / 1.2)))
    a0 = np.linspace(0.0, np.pi, m + 1)
    row = np.repeat(np.arange(items.size), m)
    a, b = np.tile(a0[:-1], items.size), np.tile(a0[1:], items.size)
    done_a, done_b, done_row = [], [], []
    bad_rows = np.zeros(items.size, bool)
    for _ in range(200):
        if not row.size:
            break
        mid, rho = 0.5 * (a + b), 0.5 * (b - a)
        pts = resp.coefficients(items[row], mid, np.zeros_like(mid))
        cel = resp.coefficients(items[row], mid, rho)
        vd = [cc.value_disc(rho, p) for cc, p in zip(cel, pts, strict=True)]
        fc, fr = _dpoly(np.array([v[0] for v in vd]), np.array([v[1] for v in vd]), u[row],
                        np.zeros(row.size))
        ok = np.abs(fc) > fr
        done_a.append(a[ok])
        done_b.append(b[ok])
        done_row.append(row[ok])
        a, b, row = a[~ok], b[~ok], row[~ok]
        floor = (b - a) <= THETA_FLOOR * (1.0 + a)
        bad_rows[row[floor]] = True
        a, b, row = a[~floor], b[~floor], row[~floor]
        mid = 0.5 * (a + b)
        a, b, row = np.concatenate([a, mid]), np.concatenate([mid, b]), np.concatenate([row, row])
    if row.size:
        bad_rows[row] = True
    A, Bv, R = np.concatenate(done_a), np.concatenate(done_b), np.concatenate(done_row)
    ends = np.concatenate([A, Bv])
    rr = np.concatenate([R, R])
    F = resp.coefficients(items[rr], ends, np.zeros_like(ends))
    val = F[0].vc + u[rr] * (F[1].vc + u[rr] * F[2].vc)
    fa, fb = val[:A.size], val[A.size:]
    inc = np.angle(fb / fa)
    total = np.zeros(items.size)
    np.add.at(total, R, inc)
    turns = total / np.pi
    out = resp.q - np.round(turns).astype(int)
    bad = bad_rows | (np.abs(turns - np.round(turns)) > 1e-6)   # whole to ~1e-15: _winding_cells
    return np.where(bad, -1, out)


# ------------------------------------------------------------------ the analysis
def analyse(resp: LoopResponse, full: bool = True) -> list[StableSet]:
    """Exact K_max and stable set in K for every item of ``resp``.

    Parameters
    ----------
    resp : LoopResponse
    full : bool
        All crossings and every stable interval (True), or only K_max (False:
        ``intervals`` is then ``((0, K_max),)`` when K_max > 0).

    Returns
    -------
    list of StableSet
        One per item.
    """
    L = resp.size
    items = np.arange(L)
    c = Cells()
    first = c.add(resp, *_initial_cells(resp, items, TURN_FULL if full else TURN_KMAX))
    anchor = _winding_cells(resp, c, first, np.full(L, U_LO))
    cap = np.full(L, np.inf if full else U_HI)
    need = items if full else items[anchor == 0]
    found = _boxes(resp, need, np.where(np.isin(items, need), cap, -np.inf),
                   start=(c, first)) if need.size else \
        Found([[] for _ in range(L)], [[] for _ in range(L)])
    out = []
    for i in range(L):
        out.append(_classify(resp, i, int(anchor[i]), _dedupe(found.cross[i]), found.unsure[i],
                             full))
    return out


def _classify(resp: LoopResponse, i: int, anchor: int, cross, unsure, full: bool) -> StableSet:
    """Item i's stable set from the count of poles outside at U_LO (``anchor``, -1:
    not certified), its crossings and its unresolved zones."""
    s = float(resp.scale[i])
    base: dict[str, Any] = {"rigid": resp.rigid, "outside_small_K": anchor}
    unc = _merge(unsure)
    if anchor < 0:
        return StableSet(**base, kmax=0.0, intervals=(), theta=math.nan,
                         uncertain=((0.0, U_LO * s),))
    # a crossing inside an unresolved zone is part of it: the count after the zone comes
    # from the argument principle above the zone, which accounts for all it holds
    inside = lambda u: any(a <= u <= b for a, b in unc)  # noqa: E731
    events = sorted([(u, u, t, d, m) for u, t, d, m in cross if not inside(u)] +
                    [(a, b, math.nan, 0, 0) for a, b in unc])
    if not full:
        return StableSet(**base, **first_only(events, anchor, s))
    counts = _counts(resp, i, events, anchor)
    _verify(resp, i, events, counts)
    return StableSet(**base, **stable_set(events, counts, s))


def _counts(resp: LoopResponse, i: int, events: list[Any],
            anchor: int) -> list[int | None]:
    """The number of poles outside in each gap between events: each crossing changes
    it by its direction times its multiplicity; after an unresolved zone it is
    counted anew by the argument principle (None: not certifiable either, so that
    gap is not claimed stable)."""
    counts: list[int | None] = [anchor]
    for g, (_a, b, _t, d, m) in enumerate(events):
        prev = counts[-1]
        if m == 0 or prev is None:
            hi = events[g + 1][0] if g + 1 < len(events) else 4 * b
            nxt = int(winding(resp, np.array([i]), np.array([math.sqrt(b * hi) if hi > b else b]))[0])
            counts.append(nxt if nxt >= 0 else None)
        else:
            counts.append(prev + int(d * m))
    if min(c for c in counts if c is not None) < 0:
        raise AnalysisError("crossing analysis: a negative count of unstable poles; please "
                            "report this loop")
    return counts


def _verify(resp: LoopResponse, i: int, events, counts) -> None:
    """Cross-check the counts from crossing directions by the argument principle in
    a few gaps (the first and last, and up to 6 others)."""
    if not events:
        return
    gaps = sorted({1, len(events)} | set(range(2, len(events), max(1, len(events) // 6))))
    us = []
    for g in gaps:
        lo = events[g - 1][1]
        hi = events[g][0] if g < len(events) else lo * 4
        us.append(math.sqrt(lo * hi) if hi > lo else lo)
    got = winding(resp, np.full(len(us), i), np.array(us))
    for g, c in zip(gaps, got, strict=True):
        if c >= 0 and counts[g] is not None and c != counts[g]:
            raise AnalysisError(f"crossing analysis: the pole count {counts[g]} from crossing "
                                f"directions disagrees with the argument principle ({c}) at "
                                f"K = {us[gaps.index(g)] * resp.scale[i]:.6g}; please report this loop")


def _dedupe(cross: list[tuple[float, float, int, int]]) -> list[tuple[float, float, int, int]]:
    """A safety net: one zero proved in two boxes would be polished by Newton's method
    to the same point (to rounding), and is one crossing. Two distinct crossings are
    never this close (the Krawczyk boxes that isolate them are disjoint)."""
    out: list[tuple[float, float, int, int]] = []
    for cr in sorted(cross):
        # the same point to rounding: Newton polishes to ~1e-15 relative, and 1e-12 is
        # still far closer than two Krawczyk-isolated crossings come (see above)
        if (out and abs(cr[0] - out[-1][0]) <= 1e-12 * cr[0]  # u, then theta (+1: it may be 0)
                and abs(cr[1] - out[-1][1]) <= 1e-12 * (1.0 + cr[1]) and cr[2] == out[-1][2]):
            continue
        out.append(cr)
    return out


def _merge(iv: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for a, b in sorted(iv):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out
