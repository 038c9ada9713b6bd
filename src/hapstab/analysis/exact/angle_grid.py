"""The angle grid on which :mod:`~hapstab.analysis.exact.candidates` proposes the
crossings: the angles (uniform in the delay's phase, geometric below the first point),
halved where a coefficient of det M = c_0 + u c_1 + u^2 c_2 turns fast (a lightly
damped resonance) and where a branch u(theta) of det M = 0 may cross the real axis
more often than the grid's signs show (:func:`dips`), and c_0..c_2 on it. Nothing here
is a proof: see that module's notes for what the proof checks of what the grid proposes.
"""

from __future__ import annotations

import math

import numpy as np

from hapstab.analysis.exact.boxes import U_HI
from hapstab.engine.frequency import LoopResponse

__all__ = ["grid", "refined", "dip_refined", "dips", "halve", "evaluate_ahead", "coefficients",
           "branches", "inserted", "POINTS_PER_RATE", "MIN_POINTS", "LOW_POINTS", "THETA_LOW", "MAX_TURN",
           "REFINE_ROUNDS", "DIP_ROUNDS", "DIP", "STEP", "NOISE", "LOOKAHEAD"]

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
#: Largest turn of a coefficient's argument between grid neighbours (rad) before the
#: interval is halved, and the most halvings: pi/8 keeps the crossing condition and
#: the winding resolved; 20 halvings reach 1e-6 of the uniform spacing (a resonance
#: narrower than that, damping ratio below ~1e-8, is left to the fallback).
MAX_TURN = math.pi / 8
REFINE_ROUNDS = 20
#: Rounds of halving where a branch may dip across the real axis between two grid
#: points (:func:`dips`); each round one evaluation of the few intervals flagged.
DIP_ROUNDS = 12
#: An interval is halved where the cubic through a branch's imaginary parts and slopes at
#: its ends comes nearer the real axis than this share of the nearer end (a dip towards
#: the axis: two crossings may hide between the points); a choice of where to look
#: harder, not a tolerance: the proof decides what the grid proposes.
DIP = 0.5
#: ... and a bracket (one sign change) where the branch moves by more than this share of
#: its modulus between the two points (the grid does not resolve it there: a resonance
#: the coefficients' turns miss; Newton's start from the bracket is then poor)
STEP = 0.25
#: Im u within this share of |u| at both ends of an interval is rounding (c_0..c_2 are
#: formed to ~1e-15 relative; 1e-13 leaves a hundredfold for their cancellation in the
#: quadratic's roots): a branch lying on the axis there, whose signs no halving resolves.
NOISE = 1e-13
#: Levels of halves below a halved interval whose midpoints are evaluated with it (a
#: resonance is halved over several rounds: 2 levels, 7 points, serve 3 rounds with one
#: evaluation, whose cost is its call's, not its points'); not a tolerance.
LOOKAHEAD = 2


def grid(resp: LoopResponse) -> np.ndarray:
    """The angles (rad/sample), increasing, inside (0, pi)."""
    m = max(MIN_POINTS, POINTS_PER_RATE * resp.phase_rate)
    uniform = np.linspace(0.0, math.pi, m + 1)[1:-1]
    low = np.geomspace(THETA_LOW, uniform[0], LOW_POINTS, endpoint=False)
    return np.concatenate([low, uniform])


def refined(resp: LoopResponse, i: int, th: np.ndarray, deriv: bool = False) -> tuple:
    """The grid, halved where the argument of c_0 or c_1 turns by more than
    :data:`MAX_TURN` between neighbours (a lightly damped resonance turns by pi over
    its width, far below the uniform spacing), and the coefficients on it. Not c_2: a
    two-port loop's is N_0 N_1 (1 - z^-n) k_0 k_1, with exact zeros on the circle
    across which its argument jumps by pi however fine the grid. ``deriv``: their
    d/dtheta too, ``(th, c, d)`` (the first grid's with its values, the points added
    in one more evaluation: the values are the same either way)."""
    th0 = th
    c, d0 = coefficients(resp, i, th, deriv)
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
        th, c = halve(resp, i, th, c, j, ahead)
    if not deriv:
        return th, c
    new = ~np.isin(th, th0)         # th0's points keep their order among the others
    d = [np.empty(th.size, complex) for _ in d0]
    dn = coefficients(resp, i, th[new])[1] if new.any() else [x[:0] for x in d0]
    for x, a, b in zip(d, d0, dn, strict=True):
        x[~new], x[new] = a, b
    return th, c, d


def dips(th: np.ndarray, c: list, d: list, quad: bool) -> np.ndarray:
    """The grid intervals where a branch u(theta) of det M = 0 (:func:`branches`) may
    cross the real axis more often than its ends' signs show: the cubic through its
    imaginary parts and their slopes (u' = -(c_0' + u c_1' + u^2 c_2') / (c_1 + 2 u c_2)),
    sampled at t = 1/8 ... 7/8 of the interval, changes sign more than once, or, with the
    ends on one side, comes nearer the axis than :data:`DIP` of the nearer end; and the
    brackets (one sign change) whose stride is more than :data:`STEP` of the branch's
    size. Two crossings between two points (a branch touching the axis and leaving it, a
    stable window of K between two crossings) change no sign the grid sees, nor any
    count at a gap's middle. Only where the branch has Re u > 0 at an end, |u| below
    the search's top U_HI and Im u above :data:`NOISE` of |u|: a heuristic for where to
    look harder, not a proof (a pair between two samples of the cubic that stays above
    DIP there is not flagged)."""
    t = np.arange(1, 8) / 8.0
    H = np.stack([2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, 3 * t**2 - 2 * t**3, t**3 - t**2])
    h = np.diff(th)
    flag = np.zeros(th.size - 1, bool)
    with np.errstate(all="ignore"):
        for u in branches(c, quad):
            du = -(d[0] + u * (d[1] + u * d[2])) / (c[1] + 2 * u * c[2])
            f, g = u.imag, du.imag
            df, near = np.diff(f), np.minimum(np.abs(f[:-1]), np.abs(f[1:]))
            # the cubic is the chord plus t (1 - t) ((1 - t) a - t b), a and b the ends'
            # slopes' departures from the chord's: it departs by at most 1/4 max(|a|, |b|),
            # so with both ends on one side it comes within DIP of the nearer only if that
            # reaches (1 - DIP) of it; only those and the brackets are evaluated
            dev = 0.25 * np.maximum(np.abs(h * g[:-1] - df), np.abs(h * g[1:] - df))
            same = f[:-1] * f[1:] > 0
            size = np.maximum(np.abs(u[:-1]), np.abs(u[1:]))
            # only where a crossing matters (K > 0, below the search's top U_HI: at an
            # exact zero of c_2 the branch is at ~1e15 and the cubic overshoots there in
            # every round) and where Im u is more than rounding (a branch on the axis
            # within NOISE of its size: no halving resolves a sign there)
            j = np.flatnonzero(((~same) | (dev >= (1 - DIP) * near))
                               & ((u.real[:-1] > 0) | (u.real[1:] > 0)) & (size < U_HI)
                               & (np.maximum(np.abs(f[:-1]), np.abs(f[1:])) > NOISE * size))
            p = (f[j, None] * H[0] + (h * g[:-1])[j, None] * H[1] + f[j + 1, None] * H[2]
                 + (h * g[1:])[j, None] * H[3])
            row = np.concatenate([f[j, None], p, f[j + 1, None]], axis=1)
            sg = np.sign(row)
            turns = np.sum(sg[:, 1:] * sg[:, :-1] < 0, axis=1)
            dip = (turns == 0) & (np.min(np.abs(p), axis=1) < DIP * near[j])
            # a bracket the branch crosses in a stride longer than STEP of its size:
            # Newton's start from it is poor (it may land on a neighbour's crossing); not
            # where the branch passes through infinity (a zero of c_2 on the circle,
            # Re(u_j conj u_j+1) < 0: no halving resolves it)
            uj, uk = u[j], u[j + 1]
            dip |= (turns == 1) & ((uj * np.conj(uk)).real > 0) & \
                (np.abs(uk - uj) > STEP * size[j])
            ok = np.all(np.isfinite(row), axis=1)
            flag[j[ok & ((turns > 1) | dip)]] = True
    return np.flatnonzero(flag)


def dip_refined(resp: LoopResponse, i: int, th: np.ndarray, c: list, d: list, quad: bool
                ) -> tuple[np.ndarray, list]:
    """The grid halved where :func:`dips` flags an interval (at most
    :data:`DIP_ROUNDS` times), and c_0..c_2 on it (``c``, ``d``: the coefficients and
    their d/dtheta on ``th``, :func:`refined` with ``deriv``). After the whole grid's first look,
    each round looks at the flagged intervals' halves alone: they are laid end to end as
    triples (start, middle, end), whose branches :func:`dips` follows within each
    triple; the steps from one triple to the next are no intervals and not looked at."""
    lt, lc, ld = th, c, d                   # the grid looked at: the whole one first
    j = dips(lt, lc, ld, quad)
    added: list[tuple[np.ndarray, list]] = []
    for _ in range(DIP_ROUNDS):
        if not j.size or j.size > th.size:  # (a valve: more than the grid's own size)
            break
        mid = 0.5 * (lt[j] + lt[j + 1])
        cm, dm = coefficients(resp, i, mid)
        added.append((mid, cm))
        lt = _triples(lt, mid, j)
        lc = [_triples(x, y, j) for x, y in zip(lc, cm, strict=True)]
        ld = [_triples(x, y, j) for x, y in zip(ld, dm, strict=True)]
        j = dips(lt, lc, ld, quad)
        j = j[j % 3 != 2]                   # a step between two triples
    if not added:
        return th, c
    return inserted(th, c, np.concatenate([m for m, _ in added]),
                    [np.concatenate([cm[q] for _, cm in added]) for q in range(len(c))])


def _triples(x: np.ndarray, xm: np.ndarray, j: np.ndarray) -> np.ndarray:
    """(x[j], xm, x[j + 1]) for each j, end to end."""
    return np.stack([x[j], xm, x[j + 1]], axis=1).ravel()


def evaluate_ahead(resp: LoopResponse, i: int, lo: np.ndarray, hi: np.ndarray,
                   ahead: dict) -> list:
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
        got, _ = coefficients(resp, i, allp, False)
        ahead.update(zip(allp.tolist(), zip(*(g.tolist() for g in got), strict=True),
                         strict=True))
    vals = [ahead[t] for t in mid.tolist()]
    return [np.array([v[q] for v in vals], complex) for q in range(3)]


def halve(resp: LoopResponse, i: int, th: np.ndarray, c: list, j: np.ndarray,
           ahead: dict | None = None) -> tuple[np.ndarray, list]:
    """The grid with the midpoints of intervals ``j`` inserted, and c_0..c_2 on it
    (``ahead``: see :func:`evaluate_ahead`)."""
    mid = 0.5 * (th[j] + th[j + 1])
    cm = (coefficients(resp, i, mid, False)[0] if ahead is None
          else evaluate_ahead(resp, i, th[j], th[j + 1], ahead))
    return inserted(th, c, mid, cm)


def inserted(th: np.ndarray, c: list, mid: np.ndarray, cm: list) -> tuple[np.ndarray, list]:
    """The grid ``th`` with the angles ``mid`` inserted in order, and the coefficients
    ``c`` with ``cm`` (theirs) inserted alike."""
    allt = np.concatenate([th, mid])
    order = np.argsort(allt, kind="stable")
    return allt[order], [np.concatenate([x, y])[order] for x, y in zip(c, cm, strict=True)]


def coefficients(resp: LoopResponse, i: int, th: np.ndarray, deriv: bool = True
          ) -> tuple[list, list]:
    """c_0..c_2 and their d/dtheta at the angles (complex arrays; the jets' centres
    alone: a proposer needs no enclosures); ``deriv`` False: the values alone (the
    derivatives :data:`~hapstab.engine.discs.NO_DERIV`, the values the same)."""
    F = resp.coefficients(np.full(th.size, i), th, np.zeros(th.size), values_only=True,
                          deriv=deriv)
    return [f.vc for f in F], [f.dc for f in F]


def branches(c: list, quad: bool) -> list[np.ndarray]:
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
