"""Phase-based reference for long delays (no hapstab code; no N x N matrix).

At 10^4 samples of delay the closed-loop matrix of :mod:`references.brute` has 10^4
rows: its eigenvalues are out of reach. This reference works on the loop's return
difference instead (the same one :func:`references.brute.char_fn` uses): for a loop of
p = 1 or 2 ports with one position controller each,

    M(z, K)_ij = delta_ij d_j(z) + C_i(z) sum_terms sign z^-delay n_j(z),
    C_i(z) = g_i K + (B_i / T)(1 - 1/z),

with d_j(z) = det(zI - A_j) and n_j(z) = [1 0] adj(zI - A_j) b_j of port j's ZOH
(A_j, b_j) (:func:`references.brute._mp_plants`, mpmath.expm). The closed loop's
characteristic polynomial is z^q det M(z, K) (q the delay registers), so

* **a root on the unit circle** at z = e^{j theta} for a real K: det M = c0 + c1 K
  + c2 K^2 (c2 = 0 for p = 1) with complex c_i(theta), and K real. For p = 1 that is
  Im(c0 conj c1) = 0; for p = 2 the resultant of the real and imaginary parts (two real
  quadratics in K with a common root). Both are smooth real functions of theta (no
  division, no branch of a square root): their sign changes on a theta grid fine enough
  for the phase z^-delay (:data:`POINTS_PER_TURN` points per turn of the fastest
  phase), refined in double precision by bisection and, near the lowest positive K, at
  :data:`DPS` digits by mpmath. theta = 0 and pi (z = +-1, every coefficient real) are
  solved apart as real polynomials in K.
* **stability at a K away from every crossing**: the argument principle. det M has
  poles only at z = 0 and behaves as z^(2p) at infinity (d_j monic of degree 2, the
  rest of lower degree), so every closed-loop root is inside the circle iff the
  winding number of det M(e^{j theta}, K) about 0 is 2p. With real coefficients it is
  the phase change over [0, pi] divided by pi. The grid is refined until no step of
  the phase exceeds pi/4 (else: undecided).

K_max is the lowest positive crossing if the loop is stable just above K = 0 (the
winding at half of it: no crossing lies in between, so the winding there is that of
K -> 0+), else 0. A pair of sign changes closer than the grid's spacing (a root that
touches the circle and leaves) can be missed: :func:`check_against_brute` in the tests
compares with the matrix brute force where both run.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import mpmath
import numpy as np

from . import brute

#: digits of the refinement (the issue's referee works at 40)
DPS = 40

#: grid points per turn of the fastest phase e^{-j theta d} in theta (d the largest
#: delay + 2): 32 keep a sign change's neighbours ~11 degrees apart, so a crossing is
#: two consecutive samples of opposite sign unless two crossings lie within ~1/32 turn
POINTS_PER_TURN = 32

#: crossings whose double-precision K is within this ratio of the lowest are all refined
#: at DPS digits (the double K of a crossing is good to ~1e-12 away from a resonance, but
#: 7.6e-9 off was measured beside a lightly damped one, delay-hve#7 of seed 26, where
#: |d(e^{j theta})| ~ 1e-7 and its double evaluation loses 7 digits: 1e-4 is far wider)
REFINE_WINDOW = 1e-4


def _require(loop: brute.Loop) -> None:
    assert not loop.extended and not loop.rigid, "one position controller per port, grounded"
    assert all(not c.filt for c in loop.controls), "backward-difference damper only"
    assert len(loop.ports) in (1, 2)


@functools.lru_cache(maxsize=64)
def _plants(loop: brute.Loop) -> tuple:
    """Per port (d coefficients [1, d1, d0], n coefficients [n1, n0]) as floats and mpf."""
    out = []
    # at DPS digits: the first call comes from the double-precision grid, and mpf
    # arithmetic rounds to the context's precision, not its operands'. At 53 bits
    # d0 = a11 a22 - a12 a21 (~1 - b T/m) lost its last digits, which near a lightly
    # damped resonance (|d(e^{j theta})| ~ 1e-7) moved a crossing's K by 1e-11 relative
    # (delay-hve#7 of seed 26: 0.014172663834791113 against the referee's
    # 0.0141726638349430: stable at K_max, unstable 1e-12 above it)
    with mpmath.workdps(DPS):
        for a11, a12, a21, a22, b1, b2 in brute._mp_plants(loop, DPS):
            d = (mpmath.mpf(1), -(a11 + a22), a11 * a22 - a12 * a21)
            n = (b1, -a22 * b1 + a12 * b2)
            out.append((d, n))
    return tuple(out)


def _max_delay(loop: brute.Loop) -> int:
    return max(dl for c in loop.controls for _, _, dl in c.terms)


def _quadratic(loop: brute.Loop) -> bool:
    """det M is quadratic in K: two ports and a delay round the loop (without one, the
    K^2 terms cancel: c2 = g n_0 n_1 (1 - z^-(n_f + n_b)) = 0)."""
    return len(loop.ports) == 2 and _max_delay(loop) > 0


def grid(loop: brute.Loop, density: int = 1) -> np.ndarray:
    """theta samples in [0, pi]: :data:`POINTS_PER_TURN` x ``density`` per turn of the
    fastest phase, plus a cluster around the argument of every plant pole: a lightly
    damped device has roots within ~b T/(2m) of the circle there, where the phase turns
    by pi over that width (a uniform grid would alias it)."""
    quad = len(loop.ports) == 2
    m = POINTS_PER_TURN * density * 2 * (_max_delay(loop) + 2) * (2 if quad else 1)
    parts = [np.linspace(0.0, math.pi, m + 1)]
    for dc, _ in _plants(loop):
        for r in np.roots([float(c) for c in dc]):
            gap = max(abs(1.0 - abs(r)), 1e-12)
            phi = abs(float(np.angle(r)))
            offs = gap * np.concatenate([-np.geomspace(1e-3, 1e3, 120 * density)[::-1], [0.0],
                                         np.geomspace(1e-3, 1e3, 120 * density)])
            parts.append(phi + offs)
    th = np.unique(np.concatenate(parts))
    return th[(th >= 0.0) & (th <= math.pi)]


def coefficients(loop: brute.Loop, theta, lib=np):
    """(c0, c1, c2) of det M(z, K) = c0 + c1 K + c2 K^2 at z = e^{j theta} (``theta`` an
    array with ``lib=np``, one mpf with ``lib=mpmath``). The delays' phases are
    e^{-j delay theta} computed as such, not as powers of z (whose rounding grows with
    the delay)."""
    pl = _plants(loop)
    if lib is np:
        cast, expj = float, (lambda x: np.exp(1j * x))
    else:
        cast, expj = (lambda v: v), mpmath.expj
    z = expj(theta)
    p = len(pl)
    d = [z * z + cast(dc[1]) * z + cast(dc[2]) for dc, _ in pl]
    n = [cast(nc[0]) * z + cast(nc[1]) for _, nc in pl]
    M0 = [[d[i] if i == j else 0 * z for j in range(p)] for i in range(p)]
    M1 = [[0 * z for _ in range(p)] for _ in range(p)]
    T = cast(mpmath.mpf(loop.period))
    for i, c in enumerate(loop.controls):
        Bt = cast(mpmath.mpf(c.damping)) / T
        for j, s, dl in c.terms:
            h = s * expj(-dl * theta) * n[j]
            M0[i][j] = M0[i][j] + Bt * (1 - 1 / z) * h
            M1[i][j] = M1[i][j] + c.gain * h
    if p == 1:
        return M0[0][0], M1[0][0], 0 * z
    c0 = M0[0][0] * M0[1][1] - M0[0][1] * M0[1][0]
    c1 = M0[0][0] * M1[1][1] + M1[0][0] * M0[1][1] - M0[0][1] * M1[1][0] - M1[0][1] * M0[1][0]
    c2 = M1[0][0] * M1[1][1] - M1[0][1] * M1[1][0]
    return c0, c1, c2


def _real_root_fn(c0, c1, c2, quadratic: bool):
    """(F, K): F = 0 where c0 + c1 K + c2 K^2 has a real root K, and that root."""
    if not quadratic:
        F = (c0 * c1.conjugate()).imag
        K = -(c0 * c1.conjugate()).real / (c1 * c1.conjugate()).real
        return F, K
    Ar, Ai, Br, Bi, Cr, Ci = c2.real, c2.imag, c1.real, c1.imag, c0.real, c0.imag
    u, v, w = Ar * Ci - Ai * Cr, Ar * Bi - Ai * Br, Br * Ci - Bi * Cr
    with np.errstate(all="ignore"):     # v = 0 where c2 = 0: K is then discarded (crossings)
        return u * u - v * w, -u / v


def _mp_real_root_fn(loop: brute.Loop, theta):
    c0, c1, c2 = coefficients(loop, theta, mpmath)
    if not _quadratic(loop):
        q = c0 * mpmath.conj(c1)
        return mpmath.im(q), -mpmath.re(q) / abs(c1) ** 2
    Ar, Ai, Br, Bi = mpmath.re(c2), mpmath.im(c2), mpmath.re(c1), mpmath.im(c1)
    Cr, Ci = mpmath.re(c0), mpmath.im(c0)
    u, v, w = Ar * Ci - Ai * Cr, Ar * Bi - Ai * Br, Br * Ci - Bi * Cr
    return u * u - v * w, -u / v


@dataclass
class Crossing:
    """A root of the closed loop on the unit circle: z = e^{j theta} at stiffness K."""

    K: float
    theta: float
    K_mp: object = None        # the DPS-digit value where refined


def _endpoint_crossings(loop: brute.Loop) -> list[Crossing]:
    """Real K with a root at z = 1 (theta = 0) or z = -1 (theta = pi)."""
    out = []
    for theta in (0.0, math.pi):
        c0, c1, c2 = (complex(c).real for c in coefficients(loop, np.float64(theta)))
        roots = np.roots([c2, c1, c0]) if c2 != 0 else ([-c0 / c1] if c1 != 0 else [])
        out += [Crossing(float(np.real(r)), theta) for r in roots if abs(np.imag(r)) == 0]
    return out


def crossings(loop: brute.Loop, density: int = 1) -> list[Crossing]:
    """Every (K, theta), K > 0, where a closed-loop root lies on the unit circle, sorted
    by K; those within :data:`REFINE_WINDOW` of the lowest refined at :data:`DPS`
    digits (``K_mp``). ``density``: of the theta grid (:func:`grid`)."""
    _require(loop)
    quad = _quadratic(loop)
    theta = grid(loop, density)
    theta = theta[(theta > 0) & (theta < math.pi)]      # the ends apart (F = 0 there)
    F, _ = _real_root_fn(*coefficients(loop, theta), quad)
    idx = np.flatnonzero(np.sign(F[1:]) * np.sign(F[:-1]) < 0)
    a, b = theta[idx], theta[idx + 1]
    fa = F[idx]
    for _ in range(60):                       # bisection of every bracket at once
        mid = 0.5 * (a + b)
        fm, _ = _real_root_fn(*coefficients(loop, mid), quad)
        left = np.sign(fm) == np.sign(fa)
        a, b, fa = np.where(left, mid, a), np.where(left, b, mid), np.where(left, fm, fa)
    th = 0.5 * (a + b)
    c0, c1, c2 = coefficients(loop, th)
    _, K = _real_root_fn(c0, c1, c2, quad)
    # the resultant u^2 - v w also vanishes where c2 = 0 (both leading coefficients: for
    # the PEB wherever the round-trip phase is 1, theta = k pi / n), with no common root:
    # keep a sign change only if det M itself vanishes there. A true root bisected 60
    # times leaves a residual near rounding (~1e-12 of the terms); a spurious one is of
    # the order of the terms themselves (measured 0.56 at PEB n = 1000, theta = 3 pi/1000)
    with np.errstate(all="ignore"):
        res = np.abs(c0 + c1 * K + c2 * K * K) / (np.abs(c0) + np.abs(c1 * K)
                                                  + np.abs(c2) * K * K)
    real = np.isfinite(res) & (res < 1e-6)
    out = [Crossing(float(k), float(t)) for k, t in zip(K[real], th[real], strict=True)]
    out += _endpoint_crossings(loop)
    out = sorted((c for c in out if c.K > 0 and math.isfinite(c.K)), key=lambda c: c.K)
    if out:
        low = out[0].K
        for c in out:
            if c.K <= low * (1 + REFINE_WINDOW):
                _refine(loop, c)
        out.sort(key=lambda c: c.K_mp if c.K_mp is not None else c.K)
    return out


def _refine(loop: brute.Loop, c: Crossing) -> None:
    """K and theta of a crossing at DPS digits (secant on the real-root function from
    the double-precision theta; an endpoint's K from its real polynomial)."""
    with mpmath.workdps(DPS + 10):
        if c.theta in (0.0, math.pi):
            th = mpmath.mpf(0) if c.theta == 0 else mpmath.pi
            c0, c1, c2 = (mpmath.re(v) for v in coefficients(loop, th, mpmath))
            if c2 == 0:
                c.K_mp = -c0 / c1
            else:
                c.K_mp = mpmath.findroot(lambda k: c0 + c1 * k + c2 * k * k, mpmath.mpf(c.K))
            return
        t0 = mpmath.mpf(c.theta)
        t = mpmath.findroot(lambda x: _mp_real_root_fn(loop, x)[0], (t0, t0 * (1 + 1e-12)),
                            solver="secant", tol=mpmath.mpf(10) ** (-2 * DPS))
        c.theta, c.K_mp = float(t), _mp_real_root_fn(loop, t)[1]


def _phase_steps(loop: brute.Loop, K: float, theta: np.ndarray) -> tuple[float, float]:
    """(sum, largest magnitude) of the phase steps of det M over ``theta`` (in chunks:
    10^6 samples at a time)."""
    total, big, prev = 0.0, 0.0, None
    for s in range(0, theta.size, 1 << 18):
        c0, c1, c2 = coefficients(loop, theta[s:s + (1 << 18)])
        f = c0 + c1 * K + c2 * K * K
        if prev is not None:
            f = np.concatenate([[prev], f])
        step = np.angle(f[1:] / f[:-1])
        if not np.all(np.isfinite(step)):
            return math.nan, math.inf
        total += float(step.sum())
        big = max(big, float(np.abs(step).max()))
        prev = f[-1]
    return total, big


def _refined(loop: brute.Loop, K: float, theta: np.ndarray, rounds: int = 40) -> np.ndarray | None:
    """``theta`` with every step whose phase turns by pi/8 or more subdivided (8 parts),
    again until none is left (None after ``rounds``): a closed-loop root near the circle
    turns the phase by ~pi over a width of its distance to it."""
    for _ in range(rounds):
        c0, c1, c2 = coefficients(loop, theta)
        f = c0 + c1 * K + c2 * K * K
        step = np.abs(np.angle(f[1:] / f[:-1]))
        if not np.all(np.isfinite(step)):
            return None
        bad = np.flatnonzero(step >= math.pi / 8)
        if bad.size == 0:
            return theta
        if theta.size + 7 * bad.size > 1 << 24:
            return None
        a, b = theta[bad], theta[bad + 1]
        extra = a[:, None] + (b - a)[:, None] * (np.arange(1, 8) / 8.0)[None, :]
        theta = np.sort(np.concatenate([theta, extra.ravel()]))
    return None


def winding(loop: brute.Loop, K: float) -> int | None:
    """Winding number of det M(e^{j theta}, K) about 0, or None when it is not followed
    (:func:`_refined` gives up, or the grid and the grid twice as dense disagree).

    A pair of roots within one grid step of each other and of the circle could turn
    the phase by 2 pi between two samples and be missed: the two densities guard
    against it (not a proof)."""
    out = []
    for density in (1, 2):
        th = _refined(loop, K, grid(loop, density))
        if th is None:
            return None
        total, big = _phase_steps(loop, K, th)
        if not big < math.pi / 4:
            return None
        out.append(round(total / math.pi))
    return out[0] if out[0] == out[1] else None


def stable(loop: brute.Loop, K: float) -> bool | None:
    """Every closed-loop root strictly inside the circle at K (None: undecided)."""
    w = winding(loop, K)
    return None if w is None else w == 2 * len(loop.ports)


@dataclass
class PhaseTruth:
    """K_max by the phase reference.

    Attributes
    ----------
    kmax : float
        0 (unstable just above K = 0), the lowest positive crossing, or inf.
    kmax_mp : mpmath.mpf or None
        The same at DPS digits (crossings only).
    crossings : list of Crossing
    stable_below : bool or None
        The winding's verdict just above K = 0.
    """

    kmax: float
    kmax_mp: object
    crossings: list
    stable_below: bool | None


def truth(loop: brute.Loop) -> PhaseTruth:
    """K_max of ``loop`` by crossings and winding (module docstring)."""
    cr = crossings(loop)
    if not cr:
        s = stable(loop, 1.0)
        return PhaseTruth(math.inf if s else 0.0, None, cr, s)
    first = cr[0]
    k1 = float(first.K_mp) if first.K_mp is not None else first.K
    s = stable(loop, 0.5 * k1)
    if not s:
        return _missed(loop, k1, cr, s)
    # stable at k1 / 2; unstable just below k1 means the grid missed a crossing between
    # (measured: delay-peb#632 of seed 12071208, 2256 samples each way: a crossing at
    # 73.946 missed, 106.88 found; the matrix brute force, 4518 states: 2 poles outside
    # at K = 90): searched between, as _missed does
    # (and delay-peb#596 of the same seed: 25.6493 missed 1.4e-4 below 25.6530 found)
    for below in JUST_BELOW:
        v = stable(loop, k1 * (1 - below))
        if v is False:
            return _between(loop, 0.5 * k1, k1 * (1 - below), cr)
        if v is None:           # the phase steps too fine to resolve there: not decided
            break
    return PhaseTruth(k1, first.K_mp, cr, s)


#: How far below the lowest crossing found :func:`truth` checks the winding (relative),
#: in turn: a missed crossing at least this far below the one found is caught; closer,
#: the winding needs phase steps it may not resolve (then it says None and the check
#: ends; :func:`decided` stays 1e-4 away)
JUST_BELOW = (1e-3, 1e-5)


#: Finer theta grids :func:`_missed` searches a missed crossing on (times the usual)
DENSER = (16, 128)
#: How far below the lowest crossing found :func:`_missed` looks for a stable K
#: (relative): below, the loop is taken as unstable from K = 0 (K_max 0, as before).
MISSED_FLOOR = 1e-12


def _missed(loop: brute.Loop, k1: float, cr: list, s: bool | None) -> PhaseTruth:
    """Unstable (or undecided) at half the lowest crossing found: either unstable from
    K = 0, or the grid missed a crossing below it -- two roots of the real-root function
    closer than its spacing (measured: delay-peb#100009 of seed 11061207, 620 samples,
    the crossing at K = 300.74 and a root for K = -992 7e-6 rad apart, one 4e-5 grid
    step). The winding decides: K halved from k1 / 2 until stable (else K_max 0); the
    crossing between that K and twice it is then searched on grids :data:`DENSER` times
    finer and refined at DPS digits; if none is found, the truth is the upper
    (unstable) end of the stability boundary bisected to 1e-6, in doubles."""
    K = 0.5 * k1
    while K > MISSED_FLOOR * k1:
        K *= 0.5
        v = stable(loop, K)
        if v is None:
            break
        if not v:
            continue
        return _between(loop, K, 2 * K, cr)
    return PhaseTruth(0.0, mpmath.mpf(0), cr, s)


def _between(loop: brute.Loop, lo: float, hi: float, cr: list) -> PhaseTruth:
    """The lowest crossing in (lo, hi], the loop stable at lo and unstable at hi: on
    grids :data:`DENSER` times finer, refined at DPS digits; if none is found, the
    upper (unstable) end of the stability boundary bisected to 1e-6, in doubles."""
    for density in DENSER:
        found = [c for c in crossings(loop, density) if lo < c.K <= hi * (1 + 1e-6)]
        if found:
            c = min(found, key=lambda c: c.K_mp if c.K_mp is not None else c.K)
            return PhaseTruth(float(c.K_mp) if c.K_mp is not None else c.K, c.K_mp, cr, True)
    while hi / lo - 1 > 1e-6:
        mid = math.sqrt(lo * hi)
        w = stable(loop, mid)
        if w is None:
            break
        lo, hi = (mid, hi) if w else (lo, mid)
    return PhaseTruth(hi, None, cr, True)


def decided(pt: PhaseTruth, loop: brute.Loop, K: float, away: float = 1e-4) -> bool | None:
    """Stability at K by the winding, only when K is more than ``away`` (relative) from
    every crossing found (closer, the phase steps need too many samples: None)."""
    if any(abs(K / c.K - 1) <= away for c in pt.crossings):
        return None
    return stable(loop, K)
