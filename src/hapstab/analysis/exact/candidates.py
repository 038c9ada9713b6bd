"""Candidate crossings from a vectorised angle grid: the fast proposer for the ball
proof (:mod:`~hapstab.analysis.exact.proof`), in place of the certified float search
(:mod:`~hapstab.analysis.exact.crossings`) when a proof follows.

A pole is on the unit circle at (theta, K) where det M(e^{j theta}, K) = c_0 + u c_1
+ u^2 c_2 = 0 with u = K / scale real. On a grid of angles
(:mod:`~hapstab.analysis.exact.angle_grid`: uniform, about 2 pi / 16 of a turn of the
delay's phase between points, geometric below the first -- the low-frequency
crossings of fast-sampled loops -- and halved where a coefficient turns fast, at
lightly damped resonances, and where a branch may cross the axis unseen) the roots
u(theta) of det M = 0
are followed branch by branch: one port, u = -c_0 / c_1; two ports, the two roots of
the quadratic, matched between neighbours by continuity (the two ports of a
symmetric teleoperator cross at nearly the same angle on different branches, 1e-8
rad apart, which one condition for both -- the resultant -- cannot tell apart on a
grid). A crossing is where a branch's imaginary part changes sign.

Each bracket's crossing is refined by Newton's method on (Re, Im) det M = 0 in
(theta, u); the real crossings through z = +-1 are the positive real roots of the real
polynomial at theta = 0 and pi. The direction is the sign of Im(F_u / F_theta), as in
the certified search.

Nothing here is a proof: the proof polishes each candidate in balls, excludes every
other (theta, K) box of each gap it claims stable and counts the poles outside there.
A crossing this grid misses below K_max, or at the end of a stable interval, leaves a
box the exclusion cannot clear (reported uncertain) or a count that disagrees with
the candidates' (see :func:`consistent`); a single crossing missed anywhere shifts
the counts of every gap above it, which the grid's own argument principle compares
(:func:`_counts_agree`). :func:`~hapstab.analysis.exact.crossings.analyse` then runs
the certified float search instead (with every interval: the cross-check counts the
gaps of :func:`_checked_gaps`, and not those both counts put 4 or more poles outside).
What no count sees is a *pair* missed inside a gap counted unstable (a branch leaving
the real axis's far side and coming back between two grid points: a stable window of K
between them); K_max and every reported interval stay proved, but the window would be
missing. So the grid is also halved where a branch's cubic interpolant (values and
slopes) may cross the axis twice or comes near it, and where a crossing's bracket is a
stride of more than a quarter of the branch's size
(:func:`~hapstab.analysis.exact.angle_grid.dips`; with every interval only): a
heuristic, not a proof. On 5,674 campaign loops of seven seeds, among them the two that
found hidden windows, it leaves none missed.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from hapstab.analysis.exact.angle_grid import (
    MAX_TURN,
    REFINE_ROUNDS,
    branches,
    coefficients,
    dip_refined,
    grid,
    halve,
    refined,
)
from hapstab.analysis.exact.boxes import U_HI, U_LO
from hapstab.analysis.exact.counts import item_stable_set
from hapstab.analysis.exact.stable_set import StableSet
from hapstab.engine.frequency import LoopResponse
from hapstab.errors import AnalysisError

__all__ = ["candidate_set", "consistent", "half_turns", "NEWTON_STEPS"]

#: Newton steps on a bracket's crossing: from the grid's linear interpolation the
#: error is ~1e-3 relative; five steps bring it to rounding, and the ball proof's own
#: Newton polishes it further (a candidate is a starting point, not an answer).
NEWTON_STEPS = 5
#: A Newton step this small relative to its point ends the steps: at a simple crossing
#: the next would be ~1e-24 (quadratic convergence), below rounding; at a multiple one
#: the point is still within ~1e-12, far inside SAME, and the ball proof polishes it.
CONVERGED = 1e-12
#: Candidates this close (relative, in u and theta) are one: Newton's steps from two
#: brackets of the same crossing end ~1e-12 apart; two true crossings this close are
#: the proof's to separate (it falls back if it cannot).
SAME = 1e-9
#: Candidates this close are taken as one crossing found twice when, kept apart, the
#: counts disagree with the grid's (:func:`_counts_agree`, which then decides again):
#: where the quadratic's two branches nearly meet, Newton's method converges linearly
#: and two brackets of one crossing end ~1e-9 apart (measured: 2e-9 in u and theta in
#: the teleoperation example's K-B region, rows B = 1.5-6.8); a true pair this close
#: with one direction merged by it leaves the counts off by two above it: refused too.
NEAR = 1e-6
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


def _newton(resp: LoopResponse, i: int, th: np.ndarray, u: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton's method on (Re, Im) det M = 0 in (theta, u), vectorised; returns theta,
    u and the direction sign of Im(F_u / F_theta)."""
    for _ in range(NEWTON_STEPS):
        c, d = coefficients(resp, i, th)
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
    c, d = coefficients(resp, i, th)
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
    return coefficients(resp, i, np.array([0.0, math.pi]))


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


def _merge_close(cross: list[tuple], same: float = SAME) -> list[tuple]:
    """Candidates (u, theta, direction, multiplicity) within ``same`` (relative) of the
    one before them, in u and theta and with its direction, dropped."""
    out: list[tuple] = []
    for cr in sorted(cross):
        if out and abs(cr[0] - out[-1][0]) <= same * cr[0] and \
                abs(cr[1] - out[-1][1]) <= same * (1.0 + cr[1]) and cr[2] == out[-1][2]:
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
    th, c, *d = refined(resp, i, grid(resp), deriv=full)
    quad = bool(np.any(c[2] != 0))
    if full:
        # every crossing: also where a branch may cross the axis twice unseen (a pair
        # missed above K_max would drop a stable window; below it, the proof sees it)
        th, c = dip_refined(resp, i, th, c, d[0], quad)
    th0, u0 = [], []
    for br in branches(c, quad):
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
    cross += _real_crossings(ends, quad)
    anchor = _anchor(resp, ends, c)
    if anchor < 0:
        return None
    tried: list = []
    for same in (SAME, NEAR):
        merged = _merge_close(cross, same)
        if merged in tried:
            break
        tried.append(merged)
        try:
            ss = item_stable_set(resp, i, anchor, merged, [], full, None, False)
        except AnalysisError:
            return None
        if not full or _counts_agree(resp, i, th, c, ss, ends[0]):
            return ss
    return None


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
    more than :data:`~hapstab.analysis.exact.angle_grid.MAX_TURN` for any of them (at most
    :data:`~hapstab.analysis.exact.angle_grid.REFINE_ROUNDS` times)."""
    U = u[:, None]
    for _ in range(REFINE_ROUNDS):
        F = c[0] + U * (c[1] + U * c[2])
        with np.errstate(all="ignore"):
            j = np.flatnonzero(np.any(np.abs(np.angle(F[:, 1:] / F[:, :-1])) > MAX_TURN, axis=0))
        if not j.size or th.size + j.size > MAX_CHECK // max(1, u.size):
            break
        th, c = halve(resp, i, th, c, j)
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
