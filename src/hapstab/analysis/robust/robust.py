"""Robust K_max over an uncertain operator: the smallest exact K_max over a box of
operator masses, dampings and stiffnesses, with a certified lower bound and the
operator that attains it.

Branch and bound over the operator box. For each sub-box B:

* **lower bound** -- the certified crossing search run on the port polynomials
  enclosed over B (:mod:`hapstab.analysis.exact.families`): the lowest K at which
  the enclosure admits a pole on the circle, 0 if the count of poles outside at
  K -> 0+ is not certified zero for all of B. When the lowest crossing of every
  operator of B is isolated in one Krawczyk box (unique and regular), K_max(p) is
  smooth on B and a mean-value bound is used as well: from an operator a of B
  (the corner in each direction where the enclosed gradient has one sign, else the
  centre), ``K_max(p) >= K_max(a) - sum_i max|dK/dp_i| |p_i - a_i|`` over the
  directions where the sign is not known, K_max(a) enclosed by the same search.
  The larger of the two is B's bound; both are certified.
* **upper bound** -- the enclosed K_max of the real operators evaluated (every
  vertex of the box at the start, then each sub-box's a): its upper end.

The sub-boxes with the lowest bounds are split (along the direction that
contributes most to their gap, else their widest in relative terms) until
``upper - lower <= rtol * upper`` or the budget of sub-boxes is spent; the gap is
then reported. The answer's ``critical_stiffness`` is the minimum over all
sub-boxes of their lower bounds, so it is never above the true minimum; vertices
alone are not enough (the boundary is not monotone in the operator).

References
----------
R. E. Moore, R. B. Kearfott and M. J. Cloud, *Introduction to Interval Analysis*,
SIAM 2009, ch. 6 (mean-value forms, monotonicity) and ch. 12 (global optimisation
by branch and bound); E. Hansen and G. W. Walster, *Global Optimization Using
Interval Analysis*, 2nd ed., Dekker 2004.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hapstab import budget, progress
from hapstab.analysis.exact.boxes import U_HI, U_LO
from hapstab.analysis.exact.core import exact_critical_stiffness
from hapstab.analysis.exact.families import crossing_gradient, first_events
from hapstab.analysis.exact.parametric import isolate
from hapstab.analysis.exact.zonotope import family_floor
from hapstab.analysis.robust.robust_result import RobustStiffnessResult
from hapstab.engine.frequency import LoopResponse, PortPoly
from hapstab.engine.operator_family import BoxPoly, derivative_response, family_response
from hapstab.engine.structure import structure_of
from hapstab.errors import AnalysisError, check_real
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.operators import OperatorBox

__all__ = ["robust_critical_stiffness", "RobustStiffnessResult", "DEFAULT_RTOL", "MAX_BOXES"]

#: Default relative gap: well above the exact core's accuracy (1e-13..1e-11, so that
#: the bounds can meet) and far below any physical meaning of a stiffness; a looser
#: rtol costs fewer sub-boxes where the minimum is interior.
DEFAULT_RTOL = 1e-6
#: Sub-boxes split per round (one batched search each for the boxes and their points).
BATCH = 16
#: Default budget of sub-boxes: the "arm-grasp" preset on the README's device (a flat
#: face: K_max within 4 % across the operators of least damping) needs about 5100.
MAX_BOXES = 6000


@dataclass
class _Leaf:
    """A sub-box, its certified lower bound (N/m) and, where known, the direction
    to split."""

    lo: np.ndarray
    hi: np.ndarray
    lb: float = 0.0
    score: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: the face that holds the box's minimum (K_max proved monotone in some
    #: directions): the box is replaced by it rather than split
    face: tuple[np.ndarray, np.ndarray] | None = None


@dataclass
class _State:
    """The branch and bound's bookkeeping."""

    loop: HapticLoop | TeleoperationLoop
    rtol: float = DEFAULT_RTOL
    upper: float = math.inf
    best: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    evaluated: int = 0
    pruned: float = math.inf


def _points(loop: HapticLoop | TeleoperationLoop, P: np.ndarray, resp: LoopResponse | None = None
            ) -> tuple[np.ndarray, np.ndarray, list, np.ndarray]:
    """Enclosures [K_lo, K_hi] (N/m) of the exact K_max of the operators P (n, 3), the
    boxes isolating their crossings (None where there is none) and their counts of
    poles outside as K -> 0+ (-1: not certified); K_hi is nan where the search could
    not isolate the crossing (no upper bound)."""
    if resp is None:
        resp, _ = family_response(loop, P, P)
    ev, _ = first_events(resp)
    lo, hi = np.zeros(len(ev)), np.full(len(ev), np.nan)
    for i, e in enumerate(ev):
        s = resp.scale[i]
        if e.anchor > 0:                # unstable for every K > 0: K_max = 0, exactly
            hi[i] = 0.0
        elif e.anchor == 0 and math.isinf(e.u_lo):
            lo[i] = hi[i] = math.inf
        elif e.anchor == 0:
            lo[i] = e.u_lo * s
            if e.box is not None:
                hi[i] = e.box[1] * s
    return lo, hi, [e.box for e in ev], np.array([e.anchor for e in ev])


def _evaluate(st: _State, leaves: list[_Leaf]) -> None:
    """Lower bounds of the sub-boxes and the upper bound from the operators tried.

    Per sub-box: the centre operator's crossing (enclosed); the parametric Krawczyk
    box X around it that holds one crossing of every operator (when proved), whose
    branch u_X(p) is smooth on the box: its gradient is enclosed over X and the box,
    and the mean-value form from the operator a (a corner in each direction where
    the gradient has one sign) bounds it below; the zonotope floor bounds every
    other crossing below. The sub-box's bound is the smaller of the two."""
    LO = np.array([lf.lo for lf in leaves])
    HI = np.array([lf.hi for lf in leaves])
    C, half = 0.5 * (LO + HI), 0.5 * (HI - LO)
    n = len(leaves)
    st.evaluated += n
    resp, poly = family_response(st.loop, LO, HI)
    cen, _ = family_response(st.loop, C, C)
    vary = list(poly.varying)
    dres = [derivative_response(resp, poly, j) for j in range(len(vary))]
    c_lo, c_hi, c_box, count = _points(st.loop, C, cen)
    _update_upper(st, C, c_hi)
    hv = half[:, vary]
    iso = np.array([i for i in range(n) if c_box[i] is not None and count[i] == 0], int)
    X: list = [None] * n            # the contracted boxes
    X0: list = [None] * n           # the boxes proved to hold one crossing each
    if iso.size and vary:
        for i, x in zip(iso, isolate(resp, cen, dres, iso, hv[iso], [c_box[i] for i in iso]),
                        strict=True):
            if x is not None:
                X0[i], X[i] = x
    # the sub-boxes' relative sizes (a zero centre guarded)
    other, clear = _lower(st, cen, dres, hv, np.max(half / np.maximum(np.abs(C), 1e-300),
                                                     axis=1), count, X0)
    branch = np.array([np.inf if x is None else x[0] * cen.scale[i] for i, x in enumerate(X)])
    glo, ghi = np.full((n, 3), -np.inf), np.full((n, 3), np.inf)
    glo[:, [j for j in range(3) if j not in vary]] = 0.0
    ghi[:, [j for j in range(3) if j not in vary]] = 0.0
    top = np.flatnonzero(np.isfinite(branch))
    if top.size:
        a, b, Xn = crossing_gradient(resp, dres, top, [X[i] for i in top],
                                     [c_box[i] for i in top], hv[top])
        cols = np.array(vary, int)
        glo[np.ix_(top, cols)] = a * resp.scale[top, None]
        ghi[np.ix_(top, cols)] = b * resp.scale[top, None]
        branch[top] = [x[0] * resp.scale[i] for x, i in zip(Xn, top, strict=True)]
    known = np.isfinite(branch) & np.all(np.isfinite(glo) & np.isfinite(ghi), axis=1)
    branch = np.maximum(branch, _mean_value(st, LO, HI, glo, ghi, known, c_lo, c_hi))
    for i, lf in enumerate(leaves):
        lf.lb = float(min(other[i], branch[i])) if vary else \
            (float(c_lo[i]) if count[i] == 0 else 0.0)   # a single operator: its enclosure
        lf.score = (np.maximum(np.abs(glo[i]), np.abs(ghi[i])) * 2 * half[i] if known[i]
                    else _spread(poly, i, half[i], vary))
        mono = known[i] & clear[i] & (HI[i] > LO[i]) & ((glo[i] >= 0) | (ghi[i] <= 0))
        if mono.any() and not np.all(mono | (HI[i] == LO[i])):
            # below the best upper bound, K_max is u_X, monotone along these directions
            # on the whole box: the box's minimum there is on this face
            face = np.where(glo[i] >= 0, LO[i], HI[i])
            lf.face = (np.where(mono, face, LO[i]), np.where(mono, face, HI[i]))


def _mean_value(st: _State, LO: np.ndarray, HI: np.ndarray, glo: np.ndarray, ghi: np.ndarray,
                known: np.ndarray, c_lo: np.ndarray, c_hi: np.ndarray) -> np.ndarray:
    """The mean-value bound of each isolated branch (N/m; -inf where none): from the
    operator a at the corner along each direction where the gradient has one sign
    (the centre along the others), u_X(p) >= u_X(a) - sum_i max|du/dp_i| |p_i - a_i|
    over the directions of unknown sign; u_X(a) is enclosed by a search of its own."""
    n = LO.shape[0]
    C, half = 0.5 * (LO + HI), 0.5 * (HI - LO)
    anchor = np.where(glo >= 0, LO, np.where(ghi <= 0, HI, C))
    k_lo, k_hi = c_lo.copy(), c_hi.copy()
    moved = np.flatnonzero(known & np.any(anchor != C, axis=1))     # the centre is done
    if moved.size:
        k_lo[moved], k_hi[moved], _, _ = _points(st.loop, anchor[moved])
        _update_upper(st, anchor[moved], k_hi[moved])
    steep = np.where((glo >= 0) | (ghi <= 0) | (half == 0), 0.0,
                     np.maximum(np.abs(glo), np.abs(ghi)))
    drop = np.sum(steep * half, axis=1) * (1 + 1e-12)   # (1e-12: the rounding of the sum)
    ok = known & np.isfinite(k_lo) & ~np.isnan(k_hi)
    return np.where(ok, np.nextafter(k_lo - drop, -np.inf), -np.inf) if n else np.zeros(0)


def _lower(st: _State, cen: LoopResponse, dres: list[LoopResponse], half: np.ndarray,
           rel: np.ndarray, count: np.ndarray, X: list) -> tuple[np.ndarray, np.ndarray]:
    """A lower bound (N/m) of every crossing of each family outside its box X (all of
    them where there is no X; X is the box proved to hold one crossing of each loop),
    by the zonotope floor searched below the best upper bound so far; and whether
    nothing outside X was found below that (then, below it, each loop's K_max is its
    crossing in X).

    No loop of a family has a crossing in [U_LO, floor) outside X, and X lies above
    its own lower end: by continuity each loop has the centre's count of poles
    outside there, so the bound is 0 unless that count is 0 (and when it is
    positive every loop has K_max = 0)."""
    n = cen.size
    cap = np.full(n, U_HI) if math.isinf(st.upper) else \
        np.minimum(U_HI, st.upper * (1 + 1e-9) / cen.scale)      # just above the best
    skip = np.full((n, 4), np.nan)
    for i, x in enumerate(X):
        if x is not None:
            skip[i] = (x[2] - x[3], x[2] + x[3], x[0], x[1])
    # resolve u to a quarter of the gap asked for, or to the zonotope's own error
    # (second order in the box's relative size w: about w^2; 0.1 w^2 to be safe)
    floor = family_floor(cen, dres, half, cap, np.maximum(st.rtol / 4, 0.1 * rel ** 2), skip)
    below = np.where(np.isnan(skip[:, 2]), floor, np.minimum(floor, skip[:, 2]))
    ok = (below > U_LO) & (count == 0)
    lb = np.where(ok, floor * cen.scale, 0.0)
    return np.where(ok & (floor >= U_HI), np.inf, lb), ok & (floor >= cap)


def _items(resp: LoopResponse, idx: np.ndarray) -> LoopResponse:
    """The items ``idx`` of a response."""
    pick = lambda a: a[idx]  # noqa: E731
    ports = [PortPoly(pick(pp.d), pick(pp.dhat), pick(pp.N), {f: pick(v) for f, v in pp.Nt.items()},
                      {f: pick(v) for f, v in pp.D.items()}, {k: pick(v) for k, v in pp.err.items()})
             for pp in resp.ports]
    return dataclasses.replace(resp, ports=ports, k=pick(resp.k), beta=pick(resp.beta),
                               scale=pick(resp.scale), periods=pick(resp.periods),
                               gain=None if resp.gain is None else pick(resp.gain))


def _spread(poly: BoxPoly, i: int, half: np.ndarray, vary: list[int]) -> np.ndarray:
    """Which parameter moves the operator port's polynomials most over a box (relative
    to their size): the direction to split when no gradient is known."""
    out = np.zeros(3)
    for p, j in enumerate(vary):
        rel = [np.max(np.abs(poly.dmid[nm][p, i]) * half[j] / np.maximum(np.abs(poly.mid[nm][i]),
                                                                         1e-300))  # 0 guarded
               for nm in ("d", "N")]
        out[j] = max(rel)
    return out


def _update_upper(st: _State, P: np.ndarray, k_hi: np.ndarray) -> None:
    ok = np.isfinite(k_hi) | np.isinf(k_hi) & (k_hi > 0)
    ok &= ~np.isnan(k_hi)
    if ok.any():
        i = int(np.flatnonzero(ok)[np.argmin(k_hi[ok])])
        if k_hi[i] < st.upper or np.isnan(st.best).any():
            st.upper, st.best = float(k_hi[i]), P[i].copy()


def _split(lf: _Leaf) -> tuple[_Leaf, ...]:
    """The face that holds a sub-box's minimum, where one is known; else its two
    halves along the direction with the largest score (its contribution to the
    mean-value gap), else along its widest relative side (geometric midpoint for a
    range over a factor of 4 above 0)."""
    if lf.face is not None:
        return (_Leaf(lf.face[0].copy(), lf.face[1].copy(), lf.lb),)
    w = lf.hi - lf.lo
    if np.any(lf.score > 0):
        j = int(np.argmax(lf.score))
    else:
        # relative widths (a range [0, x] counts as 1; the 1e-300 only guards 0 / 0)
        rel = np.where(w > 0, w / np.maximum(np.maximum(np.abs(lf.hi), np.abs(lf.lo)), 1e-300),
                       -1.0)
        j = int(np.argmax(rel))
    a, b = lf.lo[j], lf.hi[j]
    mid = math.sqrt(a * b) if a > 0 and b > 4 * a else 0.5 * (a + b)
    left_hi, right_lo = lf.hi.copy(), lf.lo.copy()
    left_hi[j], right_lo[j] = mid, mid
    return _Leaf(lf.lo.copy(), left_hi), _Leaf(right_lo, lf.hi.copy())


def _unique(leaves: list[_Leaf]) -> list[_Leaf]:
    """The sub-boxes without repeats (two boxes may reduce to the same face)."""
    seen: dict[tuple, _Leaf] = {}
    for lf in leaves:
        seen.setdefault((*lf.lo.tolist(), *lf.hi.tolist()), lf)
    return list(seen.values())


def _vertices(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    axes = [np.unique([a, b]) for a, b in zip(lo, hi, strict=True)]
    return np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T


def robust_critical_stiffness(loop: HapticLoop | TeleoperationLoop, box: OperatorBox, *,
                              rtol: float = DEFAULT_RTOL, max_boxes: int = MAX_BOXES,
                              max_memory: float | None = None,
                              max_seconds: float | None = None) -> RobustStiffnessResult:
    """The smallest exact K_max over every operator of ``box``, certified from below.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        The loop (HVE, or PEB with the operator at the master); its own operator is
        replaced by the box's. Spring-damper controllers; any delay.
    box : OperatorBox
        Operator mass, damping and stiffness ranges (see
        :func:`hapstab.models.operators.operator_box`).
    rtol : float
        Stop when upper - lower <= rtol * upper (default 1e-6, see
        :data:`DEFAULT_RTOL`).
    max_boxes : int
        Budget of sub-boxes; when it is spent the gap is reported (``converged``
        False).
    max_memory, max_seconds : float, optional
        Budget in bytes and seconds (default :mod:`hapstab.budget`'s), estimated
        for ``max_boxes`` sub-boxes before starting.

    Returns
    -------
    RobustStiffnessResult
        ``critical_stiffness``: a certified lower bound of min K_max over the box;
        ``operator``: the operator with the smallest K_max found, its exact K_max
        (``operator_critical_stiffness``), the gap, the sub-boxes evaluated and the
        minimum over the box's vertices alone.

    Raises
    ------
    AnalysisError
        A loop other than the HVE or PEB, controllers that are not spring-dampers,
        a bad ``rtol`` or ``max_boxes``.

    References
    ----------
    See the module docstring.
    """
    rtol, max_boxes = _check(loop, box, rtol, max_boxes)
    from hapstab.analysis.methods import order_estimate
    delays = [getattr(loop, "delay_in_samples", 0.0)]
    # sub-boxes go in batches of 2 BATCH, each about two certified searches (a K_max's
    # cost, budget.exact_points_cost: the box and its centre; its point a only when a
    # gradient sign is known); the memory is that of one batch, whatever the budget
    per = budget.exact_points_cost("", 2, order_estimate(loop, max(delays)))
    # (time is not refused up front: the search stops at the time budget, with its gap)
    budget.check(budget.Cost(f"robust K_max: up to {max_boxes} operator sub-boxes",
                             2 * BATCH * per.memory_bytes, 0.0), max_memory, None)
    seconds = budget.seconds_allowed(max_seconds)
    t0 = time.perf_counter()
    st = _State(loop, rtol)
    verts = _vertices(box.lo, box.hi)
    _, v_hi, _, _ = _points(loop, verts)
    _update_upper(st, verts, v_hi)
    leaves = [_Leaf(box.lo.astype(float), box.hi.astype(float))]
    with progress.steps(max_boxes, f"robust K_max: up to {max_boxes} sub-boxes") as advance:
        lower = _search(st, leaves, rtol, max_boxes, lambda: time.perf_counter() - t0 > seconds,
                        advance)
    stopped = "" if _done(st.upper, lower, rtol) else (
        "boxes" if st.evaluated >= max_boxes else "time")
    return _result(st, box, lower, rtol, verts, v_hi, time.perf_counter() - t0, stopped)


def _search(st: _State, leaves: list[_Leaf], rtol: float, max_boxes: int,
            late: Callable[[], bool], advance: Callable[[int], None]) -> float:
    """Branch and bound until the gap is within ``rtol``, ``max_boxes`` are spent or
    ``late()``; returns the certified lower bound (the least of the live leaves' and the
    pruned ones': sound whenever it stops)."""
    _evaluate(st, leaves)
    advance(st.evaluated)
    while True:
        lower = min([lf.lb for lf in leaves] + [st.pruned])
        if _done(st.upper, lower, rtol) or st.evaluated >= max_boxes or late():
            return lower
        live = [lf.lb < st.upper * (1 - rtol) for lf in leaves]
        keep = [lf for lf, ok in zip(leaves, live, strict=True) if ok]
        st.pruned = min([st.pruned] + [lf.lb for lf, ok in zip(leaves, live, strict=True)
                                       if not ok])
        keep.sort(key=lambda lf: lf.lb)
        todo, rest = keep[:BATCH], keep[BATCH:]
        kids = _unique([k for lf in todo for k in _split(lf)])
        before = st.evaluated
        _evaluate(st, kids)
        advance(st.evaluated - before)
        leaves = rest + kids


def _done(upper: float, lower: float, rtol: float) -> bool:
    if math.isinf(upper):
        return math.isinf(lower)
    return upper - lower <= rtol * upper


def _check(loop: HapticLoop | TeleoperationLoop, box: OperatorBox, rtol: float,
           max_boxes: int) -> tuple[float, int]:
    if not isinstance(box, OperatorBox):
        raise AnalysisError(f"box = {box!r:.60}: must be an OperatorBox (see operator_box)")
    if getattr(loop, "kind", None) not in ("hve", "peb") or not structure_of(loop).simple:
        raise AnalysisError(f"loop kind = {getattr(loop, 'kind', type(loop).__name__)!r}: the "
                            "robust K_max takes the HVE and PEB (operator at the master)")
    rtol = check_real("rtol", rtol, positive=True)
    if isinstance(max_boxes, bool) or not isinstance(max_boxes, (int, np.integer)) \
            or max_boxes < 1:
        raise AnalysisError(f"max_boxes = {max_boxes!r}: must be a whole number >= 1")
    return rtol, int(max_boxes)


def _result(st: _State, box: OperatorBox, lower: float, rtol: float, verts: np.ndarray,
            v_hi: np.ndarray, seconds: float, stopped: str = "") -> RobustStiffnessResult:
    """The answer: the certified bound, the named operator with its exact K_max, the
    vertices' minimum beside it."""
    lower = max(0.0, lower)
    named = st.best
    exact = math.nan
    if not np.isnan(named).any():
        exact = exact_critical_stiffness(st.loop.replace(
            operator=box.operator(*named))).critical_stiffness
        # the minimum over the box is at most the named operator's K_max, proved in ball
        # arithmetic (the safe end, never above the truth): the bound from the float
        # enclosures of the sub-boxes can sit ~1e-12 above it (the proof's 2^-40 window)
        lower = min(lower, exact)
    vmin = float(np.nanmin(v_hi)) if np.any(~np.isnan(v_hi)) else math.nan
    vert = verts[int(np.nanargmin(v_hi))] if np.any(~np.isnan(v_hi)) else named
    converged = _done(st.upper, lower, rtol)
    three = lambda p: (float(p[0]), float(p[1]), float(p[2]))  # noqa: E731
    return RobustStiffnessResult(lower, three(named), float(exact), st.upper, converged,
                                 st.evaluated, rtol, vmin, three(vert), box, seconds, st.loop,
                                 stopped)
