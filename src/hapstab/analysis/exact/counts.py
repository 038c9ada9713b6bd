"""The pole counts by the argument principle, and each item's stable set from its
count at small K, its crossings and its unresolved zones.

The number of poles outside the unit circle at a given K is Z_out = q - wind(det M)
over [0, pi], certified cell by cell (each cell's enclosure excludes 0):
:func:`winding` on cells of its own, :func:`winding_on_cells` on the cells a search of
:mod:`~hapstab.analysis.exact.crossings` already built
(:class:`~hapstab.analysis.exact.boxes.Cells`). Between counts, each crossing changes
the count by its direction times its multiplicity: :func:`item_stable_set` turns the
count at small K, the crossings (:func:`dedupe_crossings`) and the unresolved zones
(:func:`crossing_events`) into the stable set in K.

The counts a stable set needs besides the one at small K (after every unresolved
zone, and the cross-checks in a few gaps) are independent per item and per K:
:func:`gap_counts` gathers those of every item of a batch into a few calls of
:func:`winding`, which is what keeps the full analysis of many loops from being a
Python loop over them (each row of a winding is subdivided and summed on its own, in
the same order whatever else is in the call, so the counts are the same as one by one).

References
----------
P. Henrici, *Applied and Computational Complex Analysis*, vol. 1, Wiley 1974, sec. 4.6
(the argument principle); R. E. Moore, R. B. Kearfott and M. J. Cloud, *Introduction
to Interval Analysis*, SIAM 2009, ch. 8.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from hapstab.analysis.exact.boxes import (
    THETA_FLOOR,
    U_HI,
    U_LO,
    Cells,
    at_theta_floor,
    disc_quadratic,
    split_cells,
)
from hapstab.analysis.exact.stable_set import StableSet, first_only, stable_set
from hapstab.engine.frequency import LoopResponse
from hapstab.errors import AnalysisError

__all__ = ["winding", "winding_on_cells", "gap_counts", "crossing_events", "item_stable_set",
           "dedupe_crossings"]

#: Rows (requested counts times the cells of [0, pi]) per call of :func:`winding` when
#: the counts of many items are gathered: a call holds some tens of complex arrays of
#: this length (about 100 MB at 2^17); the counts do not depend on the grouping.
WIND_ROWS = 1 << 17

#: Counts already computed: (item, u) -> poles outside (-1: not certifiable).
Known = dict[tuple[int, float], int]


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
        pts = _coefficients(resp, items[row], mid, np.zeros_like(mid))
        cel = _coefficients(resp, items[row], mid, rho)
        vd = [cc.value_disc(rho, p) for cc, p in zip(cel, pts, strict=True)]
        fc, fr = disc_quadratic(np.array([v[0] for v in vd]), np.array([v[1] for v in vd]), u[row],
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
    F = _coefficients(resp, items[rr], ends, np.zeros_like(ends))
    val = F[0].vc + u[rr] * (F[1].vc + u[rr] * F[2].vc)
    fa, fb = val[:A.size], val[A.size:]
    inc = np.angle(fb / fa)
    total = np.zeros(items.size)
    np.add.at(total, R, inc)
    turns = total / np.pi
    out = resp.q - np.round(turns).astype(int)
    bad = bad_rows | (np.abs(turns - np.round(turns)) > 1e-6)  # whole to ~1e-15: winding_on_cells
    return np.where(bad, -1, out)


def winding_on_cells(resp: LoopResponse, c: Cells, leaves: np.ndarray, u: np.ndarray,
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
    kids = leaves[:0]
    for _ in range(200):
        it = c.item[leaves]
        fc, fr = disc_quadratic(c.vc[:, leaves], c.vr[:, leaves], u[it], np.zeros(leaves.size))
        holds0 = ~(np.abs(fc) > fr)
        if not holds0.any():
            break
        floor = holds0 & at_theta_floor(c, leaves)
        if robust:
            pc, pr = disc_quadratic(c.pc[:, leaves], c.pr[:, leaves], u[it], np.zeros(leaves.size))
            floor |= holds0 & ~(np.abs(pc) > pr)
        bad_item[it[floor]] = True
        split = leaves[holds0 & ~floor]
        keep = leaves[~holds0 | floor]
        if not split.size:
            break
        kids = c.add(resp, *split_cells(c, split))
        leaves = np.concatenate([keep, kids])
    else:       # the items still splitting (not every item of a batch)
        bad_item[c.item[kids]] = True
    it = c.item[leaves]
    order = np.lexsort((c.th[leaves], it))
    leaves, it = leaves[order], it[order]
    fc, fr = disc_quadratic(c.vc[:, leaves], c.vr[:, leaves], u[it], np.zeros(leaves.size))
    F, _ = disc_quadratic(c.pc[:, leaves], c.pr[:, leaves], u[it], np.zeros(leaves.size))
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


def _coefficients(resp: LoopResponse, it: np.ndarray, th: np.ndarray, rho: np.ndarray) -> list:
    """:meth:`~LoopResponse.coefficients`, each distinct (item, theta, rho) evaluated once:
    neighbouring cells share their ends, and the counts of one item at several u share
    their cells. The evaluation is elementwise, so the values are those of the full call."""
    order = np.lexsort((rho, th, it))
    a, b, c = it[order], th[order], rho[order]
    new = np.ones(it.size, bool)
    new[1:] = (a[1:] != a[:-1]) | (b[1:] != b[:-1]) | (c[1:] != c[:-1])
    if new.all():
        return resp.coefficients(it, th, rho)
    inv = np.empty(it.size, int)
    inv[order] = np.cumsum(new) - 1
    first = order[new]
    F = resp.coefficients(it[first], th[first], rho[first])
    return [type(j)(j.vc[inv], j.vr[inv], j.dc[inv], j.dr[inv]) for j in F]


def gap_counts(resp: LoopResponse, anchor: np.ndarray, events: Sequence[list[Any]],
               check: np.ndarray | None = None) -> Known:
    """Every count the full stable sets of ``resp``'s items ask for that is known in
    advance (after each unresolved zone, and :func:`_verify`'s gaps), computed in
    batched calls of :func:`winding` of at most :data:`WIND_ROWS` rows.

    Parameters
    ----------
    resp : LoopResponse
    anchor : (L,) array of int
        Poles outside at U_LO per item (-1: not certified; such an item needs none).
    events : list of list
        Each item's events (:func:`crossing_events`).
    check : (L,) array of bool, optional
        Items whose counts :func:`_verify` cross-checks (default all).

    Returns
    -------
    dict
        (item, u) -> the count :func:`winding` gives there.
    """
    reqs: list[tuple[int, float]] = []
    for i, ev in enumerate(events):
        if anchor[i] >= 0 and ev:
            reqs += [(i, u) for u in _zone_points(ev, check is None or bool(check[i]))]
            if check is None or check[i]:
                reqs += [(i, u) for u in _verify_points(ev)[1]]
    reqs = list(dict.fromkeys(reqs))
    per = max(1, WIND_ROWS // max(8, int(np.ceil(np.pi * resp.phase_rate / 1.2))))
    known: Known = {}
    for k in range(0, len(reqs), per):
        part = reqs[k:k + per]
        got = winding(resp, np.array([i for i, _ in part]), np.array([u for _, u in part]))
        known.update(zip(part, (int(g) for g in got), strict=True))
    return known


def _wind(resp: LoopResponse, i: int, us: list[float], known: Known | None) -> list[int]:
    """Counts of item i at ``us``: from ``known`` when all are there, else computed."""
    if known is not None and all((i, u) in known for u in us):
        return [known[(i, u)] for u in us]
    return [int(c) for c in winding(resp, np.full(len(us), i), np.array(us))]


def _gap_point(events: list[Any], g: int) -> float:
    """Where the count after event g is taken: inside the gap to the next event."""
    b = events[g][1]
    hi = events[g + 1][0] if g + 1 < len(events) else 4 * b
    return math.sqrt(b * hi) if hi > b else b


def _zone_points(events: list[Any], top: bool = True) -> list[float]:
    """The gap points after each unresolved zone (multiplicity 0); ``top`` False: not
    after a zone that reaches U_HI (see :func:`_counts`)."""
    return [_gap_point(events, g) for g, ev in enumerate(events)
            if ev[4] == 0 and (top or ev[1] < U_HI)]


def _verify_points(events: list[Any]) -> tuple[list[int], list[float]]:
    """The gaps :func:`_verify` cross-checks (the first and last, up to 6 others) and
    the u at which it counts in each."""
    gaps = sorted({1, len(events)} | set(range(2, len(events), max(1, len(events) // 6))))
    us = []
    for g in gaps:
        lo = events[g - 1][1]
        hi = events[g][0] if g < len(events) else lo * 4
        us.append(math.sqrt(lo * hi) if hi > lo else lo)
    return gaps, us


def crossing_events(cross, unsure) -> tuple[list[tuple[float, float]], list[Any]]:
    """The merged unresolved zones and the sorted events: crossings outside the zones
    (a crossing inside one is part of it: the count after the zone comes from the
    argument principle above it, which accounts for all it holds) and the zones."""
    unc = _merge(unsure)
    inside = lambda u: any(a <= u <= b for a, b in unc)  # noqa: E731
    events = sorted([(u, u, t, d, m) for u, t, d, m in cross if not inside(u)] +
                    [(a, b, math.nan, 0, 0) for a, b in unc])
    return unc, events


def item_stable_set(resp: LoopResponse, i: int, anchor: int, cross, unsure, full: bool,
              known: Known | None = None, check: bool = True) -> StableSet:
    """Item i's stable set from the count of poles outside at U_LO (``anchor``, -1:
    not certified), its crossings and its unresolved zones; ``known``: counts
    already computed (:func:`gap_counts`); ``check``: cross-check the counts from
    the crossings' directions by the argument principle (:func:`_verify`)."""
    s = float(resp.scale[i])
    _unc, events = crossing_events(cross, unsure)
    base: dict[str, Any] = {"rigid": resp.rigid, "outside_small_K": anchor,
                            "events": tuple((a * s, b * s, t, d, m) for a, b, t, d, m in events)}
    if anchor < 0:
        return StableSet(**base, kmax=0.0, intervals=(), theta=math.nan,
                         uncertain=((0.0, U_LO * s),))
    if not full:
        return StableSet(**base, **first_only(events, anchor, s))
    counts = _counts(resp, i, events, anchor, known, check)
    if check:
        _verify(resp, i, events, counts, known)
    return StableSet(**base, **stable_set(events, counts, s))


def _counts(resp: LoopResponse, i: int, events: list[Any], anchor: int,
            known: Known | None = None, top: bool = True) -> list[int | None]:
    """The number of poles outside in each gap between events: each crossing changes
    it by its direction times its multiplicity; after an unresolved zone it is
    counted anew by the argument principle (None: not certifiable either, so that
    gap is not claimed stable). ``top`` False (a ball proof follows, which examines
    nothing above U_HI): the gap above a zone that reaches U_HI is not counted (None)
    -- at such K the count costs the most and decides nothing the proof uses."""
    counts: list[int | None] = [anchor]
    for g, (_a, b, _t, d, m) in enumerate(events):
        prev = counts[-1]
        if m == 0 and not top and b >= U_HI:
            counts.append(None)
        elif m == 0 or prev is None:
            nxt = _wind(resp, i, [_gap_point(events, g)], known)[0]
            counts.append(nxt if nxt >= 0 else None)
        else:
            counts.append(prev + int(d * m))
    if min(c for c in counts if c is not None) < 0:
        raise AnalysisError("crossing analysis: a negative count of unstable poles; please "
                            "report this loop")
    return counts


def _verify(resp: LoopResponse, i: int, events, counts, known: Known | None = None) -> None:
    """Cross-check the counts from crossing directions by the argument principle in
    a few gaps (the first and last, and up to 6 others)."""
    if not events:
        return
    gaps, us = _verify_points(events)
    got = _wind(resp, i, us, known)
    for g, c in zip(gaps, got, strict=True):
        if c >= 0 and counts[g] is not None and c != counts[g]:
            raise AnalysisError(f"crossing analysis: the pole count {counts[g]} from crossing "
                                f"directions disagrees with the argument principle ({c}) at "
                                f"K = {us[gaps.index(g)] * resp.scale[i]:.6g}; please report this loop")


def dedupe_crossings(cross: list[tuple[float, float, int, int]]
                     ) -> list[tuple[float, float, int, int]]:
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
