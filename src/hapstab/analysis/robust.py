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
from dataclasses import dataclass, field

import numpy as np

from hapstab import budget
from hapstab.analysis.exact.boxes import U_HI, U_LO
from hapstab.analysis.exact.core import exact_critical_stiffness
from hapstab.analysis.exact.crossings import winding
from hapstab.analysis.exact.families import crossing_gradient, first_events
from hapstab.analysis.exact.zonotope import family_floor
from hapstab.analysis.robust_result import RobustStiffnessResult
from hapstab.engine.frequency import LoopResponse, PortPoly
from hapstab.engine.operator_family import BoxPoly, derivative_response, family_response
from hapstab.engine.structure import structure_of
from hapstab.errors import AnalysisError, check_real
from hapstab.models.loops import HapticLoop, TeleoperationLoop
from hapstab.models.operators import OperatorBox

__all__ = ["robust_critical_stiffness", "RobustStiffnessResult", "DEFAULT_RTOL"]

#: Default relative gap: well above the exact core's accuracy (1e-13..1e-11, so that
#: the bounds can meet) and far below any physical meaning of a stiffness; a looser
#: rtol costs fewer sub-boxes where the minimum is interior.
DEFAULT_RTOL = 1e-6
#: Sub-boxes split per round (one batched search each for the boxes and their points).
BATCH = 16


@dataclass
class _Leaf:
    """A sub-box, its certified lower bound (N/m) and, where known, the direction
    to split."""

    lo: np.ndarray
    hi: np.ndarray
    lb: float = 0.0
    score: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class _State:
    """The branch and bound's bookkeeping."""

    loop: HapticLoop | TeleoperationLoop
    rtol: float = DEFAULT_RTOL
    upper: float = math.inf
    best: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    evaluated: int = 0
    pruned: float = math.inf


def _points(loop: HapticLoop | TeleoperationLoop, P: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, list]:
    """Enclosures [K_lo, K_hi] (N/m) of the exact K_max of the operators P (n, 3) and
    the boxes isolating their crossings (None where there is none); K_hi is nan where
    the search could not isolate the crossing (no upper bound)."""
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
    return lo, hi, [e.box for e in ev]


def _evaluate(st: _State, leaves: list[_Leaf]) -> None:
    """Lower bounds of the sub-boxes (the zonotope floor, the disc search, and the
    mean-value form from each one's point a) and the upper bound from the points a."""
    LO = np.array([lf.lo for lf in leaves])
    HI = np.array([lf.hi for lf in leaves])
    C = 0.5 * (LO + HI)
    n = len(leaves)
    resp, poly = family_response(st.loop, LO, HI)
    cen, _ = family_response(st.loop, C, C)
    ev, _ = first_events(resp)
    st.evaluated += n
    vary = list(poly.varying)
    half = 0.5 * (HI - LO)
    dres = [derivative_response(resp, poly, j) for j in range(len(vary))]
    lb = np.array([0.0 if e.anchor != 0 else e.u_lo * resp.scale[i] for i, e in enumerate(ev)])
    glo, ghi = np.full((n, 3), -np.inf), np.full((n, 3), np.inf)
    glo[:, [j for j in range(3) if j not in vary]] = 0.0
    ghi[:, [j for j in range(3) if j not in vary]] = 0.0
    _, c_hi, c_box = _points(st.loop, C)
    _update_upper(st, C, c_hi)
    iso = np.array([i for i, e in enumerate(ev) if e.box is not None and c_box[i] is not None], int)
    rest = np.setdiff1d(np.arange(n), iso)     # the zonotope floor where nothing is isolated
    if rest.size:
        rel = np.max(half / np.maximum(np.abs(C), 1e-300), axis=1)    # relative size
        lb[rest] = np.maximum(lb[rest], _zonotope_bound(st, _items(cen, rest),
                                                        [_items(d, rest) for d in dres],
                                                        half[np.ix_(rest, vary)], rel[rest]))
    if iso.size and vary:
        a, b, X = crossing_gradient(resp, dres, iso, [ev[i].box for i in iso],
                                    [c_box[i] for i in iso], half[np.ix_(iso, vary)])
        glo[np.ix_(iso, vary)] = a * resp.scale[iso, None]
        ghi[np.ix_(iso, vary)] = b * resp.scale[iso, None]
        lb[iso] = np.maximum(lb[iso], [x[0] * resp.scale[i] for x, i in zip(X, iso, strict=True)])
    known = np.all(np.isfinite(glo) & np.isfinite(ghi), axis=1)
    anchor = np.where(glo >= 0, LO, np.where(ghi <= 0, HI, C))
    k_lo, k_hi, _ = _points(st.loop, anchor)
    _update_upper(st, anchor, k_hi)
    steep = np.where((glo >= 0) | (ghi <= 0), 0.0, np.maximum(np.abs(glo), np.abs(ghi)))
    for i, lf in enumerate(leaves):
        lf.lb = float(lb[i])
        if known[i] and np.isfinite(k_lo[i]) and not np.isnan(k_hi[i]):
            drop = float(np.sum(steep[i] * half[i])) * (1 + 1e-12)   # rounding of the sum
            lf.lb = max(lf.lb, float(np.nextafter(k_lo[i] - drop, -np.inf)))
        lf.score = (np.maximum(np.abs(glo[i]), np.abs(ghi[i])) * 2 * half[i] if known[i]
                    else _spread(poly, i, half[i], vary))


def _zonotope_bound(st: _State, cen: LoopResponse, dres: list[LoopResponse],
                    half: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """The zonotope floor of each family in N/m (0 where the count of poles outside
    at K -> 0+ is not zero), searched only below the best upper bound so far."""
    n = cen.size
    cap = np.full(n, U_HI) if math.isinf(st.upper) else \
        np.minimum(U_HI, st.upper * (1 + 1e-9) / cen.scale)      # just above the best
    # resolve u to a quarter of the gap asked for, or to the zonotope's own error
    # (second order in the box's relative size w: about w^2; 0.1 w^2 to be safe)
    floor = family_floor(cen, dres, half, cap, np.maximum(st.rtol / 4, 0.1 * rel ** 2))
    count = winding(cen, np.arange(n), np.full(n, U_LO))
    # no loop of a family has a crossing in [U_LO, floor): each has the centre's count
    lb = np.where((floor > U_LO) & (count == 0), floor * cen.scale, 0.0)
    return np.where((floor >= U_HI) & (count == 0), np.inf, lb)


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
                                                                         1e-300))
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


def _split(lf: _Leaf) -> tuple[_Leaf, _Leaf]:
    """Halve a sub-box along the direction with the largest score (its contribution
    to the mean-value gap), else its widest relative side (geometric midpoint for a
    range over a factor of 4 above 0)."""
    w = lf.hi - lf.lo
    if np.any(lf.score > 0):
        j = int(np.argmax(lf.score))
    else:
        rel = np.where(w > 0, w / np.maximum(np.maximum(np.abs(lf.hi), np.abs(lf.lo)), 1e-300),
                       -1.0)
        j = int(np.argmax(rel))
    a, b = lf.lo[j], lf.hi[j]
    mid = math.sqrt(a * b) if a > 0 and b > 4 * a else 0.5 * (a + b)
    left_hi, right_lo = lf.hi.copy(), lf.lo.copy()
    left_hi[j], right_lo[j] = mid, mid
    return _Leaf(lf.lo.copy(), left_hi), _Leaf(right_lo, lf.hi.copy())


def _vertices(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    axes = [np.unique([a, b]) for a, b in zip(lo, hi, strict=True)]
    return np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T


def robust_critical_stiffness(loop: HapticLoop | TeleoperationLoop, box: OperatorBox, *,
                              rtol: float = DEFAULT_RTOL, max_boxes: int = 2000,
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
    budget.check(budget.exact_points_cost(f"robust K_max: up to {max_boxes} operator sub-boxes",
                                          2 * max_boxes, order_estimate(loop, max(delays))),
                 max_memory, max_seconds)
    t0 = time.perf_counter()
    st = _State(loop, rtol)
    verts = _vertices(box.lo, box.hi)
    _, v_hi, _ = _points(loop, verts)
    _update_upper(st, verts, v_hi)
    leaves = [_Leaf(box.lo.astype(float), box.hi.astype(float))]
    _evaluate(st, leaves)
    while True:
        lower = min([lf.lb for lf in leaves] + [st.pruned])
        if _done(st.upper, lower, rtol) or st.evaluated >= max_boxes:
            break
        live = [lf.lb < st.upper * (1 - rtol) for lf in leaves]
        keep = [lf for lf, ok in zip(leaves, live, strict=True) if ok]
        st.pruned = min([st.pruned] + [lf.lb for lf, ok in zip(leaves, live, strict=True)
                                       if not ok])
        keep.sort(key=lambda lf: lf.lb)
        todo, rest = keep[:BATCH], keep[BATCH:]
        kids = [k for lf in todo for k in _split(lf)]
        _evaluate(st, kids)
        leaves = rest + kids
    return _result(st, box, lower, rtol, verts, v_hi, time.perf_counter() - t0)


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
            v_hi: np.ndarray, seconds: float) -> RobustStiffnessResult:
    """The answer: the certified bound, the named operator with its exact K_max, the
    vertices' minimum beside it."""
    lower = max(0.0, lower)
    named = st.best
    exact = math.nan
    if not np.isnan(named).any():
        exact = exact_critical_stiffness(st.loop.replace(
            operator=box.operator(*named))).critical_stiffness
    vmin = float(np.nanmin(v_hi)) if np.any(~np.isnan(v_hi)) else math.nan
    vert = verts[int(np.nanargmin(v_hi))] if np.any(~np.isnan(v_hi)) else named
    converged = _done(st.upper, lower, rtol)
    return RobustStiffnessResult(lower, tuple(float(x) for x in named), float(exact),
                                 st.upper, converged, st.evaluated, rtol, vmin,
                                 tuple(float(x) for x in vert), box, seconds, st.loop)
