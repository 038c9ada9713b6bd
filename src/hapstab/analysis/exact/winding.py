"""The argument principle in ball arithmetic: the number of closed-loop poles outside
the unit circle at one K, proved piece by piece over [0, pi]
(:mod:`~hapstab.analysis.exact.proof`'s step 3), and the pieces every subdivision of
the proof starts from.

References
----------
.. [1] Miandashti, N. and Tavakoli, M., "Stability of sampled-data, delayed haptic
   interaction under passive or active operator", IEEE Haptics Symposium, 2014
   (the loop; the characteristic function of eq. 8 with the delay's phase).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from hapstab.engine.arb_loop import ArbLoop, poly_k, working_precision

__all__ = ["Count", "count", "root_count", "piece_increment", "start_pieces", "theta_ball",
           "k_ball", "START_PIECES", "FLOOR", "MAX_PIECES", "ROOTS_MAX_DEGREE",
           "subdivision_start", "split_theta", "GEOMETRIC"]

#: Pieces of [0, pi] a search starts from.
START_PIECES = 8
#: A piece narrower than this relative to its upper end (theta or K) is not split again:
#: the proof gives up there (double-precision ends cannot be halved much further).
FLOOR = 4e-16
#: Most pieces one exclusion or count may try (a valve on time: beyond it, uncertain).
MAX_PIECES = 4000
#: Highest degree of the characteristic polynomial counted by root isolation
#: (:func:`root_count`) before the argument principle: measured, Arb isolates the roots
#: of degree 12 in ~0.1-1.4 ms and of degree 64 in 2-23 ms at 320 bits, while a winding
#: count costs 4-19 ms at any degree (HVE, PEB; 2026-12-02). Not a tolerance: either
#: count is a proof.
ROOTS_MAX_DEGREE = 32
#: Highest degree at which root isolation is tried after the argument principle could not
#: decide a count (a pole within ~1e-14 of the circle, where a piece's end lands next to
#: it: marginal-peb#300010 of seed 1631425580, degree 58, undamped ports, at the base
#: point): ~30 ms at degree 68, ~1 s at 300 (measured 2026-12-02), on that failure path
#: only. Not a tolerance: either count is a proof.
ROOTS_FALLBACK_DEGREE = 300
#: The isolating balls' radii :func:`root_count` asks for in turn: 1e-20 (a pole within
#: 1e-20 of the circle is left to the argument principle; about as cheap as Arb's own
#: radii, and it decides the count just above a crossing's window, |z| - 1 ~ 1e-12,
#: where Arb's own balls of ~1e-3 did not and a second search followed: measured 0.9 of
#: 2.5 ms on the paper's PEB at n = 10), then Arb's own (None) when Arb cannot reach
#: 1e-20 within its precision (a cluster). Not tolerances of the answer: a ball that
#: still meets the circle decides nothing.
ROOT_TOLERANCES = (1e-20, None)
#: Arb's root finder may raise its precision to this multiple of the loop's: two modes
#: 1e-10 apart (the two ports of a PEB with nearly equal devices) need ~1280 bits where
#: the default gives up at 320 (measured on mass-peb#1001 of seed 26).
ROOTS_MAX_PREC_FACTOR = 4


def theta_ball(a: float, b: float) -> Any:
    """The ball holding [a, b]; an end equal to ``math.pi`` stands for pi itself."""
    import flint
    arb = flint.arb
    lo = arb.pi() if a == math.pi else arb(a)
    hi = arb.pi() if b == math.pi else arb(b)
    return lo.union(hi)


def k_ball(a: float, b: float) -> Any:
    """The ball holding [a, b] (N/m)."""
    import flint
    arb = flint.arb
    return arb(a).union(arb(b))


def start_pieces(n: int = START_PIECES) -> list[tuple[float, float]]:
    """The n equal pieces of [0, pi] (the last ends at pi itself), the first cut again
    at pi/n 2^-k, k = 1..40 (the poles of a fast-sampled loop crowd z = 1, theta = 0)."""
    step = math.pi / n
    near = [(0.0, step * 2.0 ** -40)] + [(step * 2.0 ** -k, step * 2.0 ** (1 - k))
                                          for k in range(40, 0, -1)]
    return near + [(i * step, math.pi if i == n - 1 else (i + 1) * step) for i in range(1, n)]


#: Version 4's subdivisions of [0, pi] (gaps and counts): a piece [a, b] with
#: 0 < a and b > GEOMETRIC a is halved at its geometric mean, so the pieces near
#: theta = 0, where a fast-sampled loop's poles crowd z = 1, shrink geometrically only
#: as far as needed (the start pieces no longer carry the fixed ladder of 40). Where
#: to cut, not a tolerance: the checker replays every cut.
GEOMETRIC = 4


def subdivision_start(v4: bool) -> list[tuple[float, float]]:
    """The pieces of [0, pi] a subdivision starts from: version 4 (``v4``),
    [0, pi/n 2^-40], [pi/n 2^-40, pi/n] and the other n - 1 equal pieces; before,
    :func:`start_pieces` (the first cut again at pi/n 2^-k, k = 1..40)."""
    if not v4:
        return start_pieces()
    step = math.pi / START_PIECES
    return [(0.0, step * 2.0 ** -40), (step * 2.0 ** -40, step), *start_pieces()[41:]]


def split_theta(a: float, b: float, v4: bool) -> float:
    """Where a piece [a, b] of angles is halved (:data:`GEOMETRIC`; before version 4
    the midpoint)."""
    return math.sqrt(a * b) if v4 and a > 0 and b > GEOMETRIC * a else 0.5 * (a + b)


def _point(al: ArbLoop, t: float, K: Any, cache: dict) -> tuple[Any, Any, Any]:
    """P, Q (at K) and w at the exact angle t (cached)."""
    if t not in cache:
        P, Q, w = al.parts(theta_ball(t, t))
        with working_precision(al.prec):
            cache[t] = (poly_k(P, K), poly_k(Q, K), w)
    return cache[t]


def piece_increment(al: ArbLoop, a: float, b: float, K: Any, cache: dict,
                    polys: bool = True) -> tuple[str | None, Any]:
    """The increment of arg det M over [a, b] at K, and how it is proved.

    ``"P"``: |P| > |Q| on the piece, arg det M = arg P + arg(1 + w Q / P) with the
    second term in (-pi/2, pi/2); ``"Q"``: |Q| > |P|, arg det M = arg Q - n theta +
    arg(1 + P / (w Q)); ``"F"``: the ball of det M excludes 0. Each principal value is
    the true increment because the function stays in a convex ball excluding 0 (or in
    the right half-plane). None: no proof on this piece. ``polys``: the balls from the
    kernel of ball polynomials (certificate version 4), else forward-mode derivatives.
    """
    with working_precision(al.prec):       # the ball as the exclusion forms it: one kernel
        Pv, Qv, Fv = al.box(theta_ball(a, b), K, key=(a, b), polys=polys)
        Pa, Qa, wa = _point(al, a, K, cache)
        Pb, Qb, wb = _point(al, b, K, cache)
        if Pv.abs_lower() > Qv.abs_upper():
            return "P", ((Pb / Pa).arg() + (1 + wb * Qb / Pb).arg() - (1 + wa * Qa / Pa).arg())
        if Qv.abs_lower() > Pv.abs_upper():
            dth = theta_ball(b, b) - theta_ball(a, a)
            return "Q", ((Qb / Qa).arg() - al.n_phase * dth
                         + (1 + Pb / (wb * Qb)).arg() - (1 + Pa / (wa * Qa)).arg())
        if not Fv.contains(0):
            Fa, Fb = Pa + wa * Qa, Pb + wb * Qb
            return "F", (Fb / Fa).arg()
    return None, None


@dataclass
class Count:
    """Poles outside at K (None: not proved), with the pieces of [0, pi] used
    (``method`` "winding") or none (``method`` "roots": :func:`root_count`)."""
    K: float
    outside: int | None
    pieces: list[tuple[float, float, str]] = field(default_factory=list)
    method: str = "winding"


def root_count(al: ArbLoop, K: float) -> int | None:
    """Poles outside the unit circle at stiffness K by isolating every root of the
    characteristic polynomial (:meth:`~hapstab.engine.arb_loop.ArbLoop.polynomial`).

    The exact zero coefficients at the bottom are divided out (roots at z = 0, inside).
    Arb's ``acb_poly.roots`` returns pairwise disjoint balls, each containing exactly one
    root of every polynomial within the coefficient balls (the inclusion disc of radius
    deg |p(m) / p'(m)| about each approximation holds a root; disjoint discs, as many as
    the degree, hold one each). The count is proved when every ball lies strictly inside
    or strictly outside |z| = 1.

    Parameters
    ----------
    al : ArbLoop
    K : float
        Stiffness (N/m).

    Returns
    -------
    int or None
        The number of poles outside; None when Arb cannot isolate the roots (a multiple
        or nearly multiple root) or a ball meets the circle.

    References
    ----------
    F. Johansson, "Arb: efficient arbitrary-precision midpoint-radius interval
    arithmetic", IEEE Trans. Computers 66 (2017) 1281-1292 (``acb_poly_find_roots``,
    ``acb_poly_validate_roots``); P. Henrici, *Applied and Computational Complex
    Analysis*, vol. 1, Wiley 1974, sec. 6.4 (root inclusion).
    """
    import flint
    acb_poly = flint.acb_poly
    with working_precision(al.prec):
        p = al.polynomial(K)
        low = 0
        while low < p.degree() and p[low].is_zero():
            low += 1
        q = acb_poly([p[i] for i in range(low, p.degree() + 1)])
        if q.degree() < 1:
            return 0
        for tol in ROOT_TOLERANCES:
            try:
                roots = q.roots(tol=tol, maxprec=ROOTS_MAX_PREC_FACTOR * al.prec)
            except ValueError:          # not isolated (a nearly multiple root), or not
                continue                # to these radii: the next tolerance, else None
            if len(roots) != q.degree():
                continue
            out = sum(1 for r in roots if r.abs_lower() > 1)
            inside = sum(1 for r in roots if r.abs_upper() < 1)
            if out + inside == len(roots):
                return out
    return None


def count(al: ArbLoop, K: float, max_pieces: int = MAX_PIECES, roots: bool = True,
          polys: bool = True) -> Count:
    """Poles of the closed loop outside the unit circle at stiffness K: by root
    isolation (:func:`root_count`) up to :data:`ROOTS_MAX_DEGREE`, else (or when it
    cannot decide) by the argument principle in balls (module doc, 3).

    Parameters
    ----------
    al : ArbLoop
    K : float
        Stiffness (N/m).
    max_pieces : int
        Safety valve on the number of pieces tried.
    roots : bool
        Try root isolation first (default; False: the argument principle alone).
    polys : bool
        The pieces' balls from the kernel of ball polynomials (certificate version 4;
        :meth:`~hapstab.engine.arb_loop.ArbLoop.kernel`), else forward-mode derivatives.

    Returns
    -------
    Count
        ``outside`` None when a piece at the floor keeps 0 in its ball (a pole on
        or within the balls' width of the circle) or the valve closed.
    """
    if roots and al.degree <= ROOTS_MAX_DEGREE:
        got = root_count(al, K)
        if got is not None:
            return Count(K, got, [], "roots")
    res = _winding_count(al, K, max_pieces, polys)
    if res.outside is None and roots and ROOTS_MAX_DEGREE < al.degree <= ROOTS_FALLBACK_DEGREE:
        # the argument principle could not decide (a pole within the pieces' reach of
        # the circle): the roots may, at a degree higher than is worth trying first
        got = root_count(al, K)
        if got is not None:
            return Count(K, got, [], "roots")
    return res


def _winding_count(al: ArbLoop, K: float, max_pieces: int, polys: bool) -> Count:
    """:func:`count` by the argument principle alone."""
    import flint
    arb = flint.arb
    Kb = arb(K)
    cache: dict = {}
    res = Count(K, None)
    stack = subdivision_start(polys)[::-1]       # version 4's with its kernel
    total = arb(0)
    tried = 0
    while stack:
        a, b = stack.pop()
        tried += 1
        if tried > max_pieces:
            return res
        how, inc = piece_increment(al, a, b, Kb, cache, polys)
        if how is not None:
            res.pieces.append((a, b, how))
            with working_precision(al.prec):
                total = total + inc
            continue
        if (b - a) <= FLOOR * b:
            return res
        m = split_theta(a, b, polys)
        stack += [(m, b), (a, m)]
    with working_precision(al.prec):
        turns = (total / arb.pi()).unique_fmpz()
    if turns is not None:
        res.outside = al.q - int(turns)
    return res
