"""Candidate crossings from a vectorised angle grid: the fast proposer for the ball
proof (:mod:`~hapstab.analysis.exact.proof`), in place of the certified float search
(:mod:`~hapstab.analysis.exact.crossings`) when a proof follows.

A pole is on the unit circle at (theta, K) where det M(e^{j theta}, K) = c_0 + u c_1
+ u^2 c_2 = 0 with u = K / scale real. On a grid of angles (uniform with
:data:`POINTS_PER_RATE` points per unit of the phase rate, i.e. about 2 pi / 16 of a
turn of the delay's phase between points, :data:`LOW_POINTS` geometric points below
the first -- the low-frequency crossings of fast-sampled loops -- and halved where a
coefficient turns fast, at lightly damped resonances) the roots u(theta) of det M = 0
are followed branch by branch: one port, u = -c_0 / c_1; two ports, the two roots of
the quadratic, matched between neighbours by continuity (the two ports of a
symmetric teleoperator cross at nearly the same angle on different branches, 1e-8
rad apart, which one condition for both -- the resultant -- cannot tell apart on a
grid). A crossing is where a branch's imaginary part changes sign.

Each bracket's crossing is refined by Newton's method on (Re, Im) det M = 0 in
(theta, u); the real crossings through z = +-1 are the positive real roots of the real
polynomial at theta = 0 and pi. The direction is the sign of Im(F_u / F_theta), as in
the certified search.

Nothing here is a proof, and nothing needs to be: the proof polishes each candidate
in balls, excludes every other (theta, K) box and counts the poles outside in every
gap it claims. A crossing this grid misses leaves a box the exclusion cannot clear
(reported uncertain) or a count that disagrees with the candidates' (see
:func:`consistent`); :func:`~hapstab.analysis.exact.crossings.analyse` then runs the
certified float search instead, so the answer never depends on the grid.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from hapstab.analysis.exact.boxes import U_HI, U_LO
from hapstab.analysis.exact.counts import item_stable_set
from hapstab.analysis.exact.stable_set import StableSet
from hapstab.engine.frequency import LoopResponse
from hapstab.errors import AnalysisError

__all__ = ["candidate_set", "consistent", "POINTS_PER_RATE", "LOW_POINTS", "NEWTON_STEPS"]

#: Uniform grid points over [0, pi] per unit of the loop's phase rate (oscillations of
#: det M over [0, pi]): 16 put 2 pi / 16 of the phase between points, where the
#: crossing condition changes sign at most once (the expert method's 32 per turn).
POINTS_PER_RATE = 16
#: Fewest uniform points (short delays: the plant's resonances still need a grid).
MIN_POINTS = 1024
#: Geometric points from THETA_LOW up to the first uniform point: fast-sampled heavy
#: loops cross at theta ~ omega T down to ~1e-9 rad.
LOW_POINTS = 120
#: the lowest angle of that geometric grid, three decades below the lowest crossing seen
THETA_LOW = 1e-12
#: Newton steps on a bracket's crossing: from the grid's linear interpolation the
#: error is ~1e-3 relative; five steps bring it to rounding, and the ball proof's own
#: Newton polishes it further (a candidate is a starting point, not an answer).
NEWTON_STEPS = 5
#: A Newton step this small relative to its point ends the steps: at a simple crossing
#: the next would be ~1e-24 (quadratic convergence), below rounding; at a multiple one
#: the point is still within ~1e-12, far inside SAME, and the ball proof polishes it.
CONVERGED = 1e-12
#: Largest turn of a coefficient's argument between grid neighbours (rad) before the
#: interval is halved, and the most halvings: pi/8 keeps the crossing condition and
#: the winding resolved; 20 halvings reach 1e-6 of the uniform spacing (a resonance
#: narrower than that, damping ratio below ~1e-8, is left to the fallback).
MAX_TURN = math.pi / 8
REFINE_ROUNDS = 20
#: Levels of halves below a halved interval whose midpoints are evaluated with it (a
#: resonance is halved over several rounds: 2 levels, 7 points, serve 3 rounds with one
#: evaluation, whose cost is its call's, not its points'); not a tolerance.
LOOKAHEAD = 2
#: Candidates this close (relative, in u and theta) are one: Newton's steps from two
#: brackets of the same crossing end ~1e-12 apart; two true crossings this close are
#: the proof's to separate (it falls back if it cannot).
SAME = 1e-9
#: Most grid evaluations (gaps x angles) the counts' cross-check takes
#: (:func:`_counts_agree`: a 10^3-sample delay's thousand gaps on 3e4 angles would
#: cost seconds); beyond it a subset of the gaps is counted (:func:`_checked_gaps`).
MAX_CHECK = 1_000_000
#: Poles outside from which a gap is taken as unstable even where the two float
#: counts (the crossings' directions, the refined grid's winding) disagree: far above
#: K_max, where u^2 c_2's zeros turn det M faster than any grid (measured: counts of
#: 192-201 off by 2-6 at K ~ 1e7 on the paper's PEB, delay 100).
FAR_UNSTABLE = 4
#: A candidate's |det M| relative to the sum of its terms' moduli after the steps:
#: converged ones reach ~1e-16 (rounding); 1e-8 drops the brackets Newton's method
#: leaves (measured: 0.3-0.5 for the resultant's spurious brackets of a PEB), and a
#: genuine crossing dropped by it is caught by the proof (see the module doc).
RESIDUAL = 1e-8


def _grid(resp: LoopResponse) -> np.ndarray:
    """The angles (rad/sample), increasing, inside (0, pi)."""
    m = max(MIN_POINTS, POINTS_PER_RATE * resp.phase_rate)
    uniform = np.linspace(0.0, math.pi, m + 1)[1:-1]
    low = np.geomspace(THETA_LOW, uniform[0], LOW_POINTS, endpoint=False)
    return np.concatenate([low, uniform])


def _refined(resp: LoopResponse, i: int, th: np.ndarray) -> tuple[np.ndarray, list]:
    """The grid, halved where the argument of c_0 or c_1 turns by more than
    :data:`MAX_TURN` between neighbours (a lightly damped resonance turns by pi over
    its width, far below the uniform spacing), and the coefficients on it. Not c_2: a
    two-port loop's is N_0 N_1 (1 - z^-n) k_0 k_1, with exact zeros on the circle
    across which its argument jumps by pi however fine the grid."""
    c, _ = _coef(resp, i, th, False)
    ahead: dict[float, tuple] = {}
    for _ in range(REFINE_ROUNDS):
        with np.errstate(all="ignore"):
            turn = np.zeros(th.size - 1)
            for x in c[:2]:
                if np.any(x != 0):
                    turn = np.maximum(turn, np.abs(np.angle(x[1:] / x[:-1])))
        j = np.flatnonzero(turn > MAX_TURN)
        if not j.size:
            break
        th, c = _halve(resp, i, th, c, j, ahead)
    return th, c


def _ahead(resp: LoopResponse, i: int, lo: np.ndarray, hi: np.ndarray, ahead: dict) -> list:
    """c_0..c_2 at the midpoints of [lo, hi], from ``ahead`` (angle: values) where it
    has them; the others are evaluated with the midpoints of the :data:`LOOKAHEAD`
    levels of halves below theirs, kept in ``ahead`` for the rounds that halve those
    (one evaluation for several rounds; the same angles, formed as the rounds form
    them, and the same values: the grid is the one the rounds alone make)."""
    mid = 0.5 * (lo + hi)
    miss = np.array([t not in ahead for t in mid.tolist()], bool)
    if miss.any():
        pts, ivs = [mid[miss]], [(lo[miss], mid[miss]), (mid[miss], hi[miss])]
        for _ in range(LOOKAHEAD):
            nxt = []
            for a, b in ivs:
                m = 0.5 * (a + b)
                pts.append(m)
                nxt += [(a, m), (m, b)]
            ivs = nxt
        allp = np.concatenate(pts)
        got, _ = _coef(resp, i, allp, False)
        ahead.update(zip(allp.tolist(), zip(*(g.tolist() for g in got), strict=True),
                         strict=True))
    vals = [ahead[t] for t in mid.tolist()]
    return [np.array([v[q] for v in vals], complex) for q in range(3)]


def _halve(resp: LoopResponse, i: int, th: np.ndarray, c: list, j: np.ndarray,
           ahead: dict | None = None) -> tuple[np.ndarray, list]:
    """The grid with the midpoints of intervals ``j`` inserted, and c_0..c_2 on it
    (``ahead``: see :func:`_ahead`)."""
    mid = 0.5 * (th[j] + th[j + 1])
    cm = _coef(resp, i, mid, False)[0] if ahead is None else _ahead(resp, i, th[j], th[j + 1], ahead)
    order = np.argsort(np.concatenate([th, mid]), kind="stable")
    return (np.concatenate([th, mid])[order],
            [np.concatenate([x, y])[order] for x, y in zip(c, cm, strict=True)])


def _coef(resp: LoopResponse, i: int, th: np.ndarray, deriv: bool = True
          ) -> tuple[list, list]:
    """c_0..c_2 and their d/dtheta at the angles (complex arrays; the jets' centres
    alone: a proposer needs no enclosures); ``deriv`` False: the values alone (the
    derivatives :data:`~hapstab.engine.discs.NO_DERIV`, the values the same)."""
    F = resp.coefficients(np.full(th.size, i), th, np.zeros(th.size), values_only=True,
                          deriv=deriv)
    return [f.vc for f in F], [f.dc for f in F]


def _branches(c: list, quad: bool) -> list[np.ndarray]:
    """The roots u(theta) of det M = 0, one array per branch, followed by continuity
    (module doc): a crossing is where a branch's imaginary part changes sign."""
    with np.errstate(all="ignore"):
        if not quad:
            return [-c[0] / c[1]]
        sq = np.sqrt(c[1] * c[1] - 4 * c[0] * c[2])
        sq = np.where((np.conj(c[1]) * sq).real >= 0, sq, -sq)
        q = -0.5 * (c[1] + sq)
        r = [q / c[2], c[0] / q]          # the stable pair of the quadratic formula
        rel = lambda x, y: np.abs(x - y) / (np.abs(x) + np.abs(y) + 1e-300)  # noqa: E731
        same = rel(r[0][1:], r[0][:-1]) + rel(r[1][1:], r[1][:-1])
        cross = rel(r[0][1:], r[1][:-1]) + rel(r[1][1:], r[0][:-1])
        swap = np.concatenate([[0], np.cumsum(np.nan_to_num(cross) < np.nan_to_num(same)) % 2])
        return [np.where(swap == 0, r[0], r[1]), np.where(swap == 0, r[1], r[0])]


def _newton(resp: LoopResponse, i: int, th: np.ndarray, u: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton's method on (Re, Im) det M = 0 in (theta, u), vectorised; returns theta,
    u and the direction sign of Im(F_u / F_theta)."""
    for _ in range(NEWTON_STEPS):
        c, d = _coef(resp, i, th)
        F = c[0] + u * (c[1] + u * c[2])
        Ft = d[0] + u * (d[1] + u * d[2])
        Fu = c[1] + 2 * u * c[2]
        with np.errstate(all="ignore"):
            det = Ft.real * Fu.imag - Ft.imag * Fu.real
            dth = -(F.real * Fu.imag - F.imag * Fu.real) / det
            du = -(Ft.real * F.imag - Ft.imag * F.real) / det
        ok = np.isfinite(dth) & np.isfinite(du)
        th = np.where(ok, th + dth, th)
        u = np.where(ok, u + du, u)
        # every step within CONVERGED of its point: the steps left would move it by
        # rounding (a candidate only places the proof's Newton)
        if np.all(~ok | ((np.abs(dth) <= CONVERGED * np.abs(th))
                         & (np.abs(du) <= CONVERGED * np.abs(u)))):
            break
    c, d = _coef(resp, i, th)
    Ft = d[0] + u * (d[1] + u * d[2])
    Fu = c[1] + 2 * u * c[2]
    F = c[0] + u * (c[1] + u * c[2])
    size = np.abs(c[0]) + np.abs(u * c[1]) + np.abs(u * u * c[2])
    with np.errstate(all="ignore"):
        s = np.sign((Fu / Ft).imag)
        # converged: det M cancels to RESIDUAL of its terms' size (a bracket of the
        # resultant whose Newton steps wander off is no candidate)
        return th, u, np.where(np.abs(F) <= RESIDUAL * size, s, 0.0)


def _ends(resp: LoopResponse, i: int) -> tuple[list, list]:
    """c_0..c_2 and their d/dtheta at theta = 0 and pi (one evaluation for
    :func:`_real_crossings` and :func:`_anchor`)."""
    return _coef(resp, i, np.array([0.0, math.pi]))


def _real_crossings(ends: tuple[list, list], quad: bool) -> list[tuple]:
    """Crossings through z = +1 (theta = 0) and z = -1 (theta = pi): positive real
    roots u of the real polynomial det M there (``ends``: :func:`_ends`)."""
    out = []
    for k, t in enumerate((0.0, math.pi)):
        c, d = [x[k:k + 1] for x in ends[0]], [x[k:k + 1] for x in ends[1]]
        coef = [x[0].real for x in c]
        roots: Any = np.roots(coef[::-1] if quad else coef[1::-1]) if any(coef[1:]) else []
        for r in roots:
            # a root with an imaginary part above 1e-9 of its size is a complex pair, not a
            # real K; a candidate only proposes: a crossing dropped here (a near-double root
            # split by rounding) shows in the grid's counts, and the certified search takes over
            if abs(r.imag) > 1e-9 * abs(r) or not (U_LO < r.real < U_HI):
                continue
            u = float(r.real)
            Fu = c[1][0] + 2 * u * c[2][0]
            Ft = d[0][0] + u * (d[1][0] + u * d[2][0])
            with np.errstate(all="ignore"):
                s = np.sign((Fu / Ft).imag)
            if np.isfinite(s) and s != 0:
                out.append((u, t, int(s), 1))
    return out


def _merge_close(cross: list[tuple]) -> list[tuple]:
    """Candidates (u, theta, direction, multiplicity) within :data:`SAME` of the one
    before them, in u and theta, dropped."""
    out: list[tuple] = []
    for cr in sorted(cross):
        if out and abs(cr[0] - out[-1][0]) <= SAME * cr[0] and \
                abs(cr[1] - out[-1][1]) <= SAME * (1.0 + cr[1]) and cr[2] == out[-1][2]:
            continue
        out.append(cr)
    return out


def _anchor(resp: LoopResponse, ends: tuple[list, list], c: list) -> int:
    """Poles outside at u = U_LO by the argument principle on the grid (and its ends
    0 and pi, ``ends``: :func:`_ends`): Z_out = q - wind(det M), the winding over
    [0, pi] in half turns. A proposal like the rest (the proof counts in balls); -1 if
    not a whole number."""
    e = ends[0]
    ends = e[0] + U_LO * (e[1] + U_LO * e[2])
    mid = c[0] + U_LO * (c[1] + U_LO * c[2])
    vals = np.concatenate([ends[:1], mid, ends[1:]])
    with np.errstate(all="ignore"):
        turns = float(np.sum(np.angle(vals[1:] / vals[:-1]))) / math.pi
    # whole up to rounding where the grid resolves det M's argument; 1e-6 off: it does not
    if not math.isfinite(turns) or abs(turns - round(turns)) > 1e-6:
        return -1
    return resp.q - round(turns)


def candidate_set(resp: LoopResponse, i: int, full: bool) -> StableSet | None:
    """Item ``i``'s float stable set from the grid's candidates (module doc), the form
    the ball proof starts from; None when the candidates are inconsistent (a count
    below zero, a first crossing inwards): the certified float search then proposes.

    Parameters
    ----------
    resp : LoopResponse
    i : int
        The item.
    full : bool
        Every stable interval, or K_max alone.

    Returns
    -------
    StableSet or None
    """
    th, c = _refined(resp, i, _grid(resp))
    quad = bool(np.any(c[2] != 0))
    th0, u0 = [], []
    for br in _branches(c, quad):
        g, u = br.imag, br.real
        ok = np.isfinite(g) & np.isfinite(u)
        s = np.sign(np.where(ok, g, 0.0))
        j = np.flatnonzero((s[:-1] * s[1:] < 0) & ok[:-1] & ok[1:])
        t = g[j] / (g[j] - g[j + 1])              # linear interpolation inside the bracket
        th0.append(th[j] + t * (th[j + 1] - th[j]))
        u0.append(np.where(np.abs(u[j] - u[j + 1]) < 0.5 * np.abs(u[j]),
                           u[j] + t * (u[j + 1] - u[j]), u[j]))
    tn, un, dn = _newton(resp, i, np.concatenate(th0), np.concatenate(u0))
    keep = np.isfinite(tn) & np.isfinite(un) & (un > U_LO) & (un < U_HI) & (dn != 0) & \
        (tn > 0) & (tn < math.pi)
    cross = [(float(a), float(b), int(d), 2) for a, b, d in zip(un[keep], tn[keep], dn[keep],
                                                                strict=True)]
    ends = _ends(resp, i)
    cross = _merge_close(cross + _real_crossings(ends, quad))
    anchor = _anchor(resp, ends, c)
    if anchor < 0:
        return None
    try:
        ss = item_stable_set(resp, i, anchor, cross, [], full, None, False)
    except AnalysisError:
        return None
    if full and not _counts_agree(resp, i, th, c, ss, ends[0]):
        return None
    return ss


def half_turns(vals: np.ndarray) -> np.ndarray:
    """Per row, the sum of the principal arguments of ``vals[k + 1] / vals[k]`` over pi
    (nan where a value is 0 or not finite), without an arctangent per step: it equals
    ``(arg(last) - arg(first)) / pi + 2 m``, m the net number of steps whose principal
    turn crosses the negative real axis (upwards -1, downwards +1): a step from the upper
    half-plane (imaginary part >= 0, arguments in [0, pi]) to the lower one turning
    counterclockwise (Im(b conj(a)) > 0) adds a turn. Steps exactly half a turn long
    (measure zero) are the only ones where the two sums can differ."""
    re, im = vals.real, vals.imag
    up = im >= 0
    # only the steps between the halves can cross the axis: few, taken sparsely
    r, c = np.nonzero(up[:, 1:] != up[:, :-1])
    with np.errstate(all="ignore"):
        s = re[r, c] * im[r, c + 1] - im[r, c] * re[r, c + 1]     # Im(b conj(a))
        d = up[r, c + 1].astype(int) - up[r, c]                    # +1 upwards, -1 down
        m = np.bincount(r, weights=np.where(d * s < 0, -d, 0), minlength=vals.shape[0])
        ends = np.angle(vals[:, [0, -1]])
        ends = np.where(ends == -math.pi, math.pi, ends)    # -0.0 imaginary: the upper half
        turns = (ends[:, 1] - ends[:, 0]) / math.pi + 2.0 * m
    ok = np.all(np.isfinite(vals) & (vals != 0), axis=1)
    return np.where(ok, turns, np.nan)


def _grid_counts(resp: LoopResponse, i: int, th: np.ndarray, c: list, u: np.ndarray,
                 e: list | None = None) -> np.ndarray:
    """Poles outside at each u by the argument principle on the grid (and its ends);
    -1 where the winding is not a whole number (the grid does not resolve it). ``e``:
    c_0..c_2 at theta = 0 and pi (:func:`_ends`), if formed already."""
    if e is None:
        e = _ends(resp, i)[0]
    U = u[:, None]
    vals = np.empty((u.size, th.size + 2), complex)
    vals[:, :1] = e[0][:1] + U * (e[1][:1] + U * e[2][:1])
    vals[:, -1:] = e[0][1:] + U * (e[1][1:] + U * e[2][1:])
    mid = vals[:, 1:-1]             # c_0 + U (c_1 + U c_2) in place (c_2 = 0: one port)
    if np.any(c[2] != 0):
        np.multiply(U, c[2], out=mid)
        mid += c[1]
        mid *= U
    else:
        np.multiply(U, c[1], out=mid)
    mid += c[0]
    turns = half_turns(vals)
    # a winding number is an integer: a sum of angles farther than 1e-6 turn from one
    # means the grid missed a fast phase change there (the gap is recounted, not trusted)
    whole = np.isfinite(turns) & (np.abs(turns - np.round(turns)) <= 1e-6)
    return np.where(whole, resp.q - np.round(np.where(whole, turns, 0)).astype(int), -1)


def _counts_agree(resp: LoopResponse, i: int, th: np.ndarray, c: list, ss: StableSet,
                  at_ends: list | None = None) -> bool:
    """Whether the counts the crossings' directions give in every gap (from the anchor)
    equal the grid's own argument principle at the gap's middle (refined for the
    gaps that disagree, :func:`_recount`). The proof examines only the gaps
    these counts call stable (beyond the first), so a crossing the grid missed must
    not go unnoticed here; a count that disagrees even there: False. ``at_ends``:
    c_0..c_2 at theta = 0 and pi (:func:`_ends`), if formed already."""
    s = float(resp.scale[i])
    ks = [e[0] / s for e in ss.events]
    edges = [U_LO, *ks, min(U_HI, 4 * ks[-1]) if ks else U_HI]
    mids = np.array([math.sqrt(a * b) for a, b in itertools.pairwise(edges)])
    counts = np.cumsum([ss.outside_small_K] + [int(e[3] * e[4]) for e in ss.events])
    pick = _checked_gaps(mids.size, th.size)
    got = _grid_counts(resp, i, th, c, mids[pick], at_ends)
    # a gap both counts put FAR_UNSTABLE or more poles outside is not one the proof
    # examines, whichever is right: two misses of one estimate could not make it stable
    far = (got >= FAR_UNSTABLE) & (counts[pick] >= FAR_UNSTABLE)
    bad = pick[(got != counts[pick]) & ~far]
    if not bad.size:
        return True
    # where u^2 c_2 dominates, its exact zeros on the circle (a two-port loop's
    # 1 - z^-n) turn det M faster than the grid resolves: those gaps are counted again
    # on a grid refined for det M at their own u
    return bool(np.array_equal(_recount(resp, i, th, c, mids[bad], at_ends), counts[bad]))


def _checked_gaps(n_gaps: int, n_angles: int) -> np.ndarray:
    """The gaps the cross-check counts: all when gaps x angles stay within
    :data:`MAX_CHECK`; else the lowest ones and evenly spaced others up to that cost
    (a missed crossing shifts every count above it, so spaced gaps still see it)."""
    most = max(2, MAX_CHECK // max(1, n_angles))
    if n_gaps <= most:
        return np.arange(n_gaps)
    low = np.arange(most // 2)
    return np.unique(np.concatenate([low, np.linspace(most // 2, n_gaps - 1,
                                                      most - most // 2).astype(int)]))


def _recount(resp: LoopResponse, i: int, th: np.ndarray, c: list, u: np.ndarray,
             e: list | None = None) -> np.ndarray:
    """The grid's counts at each u with the grid halved where det M(., u) turns by
    more than :data:`MAX_TURN` for any of them (at most :data:`REFINE_ROUNDS` times)."""
    U = u[:, None]
    for _ in range(REFINE_ROUNDS):
        F = c[0] + U * (c[1] + U * c[2])
        with np.errstate(all="ignore"):
            j = np.flatnonzero(np.any(np.abs(np.angle(F[:, 1:] / F[:, :-1])) > MAX_TURN, axis=0))
        if not j.size or th.size + j.size > MAX_CHECK // max(1, u.size):
            break
        th, c = _halve(resp, i, th, c, j)
    return _grid_counts(resp, i, th, c, u, e)


def consistent(ss: StableSet, proved: StableSet) -> bool:
    """Whether the proof settled everything the candidates proposed: no range left
    uncertain, the count at K -> 0+ proved, and every gap the proof counted agreeing
    with the candidates' stable set (a missed crossing shows up in one of these)."""
    pr = proved.proof
    if pr is None or pr.base_outside is None or proved.uncertain:
        return False
    if pr.base_outside != ss.outside_small_K:
        return False
    ends = [e for iv in ss.intervals for e in iv]
    for g in pr.gaps:
        if g.counted is None or g.counted.outside is None:
            continue
        K = g.counted.K
        # a count within 1e-6 of a candidate interval's end is on the crossing's far
        # side of the proof's window, which the candidate K (a float Newton's, good to
        # ~1e-11 at long delays) may overshoot: nothing to compare there
        if any(abs(K - e) <= 1e-6 * e for e in ends):
            continue
        float_stable = any(a <= K <= b for a, b in ss.intervals)
        if float_stable != (g.counted.outside == 0):
            return False
    return True
