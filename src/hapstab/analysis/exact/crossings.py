"""The certain crossing analysis behind the exact critical stiffness: every K > 0 at
which a closed-loop pole is on |z| = 1, and the stable set in K.

A pole is on the unit circle at (theta, K) exactly where the characteristic
function det M(e^{j theta}, K) = F0 + u F1 + u^2 F2 vanishes (u = K / scale; see
:mod:`~hapstab.engine.frequency`). The set of such points in the box
theta in [0, pi] x u in [U_LO, U_HI] is found by branch and prune on
boxes (theta-cell x u-interval) with verified enclosures (:mod:`~hapstab.engine.discs`):

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

from dataclasses import dataclass

import numpy as np

from hapstab.analysis.exact.boxes import (
    U_FLOOR,
    U_HI,
    U_LO,
    Cells,
    Found,
    at_theta_floor,
    classify_boxes,
    estimate_lowest,
    initial_cells,
    polish_boxes,
    split_cells,
    trim_boxes,
)
from hapstab.analysis.exact.counts import (
    crossing_events,
    dedupe_crossings,
    gap_counts,
    item_stable_set,
    winding,
    winding_on_cells,
)
from hapstab.analysis.exact.stable_set import StableSet
from hapstab.engine.frequency import LoopResponse
from hapstab.errors import AnalysisError

__all__ = ["analyse", "winding", "branch_and_prune", "U_LO", "U_HI"]

#: Phase turn of the delay per first cell (rad): the full analysis needs every crossing
#: and starts fine; for K_max alone (small K, where the delayed part of F is small)
#: coarse cells exclude as well and fewer are split. Measured, not a tolerance.
TURN_FULL, TURN_KMAX = 1.2, 3.0
#: Safety valve on the number of boxes in one round (memory), far above real needs.
MAX_BOXES = 2_000_000
#: Safety valve on the rounds of splitting: 50 halvings of theta per decade of u and
#: 60 of u reach both floors from the initial boxes several times over.
MAX_ROUNDS = 600
#: Loops of at most this many ports are proposed by the angle grid first (see analyse)
FAST_PORTS = 2


@dataclass
class _Search:
    """The state of one branch-and-prune search (:func:`branch_and_prune`)."""

    resp: LoopResponse
    c: Cells
    found: Found
    lowest_only: np.ndarray     # (L,) only the lowest crossing is wanted
    cap: np.ndarray             # (L,) the u above which nothing is of interest (yet)
    guess: np.ndarray           # (L,) the cap is a guess that may have to be raised
    deferred: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
    #: (L,) rounds in which each item still had boxes to split (counted per item, so a
    #: batch of loops gives each the limit it has alone)
    rounds: np.ndarray | None = None
    #: a family of loops (coefficient enclosures over a box of parameters): a crossing
    #: is recorded at its box's lower end and keeps the boxes below its upper end
    robust: bool = False


def branch_and_prune(resp: LoopResponse, items: np.ndarray, u_cap: np.ndarray, polish: bool = True,
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
        cells = c.add(resp, *initial_cells(resp, items))
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
        est = estimate_lowest(c, cells, L)
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
        cell, ua, ub = trim_boxes(srch.c, cell, ua, ub)
    if not cell.size:
        return cell, ua, ub
    if cell.size > MAX_BOXES:
        T = ", ".join(f"{t:g}" for t in np.unique(srch.resp.periods[srch.c.item[cell]]))
        raise AnalysisError(f"period = {T} s: the crossing analysis needs more than {MAX_BOXES} "
                            "boxes for this loop at this sampling period; it is beyond what it "
                            "can certify (a shorter period or delay may be; so may a mass, "
                            "damping or stiffness nearer a device's usual range, when the "
                            "loop's poles crowd z = 1 to within rounding)")
    status, w_th, w_u, f_abs, noise = classify_boxes(srch.c, cell, ua, ub)
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
    res = polish_boxes(srch.resp, c, cell, ua, ub) if polish or srch.robust else None
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
    th_small = at_theta_floor(srch.c, cell)
    u_small = (ub - ua) <= U_FLOOR * ub
    # at the theta floor, splitting u cannot help once theta alone spans 0; nor
    # can any split once the box adds less than the error of F itself (the
    # numerics cannot tell this box from a zero); nor can a non-finite enclosure
    th_done = th_small | (w_th <= noise)          # theta splits cannot help any more
    stuck = (th_done & (u_small | (w_u <= noise)) | th_small & (w_th >= f_abs)
             | ~np.isfinite(f_abs + w_th + w_u))
    items = srch.c.item[cell]
    if srch.rounds is None:
        srch.rounds = np.zeros(srch.cap.size, int)
    srch.rounds[np.unique(items)] += 1
    stuck |= srch.rounds[items] > MAX_ROUNDS
    for k in np.flatnonzero(stuck):
        i = int(srch.c.item[cell[k]])
        srch.found.unsure[i].append((float(ua[k]), float(ub[k])))
        if srch.lowest_only[i]:
            srch.cap[i] = min(srch.cap[i], ua[k])
    go = ~stuck
    # u is treated exactly by trim_boxes, so splitting u only helps once theta cannot
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
        kids = srch.c.add(srch.resp, *split_cells(srch.c, parents))
        left, right = kids[:parents.size], kids[parents.size:]
        new_cell += [left[inv], right[inv]]
        new_ua += [ua[st], ua[st]]
        new_ub += [ub[st], ub[st]]
    return np.concatenate(new_cell), np.concatenate(new_ua), np.concatenate(new_ub)


# ------------------------------------------------------------------ the analysis
def analyse(resp: LoopResponse, full: bool = True, proof: bool = False,
            fast: bool = True) -> list[StableSet]:
    """Exact K_max and stable set in K for every item of ``resp``.

    Parameters
    ----------
    resp : LoopResponse
    full : bool
        All crossings and every stable interval (True), or only K_max (False:
        ``intervals`` is then ``((0, K_max),)`` when K_max > 0).
    proof : bool
        Re-prove each covered item's answer in ball arithmetic
        (:mod:`~hapstab.analysis.exact.proved`; False, the default: the float search's
        answer, whose rounding allowances are not proved).
    fast : bool
        With ``proof``, one or two ports (:data:`FAST_PORTS`): let the angle grid of
        :mod:`~hapstab.analysis.exact.candidates` propose the crossings, and fall back
        to the certified float search for an item whose proof does not settle
        everything (default True; every reported interval is proved either way; what
        the grid's proposals decide alone is said in that module's notes).

    Returns
    -------
    list of StableSet
        One per item.
    """
    if proof and fast and len(resp.ports) <= FAST_PORTS and resp.params and \
            all(p is not None for p in resp.params):
        return _analyse_fast(resp, full)
    L = resp.size
    items = np.arange(L)
    c = Cells()
    first = c.add(resp, *initial_cells(resp, items, TURN_FULL if full else TURN_KMAX))
    anchor = winding_on_cells(resp, c, first, np.full(L, U_LO))
    cap = np.full(L, np.inf if full else U_HI)
    need = items if full else items[anchor == 0]
    found = branch_and_prune(resp, need, np.where(np.isin(items, need), cap, -np.inf),
                   start=(c, first)) if need.size else \
        Found([[] for _ in range(L)], [[] for _ in range(L)])
    cross = [dedupe_crossings(found.cross[i]) for i in range(L)]
    # the float cross-check of the counts from the crossings' directions (a safety net
    # of this search: the directions are certified by the isolating boxes) is left to
    # the ball proof where one follows: it counts, in balls, every gap it claims
    check = np.array([not (proof and resp.params and resp.params[i] is not None)
                      for i in range(L)])
    # the counts the stable sets need, for every item in a few batched calls
    known = gap_counts(resp, anchor, [crossing_events(cross[i], found.unsure[i])[1]
                                      for i in range(L)], check) if full else None
    sets = [item_stable_set(resp, i, int(anchor[i]), cross[i], found.unsure[i], full, known,
                            bool(check[i])) for i in range(L)]
    if not proof or not any(p is not None for p in resp.params):
        return sets
    from hapstab.analysis.exact.proved import prove_sets
    return prove_sets(resp, sets, full, lambda one: analyse(one, True, False)[0])




def _analyse_fast(resp: LoopResponse, full: bool) -> list[StableSet]:
    """:func:`analyse` with a proof, each item proposed by the angle grid first
    (:func:`~hapstab.analysis.exact.candidates.candidate_set`); an item whose proof
    leaves anything open (:func:`~hapstab.analysis.exact.candidates.consistent`) is
    analysed again with the certified float search proposing."""
    from hapstab.analysis.exact.candidates import candidate_set, consistent
    from hapstab.analysis.exact.proved import item_response, prove_sets
    out = []
    for i in range(resp.size):
        one = item_response(resp, i)
        ss = candidate_set(one, 0, full)
        got = None
        if ss is not None:
            got = prove_sets(one, [ss], full, lambda r: analyse(r, True, False)[0])[0]
            if not consistent(ss, got):
                got = None
        out.append(got if got is not None else analyse(one, full, True, fast=False)[0])
    return out
