"""The referee campaign of issue 26: is every K_max hapstab reports safe?

Scenarios (seeded: class c, index i drawn from ``np.random.default_rng([SEED, c, i])``;
``HAPSTAB_SEED`` draws a fresh campaign, the default stays fixed):

* ``wall``: stiff walls on light devices, k T^2/m from 1 to 1e4 (stratified in its
  log: :func:`wall_group`; walls 1e5...1e7 N/m, T 0.5...2 ms, masses 1...50 g; the
  issue's reproducers are in this class), HVE and PEB;
* ``marginal``: undamped devices and B = 0 (marginal at K -> 0+), delays near the
  operator's resonance;
* ``mass``: heavy and light masses over the documented range (grams to tonnes, k T^2/m
  1e-8...1e2), and a few beyond it (1e9...1e15 kg: a refusal is an answer there);
* ``delay``: long delays (100 ... ``max_delay`` samples), truth by :mod:`references.phase`.

The truth: the tests' own brute force (:func:`references.brute.stable_intervals`: the
closed-loop matrix's eigenvalues on a geometric scan of K) with every verdict that
matters settled by the 40-digit referee (:func:`references.brute.robust`, ``dps=40``);
for ``delay`` the phase reference (crossings refined at 40 digits, winding numbers).

What must hold (each violation is a problem of the scenario):

1. **never above**: K_max = K_h > 0 is stable by the referee (at K_h itself, and no
   grid point of the scan below K_h is unstable); K_h = inf only if the scan finds no
   instability. The referee decides at 40 digits, so its own precision is ~1e-30; no
   allowance is made for the rounding of K_h (the safe end of an enclosure rounds down).
2. **tight or uncertain**: the truth K_t lies in [K_h, K_h (1 + 1e-9)] (the referee is
   unstable at K_h (1 + 1e-9)), or hapstab's ``details["uncertain_intervals"]`` (chained
   with the stable intervals that follow them from K_h) reach K_t: the enclosure
   [K_h, U], whose width is recorded.
3. **no confident wrong verdict**: ``stability()`` at K_t (1 +- 1e-6), (1 +- 1e-3),
   (1 +- 1e-2), K_t / 2 and between K_t and K_h (when K_h is above) is never "stable"
   where the referee says unstable or "unstable" where it says stable; "marginal" only
   within 1e-9 of the circle (hapstab's own band).
4. a refusal (a HapstabError) is an answer only beyond the documented range (class
   ``mass``, masses above 1e3 kg); elsewhere it is a problem ("refused").
5. **the certificate**: ``res.certificate``, through JSON as a file holds it, is valid
   by :func:`hapstab.verify_certificate` against the loop and claims the K_max reported;
   K_max nudged up 1e-9, an excluded piece dropped, a crossing's direction flipped are
   each invalid (category "certificate").
"""

from __future__ import annotations

import copy
import json
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

import hapstab as h

from . import brute, phase
from .campaign import Scenario

#: the campaign's seed (scenario (c, i) from ``default_rng([SEED, c, i])``)
SEED = int(os.environ.get("HAPSTAB_SEED", "26"))

#: digits of the referee (the issue's: 40)
DPS = 40

#: most states for which an undecided verdict is settled by refining the whole spectrum
#: at DPS digits (Aberth: ~0.4 s at 72 states; quadratic in the states per iteration)
WHOLE_SPECTRUM_MAX = 160
#: most states for which, when Aberth does not converge either, the whole spectrum is
#: computed by mpmath's QR (mpmath.eig) at DPS digits (~7 s at 42 states, cubic)
QR_SPECTRUM_MAX = 64

#: relative distance below the truth within which K_max counts as tight (the issue's)
TIGHT = 1e-9

#: verdict probes around the truth, relative
OFFSETS = (-1e-2, -1e-3, -1e-6, 1e-6, 1e-3, 1e-2)

#: |rho - 1| within which "marginal" is an acceptable verdict (hapstab's own band,
#: exact.MARGINAL_TOL)
MARGINAL_BAND = 1e-9

#: the documented mass range's top (grams to tonnes); heavier may be refused
DOCUMENTED_MASS = 1e3

CLASSES = ("wall", "marginal", "mass", "delay")

#: every outcome of :func:`check` in this process (the test file prints a summary)
RESULTS: list[Outcome] = []


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(math.log(lo), math.log(hi))))


#: strata of log10(k T^2/m) over [0, 4] (the issue's 1 to 1e4) for the walls: wall i
#: draws from stratum i mod WALL_STRATA, so every seed's first WALL_STRATA walls span it
#: (drawn freely, 400 walls of seed 20261202 spanned only 818x)
WALL_STRATA = 8
#: the walls' ranges: masses of light devices (1 to 50 g, the documented range's light
#: end), haptic periods (0.5 to 2 ms), stiff walls (1e5 to 1e7 N/m)
WALL_MASS_KG, WALL_PERIOD_S, WALL_STIFFNESS_N_PER_M = (1e-3, 5e-2), (5e-4, 2e-3), (1e5, 1e7)


def wall_group(rng: np.random.Generator, i: int) -> tuple[float, float, float]:
    """(mass, period, wall stiffness) with k T^2/m log-uniform in stratum i mod
    WALL_STRATA of [1, 1e4]: the group first, then a period for which a mass and a wall
    in their ranges give it, then the mass, and the wall from the group."""
    j = i % WALL_STRATA
    x = 10.0 ** (4.0 * (j + rng.uniform()) / WALL_STRATA)
    (m_lo, m_hi), (t_lo, t_hi), (k_lo, k_hi) = WALL_MASS_KG, WALL_PERIOD_S, WALL_STIFFNESS_N_PER_M
    # m = k T^2 / x in [m_lo, m_hi] for some k in [k_lo, k_hi]: T^2 in [m_lo x / k_hi,
    # m_hi x / k_lo] (non-empty with the periods' range for every x in [1, 1e4])
    T = _logu(rng, max(t_lo, math.sqrt(m_lo * x / k_hi)), min(t_hi, math.sqrt(m_hi * x / k_lo)))
    m = _logu(rng, max(m_lo, k_lo * T * T / x), min(m_hi, k_hi * T * T / x))
    return m, T, x * m / (T * T)


def _wall(rng: np.random.Generator, i: int) -> Scenario:
    m, T, k = wall_group(rng, i)
    b = _logu(rng, 1e-6, 1e-1)
    B = 0.0 if rng.uniform() < 0.3 else _logu(rng, 1e-4, 5e-2)
    n = int(rng.integers(0, 11))
    if rng.uniform() < 0.8:
        return Scenario(f"wall-hve#{i}", "hve", m, b, T, n, B, operator=f"spring:{k!r}")
    # PEB: the wall is the slave's environment, k T^2/m of the slave's mass; the master
    # is a light device of its own
    mm, bs = _logu(rng, *WALL_MASS_KG), _logu(rng, 1e-6, 1e-1)
    return Scenario(f"wall-peb#{i}", "peb", mm, b, T, n, B, m, bs, n, B,
                    operator=f"spring:{_logu(rng, 1.0, 1e3)!r}", environment=f"spring:{k!r}")


def _marginal(rng: np.random.Generator, i: int) -> Scenario:
    m, T = _logu(rng, 1e-2, 1.0), _logu(rng, 1e-4, 5e-3)
    w = _logu(rng, 0.02, 1.0) / T                       # resonance: omega T < 1
    k = m * w * w
    n = int(rng.integers(0, 41))
    if rng.uniform() < 0.6:
        return Scenario(f"marginal-hve#{i}", "hve", m, 0.0, T, n, 0.0, operator=f"spring:{k!r}")
    ms = _logu(rng, 1e-2, 1.0)
    return Scenario(f"marginal-peb#{i}", "peb", m, 0.0, T, n, 0.0, ms, 0.0, n, 0.0,
                    operator=f"spring:{k!r}", environment=f"spring:{ms * w * w * _logu(rng, 0.3, 3)!r}")


def _mass(rng: np.random.Generator, i: int) -> Scenario:
    top = 1e15 if rng.uniform() < 0.05 else DOCUMENTED_MASS
    m, T = _logu(rng, 1e-3, top), _logu(rng, 1e-5, 1e-1)
    b = m * _logu(rng, 1e-3, 1e2)                        # b/m from 1e-3 to 1e2 per second
    k = m / (T * T) * _logu(rng, 1e-8, 1e2)
    n = int(rng.integers(0, 21))
    B = 0.0 if rng.uniform() < 0.3 else b * _logu(rng, 1e-2, 2.0)
    if rng.uniform() < 0.6:
        return Scenario(f"mass-hve#{i}", "hve", m, b, T, n, B, operator=f"spring:{k!r}")
    ms = m * _logu(rng, 0.1, 10.0)
    bs = ms * _logu(rng, 1e-3, 1e2)
    return Scenario(f"mass-peb#{i}", "peb", m, b, T, n, B, ms, bs, n, B,
                    operator=f"spring:{k!r}", environment=f"spring:{k * _logu(rng, 0.1, 10)!r}")


def _delay(rng: np.random.Generator, i: int, max_delay: int) -> Scenario:
    n = round(_logu(rng, 100, max_delay))
    m, T = _logu(rng, 1e-2, 1.0), _logu(rng, 1e-4, 2e-3)
    b = m * _logu(rng, 1e-2, 10.0)
    k = m / (T * T) * _logu(rng, 1e-8, 1e-3)
    B = 0.0 if rng.uniform() < 0.5 else b * _logu(rng, 1e-3, 0.3) * T
    if rng.uniform() < 0.6:
        return Scenario(f"delay-hve#{i}", "hve", m, b, T, n, B, operator=f"spring:{k!r}")
    ms = m * _logu(rng, 0.3, 3.0)
    nb = n if rng.uniform() < 0.7 else round(_logu(rng, 100, max_delay))
    return Scenario(f"delay-peb#{i}", "peb", m, b, T, n, B, ms, ms * _logu(rng, 1e-2, 10.0), nb,
                    B, operator=f"spring:{k!r}", environment=f"spring:{k * _logu(rng, 1, 100)!r}")


def scenario(cls: str, i: int, max_delay: int = 10_000, seed: int | None = None) -> Scenario:
    """Scenario ``i`` of class ``cls`` (deterministic in ``seed``, default :data:`SEED`,
    ``cls`` and ``i``)."""
    rng = np.random.default_rng([SEED if seed is None else seed, CLASSES.index(cls), i])
    if cls == "wall":
        return _wall(rng, i)
    if cls == "marginal":
        return _marginal(rng, i)
    if cls == "mass":
        return _mass(rng, i)
    return _delay(rng, i, max_delay)


#: the issue's reproducers (true values in the issue, confirmed at 40 digits there)
ISSUE_26 = (
    Scenario("issue26-wall-1", "hve", 0.0011034930256540415, 2.793119774241153e-05,
             0.0008382324672663228, 4, 0.008156767423636477, operator="spring:1000000.0"),
    Scenario("issue26-wall-2", "hve", 0.0026649320666119014, 1.7482375171673343e-05,
             0.001091137890352246, 5, 0.0, operator="spring:1000000.0"),
    Scenario("issue26-marginal-hve", "hve", 0.02272704999558146, 0.0, 0.003999733575564432, 22,
             0.0, operator="spring:373.11629214807107"),
    Scenario("issue26-marginal-peb", "peb", 0.13749381169616529, 0.0, 0.000890594778822135, 34,
             0.0, 0.23273843177103054, 0.0, 34, 0.0, operator="spring:459.7312419258073",
             environment="spring:374.8968065578325"),
    Scenario("issue26-heavy-1e12", "hve", 1e12, 0.1, 1e-3, 0, 0.0, operator="spring:1"),
)


# ------------------------------------------------------------------- checking
@dataclass
class Outcome:
    """What :func:`check` found for one scenario."""

    scenario: Scenario
    problems: list[str] = field(default_factory=list)
    categories: set = field(default_factory=set)
    notes: list[str] = field(default_factory=list)
    kmax: float = math.nan           # hapstab's
    truth: float = math.nan          # the reference's (nan: not computed)
    rel: float = 0.0                 # (K_h - K_t) / K_t where a problem has it
    width: float = 0.0               # the enclosure's width U - K_h (uncertain answers)
    certificates: int = 0            # genuine certificates verified
    tampered: int = 0                # forgeries of them checked
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.problems

    def problem(self, cat: str, msg: str) -> None:
        self.categories.add(cat)
        self.problems.append(f"[{cat}] {msg}")

    def report(self) -> str:
        s = self.scenario
        return "\n".join([f"scenario {s.name}: K_max {self.kmax!r}, truth {self.truth!r} "
                          f"(rel {self.rel:.3g})", f"  CLI: {s.cli()}",
                          *(f"  - {p}" for p in self.problems),
                          *(f"  note: {n}" for n in self.notes)])


class _Referee:
    """Stability at K: the 40-digit referee on the closed-loop matrix, or the phase
    reference (long delays)."""

    def __init__(self, s: Scenario, long: bool):
        self.L, self.long = s.brute_loop(), long
        self.pt = phase.truth(self.L) if long else None
        self.scan = None if long else brute.stable_intervals(self.L)

    def stable(self, K: float) -> bool | None:
        if self.long:
            return phase.decided(self.pt, self.L, K)
        v = brute.robust(self.L, K, dps=DPS).stable
        return v if v is not None else self._whole_spectrum(K)

    def _whole_spectrum(self, K: float) -> bool | None:
        """The verdict from every eigenvalue refined together at DPS digits (Aberth on
        det(zI - A(K))), where :func:`brute.robust` left a cluster of more than 40 near
        the circle undecided (undamped two-port loops with stiff walls: four poles
        1e-14..1e-12 outside among 72, marginal-peb#100065 of seed 1796310007).
        None when the loop is too large for it or Aberth does not converge."""
        import mpmath
        A0, A1 = brute.matrices(self.L)
        if A0.shape[0] > WHOLE_SPECTRUM_MAX:
            return None
        roots = brute.aberth(self.L, K, np.linalg.eigvals(A0 + K * A1), DPS, iters=400)
        if roots is None:
            return self._qr_spectrum(A0, A1, K)
        with mpmath.workdps(DPS):
            top = max(abs(r) for r in roots)
        return None if top == 1 else bool(top < 1)

    def _qr_spectrum(self, A0: np.ndarray, A1: np.ndarray, K: float) -> bool | None:
        """The verdict from every root of det(zI - A(K)) built at DPS digits (the ZOH by
        mpmath.expm: :func:`brute.char_poly_mp`) and found by mpmath.polyroots, where
        Aberth did not converge (many poles within 1e-6 of the circle: a stiff PEB with
        its ports' resonances above the Nyquist frequency, mass-peb#200134 of seed
        1796540596: |z| = 1 - 2.4e-7 at K = 4.3). Not the double-precision matrices: their
        rounding moves |z| by ~1e-13 there, 1e-4 N/m of K near the crossing. Decided only
        when polyroots converges and the spectral radius is farther from 1 than its error
        estimate; None beyond QR_SPECTRUM_MAX states or for the loops char_poly_mp does
        not build."""
        import mpmath
        if A0.shape[0] > QR_SPECTRUM_MAX or self.L.extended:
            return None
        with mpmath.workdps(DPS):
            coeffs = brute.char_poly_mp(self.L, K, DPS)
            try:
                roots, err = mpmath.polyroots(coeffs[::-1], maxsteps=600, extraprec=4 * DPS,
                                              error=True, asc=True)   # lowest power first
            except mpmath.libmp.libhyper.NoConvergence:
                return None
            top = max(abs(r) for r in roots)
            if abs(top - 1) <= 10 * err:
                return None
            return bool(top < 1)

    def rho_near_circle(self, K: float) -> bool:
        """Within :data:`MARGINAL_BAND` of the circle ("marginal" acceptable)."""
        if self.long:
            return any(abs(K / c.K - 1) <= 1e-6 for c in self.pt.crossings)
        return abs(brute.robust(self.L, K, dps=DPS).rho - 1) <= MARGINAL_BAND

    def first_unstable(self) -> tuple[float, float]:
        """(last stable, first unstable) scan points by the referee ((0, inf) if none)."""
        if self.long:
            k = self.pt.kmax
            return (0.0, 0.0) if k == 0 else (k, k) if math.isfinite(k) else (math.inf, math.inf)
        Ks, rho = self.scan.K, self.scan.rho
        prev = 0.0
        for K, r in zip(Ks, rho, strict=True):
            if r < 1 - 1e-6:          # far inside: the double eigenvalues decide
                prev = K
                continue
            v = self.stable(float(K))
            if v is False:          # unstable at the scan's bottom: K_max = 0
                return (prev, float(K)) if prev > 0 else (0.0, 0.0)
            if v is None:           # undecided even at DPS digits: no truth claimed above
                return (prev, float(K)) if prev > 0 else (0.0, float(K))
            prev = float(K)
        return prev, math.inf

    def truth(self, lo: float, hi: float) -> float:
        """The first boundary between a stable ``lo`` and an unstable ``hi`` (bisection
        on the referee's verdicts to 1e-13)."""
        if self.long or hi == 0 or not math.isfinite(hi):
            return lo if self.long else hi
        if lo == 0:
            lo = hi * 1e-12
        for _ in range(200):
            if hi / lo - 1 <= 1e-13:
                break
            mid = math.sqrt(lo * hi)
            if self.stable(mid) is not True:    # undecided: the safe side (lower)
                hi = mid
            else:
                lo = mid
        return lo


def _enclosure_end(res, K_h: float) -> float:
    """U: from K_h, the uncertain intervals and the stable intervals that follow, chained
    (each starting within TIGHT of where the last ended)."""
    pieces = sorted([tuple(map(float, iv)) for iv in res.details.get("uncertain_intervals", [])]
                    + [tuple(map(float, iv)) for iv in res.stable_intervals])
    U, grown = K_h, True
    while grown:
        grown = False
        for a, b in pieces:
            if a <= U * (1 + TIGHT) + 1e-300 and b > U:
                U, grown = b, True
    return U


def check(s: Scenario, long: bool = False) -> Outcome:
    """Check one scenario (module docstring); every violation is a problem."""
    t0 = time.perf_counter()
    out = Outcome(s)
    try:
        _check(s, long, out)
    except Exception as e:  # the reference failed: its own category, never hidden
        out.problem("reference error", f"{type(e).__name__}: {e}")
    out.seconds = time.perf_counter() - t0
    RESULTS.append(out)
    return out


def _check(s: Scenario, long: bool, out: Outcome) -> None:
    try:
        res = h.critical_stiffness(s.hapstab_loop(), certify=True)
    except h.HapstabError as e:
        heavy = max(s.m, s.ms) > DOCUMENTED_MASS
        if not heavy:
            out.problem("refused", f"{type(e).__name__}: {e}")
        else:
            out.notes.append(f"refused beyond the documented range: {e}")
        return
    K_h = out.kmax = float(res.critical_stiffness)
    _certificate(s, res, K_h, out)
    ref = _Referee(s, long)
    lo, hi = ref.first_unstable()
    if long:
        _check_long(ref, K_h, res, out)
        _verdicts(s, ref, out.truth, K_h, out)
        return
    # 1. never above
    above = (0 < K_h and hi <= K_h) or (0 < K_h < math.inf and ref.stable(K_h) is False)
    if above:
        K_t = out.truth = ref.truth(lo, min(hi, K_h))
        out.rel = (K_h - K_t) / K_t if K_t > 0 else math.inf
        out.problem("above", f"K_max {K_h!r} above the true {K_t!r} (rel {out.rel:.3g})")
        _verdicts(s, ref, K_t, K_h, out)
        return
    # 2. tight or uncertain
    tight = (hi == 0 and K_h == 0) or (math.isinf(hi) and math.isinf(K_h))
    if not tight and math.isfinite(K_h):
        v = ref.stable(K_h * (1 + TIGHT)) if K_h > 0 else (hi != 0)
        tight = v is False
        if v is None:
            out.notes.append(f"referee undecided at K_max (1 + {TIGHT:g})")
            tight = True
    if tight:
        K_t = K_h if math.isfinite(K_h) and K_h > 0 else hi
    else:
        K_t = ref.truth(lo, hi) if math.isfinite(hi) else math.inf
        U = _enclosure_end(res, K_h)
        out.width = U - K_h
        if not U * (1 + TIGHT) >= K_t:
            out.rel = (K_h - K_t) / K_t if K_t > 0 and math.isfinite(K_t) else -math.inf
            out.problem("below", f"K_max {K_h!r} below the true {K_t!r} (rel {out.rel:.3g}) "
                        f"and the enclosure [{K_h!r}, {U!r}] does not reach it")
    if math.isnan(out.truth):
        out.truth = K_t
    _verdicts(s, ref, K_t, K_h, out)


def _tampered(cert: dict) -> list[tuple[str, dict]]:
    """The issue's three forgeries of a genuine certificate, where it has what they edit:
    K_max nudged up 1e-9 (with its interval), an excluded piece dropped, the first
    crossing's direction flipped."""
    out = []
    claim = cert["claim"]
    if claim["kmax_N_per_m"] > 0 and claim["stable_intervals_N_per_m"]:
        t = copy.deepcopy(cert)
        t["claim"]["kmax_N_per_m"] *= 1 + 1e-9
        for iv in t["claim"]["stable_intervals_N_per_m"]:
            if iv[1] == claim["kmax_N_per_m"]:
                iv[1] = t["claim"]["kmax_N_per_m"]
        out.append(("K_max nudged", t))
    gaps = [j for j, g in enumerate(cert["gaps"]) if g["excluded"] and len(g["pieces"]) > 1]
    if gaps:
        t = copy.deepcopy(cert)
        pieces = t["gaps"][gaps[0]]["pieces"]
        del pieces[len(pieces) // 2]
        out.append(("piece dropped", t))
    if cert["crossings"]:
        t = copy.deepcopy(cert)
        c = t["crossings"][0]
        c["direction"] = "inwards" if c["direction"] != "inwards" else "outwards"
        out.append(("direction flipped", t))
    return out


def _certificate(s: Scenario, res, K_h: float, out: Outcome) -> None:
    """5. the certificate (as a file holds it: through JSON) verifies from the loop's
    numbers and claims the K_max reported; each forgery of it is invalid."""
    cert = getattr(res, "certificate", None)
    if cert is None:
        out.problem("certificate", f"no certificate ({res.details.get('proof')!r})")
        return
    cert = json.loads(json.dumps(cert))
    loop = s.hapstab_loop()
    chk = h.verify_certificate(cert, loop)
    out.certificates += 1
    if not chk.valid:
        out.problem("certificate", f"the genuine certificate is invalid: {chk.reason}")
        return
    # a certificate claims a finite K_max: the top examined when hapstab reports inf
    if chk.kmax != K_h and not (math.isinf(K_h) and chk.kmax <= K_h):
        out.problem("certificate", f"verifies K_max {chk.kmax!r}, the result says {K_h!r}")
    for what, t in _tampered(cert):
        out.tampered += 1
        if h.verify_certificate(t, loop).valid:
            out.problem("certificate", f"a forgery ({what}) verifies")


def _check_long(ref: _Referee, K_h: float, res, out: Outcome) -> None:
    """1. and 2. against the phase reference (its K_max at 40 digits)."""
    pt = ref.pt
    K_t = out.truth = pt.kmax
    if pt.stable_below is None:
        out.notes.append("phase reference undecided just above K = 0")
        return
    exact = pt.kmax_mp if pt.kmax_mp is not None else K_t
    if K_h > exact:
        out.rel = (K_h - K_t) / K_t if K_t > 0 else math.inf
        out.problem("above", f"K_max {K_h!r} above the true {K_t!r} (rel {out.rel:.3g})")
    elif K_h < K_t * (1 - TIGHT):
        U = _enclosure_end(res, K_h)
        out.width = U - K_h
        if not U * (1 + TIGHT) >= K_t:
            out.rel = (K_h - K_t) / K_t if math.isfinite(K_t) else -math.inf
            out.problem("below", f"K_max {K_h!r} below the true {K_t!r} (rel {out.rel:.3g}) "
                        f"and the enclosure [{K_h!r}, {U!r}] does not reach it")


def _verdicts(s: Scenario, ref: _Referee, K_t: float, K_h: float, out: Outcome) -> None:
    """3. stability() at the probes against the referee."""
    if K_t > 0 and math.isfinite(K_t):
        probes = [K_t * (1 + d) for d in OFFSETS] + [K_t / 2]
        if K_h > K_t and math.isfinite(K_h):
            probes += [math.sqrt(K_t * K_h), K_h]
    else:
        probes = [s.m / s.T ** 2 * f for f in (1e-6, 1e-2, 1.0)]
    for K in probes:
        try:
            got = h.stability(s.hapstab_loop(K), certify=True).verdict
        except h.HapstabError as e:   # refused (the matrix's budget at long delays): no verdict
            out.notes.append(f"stability at K = {K!r} refused: {type(e).__name__}: {e}")
            continue
        if got not in ("stable", "unstable", "marginal"):
            continue                     # not confident (uncertain): never wrong
        v = ref.stable(K)
        if v is None:
            continue
        if got == "marginal":
            if not ref.rho_near_circle(K):
                out.problem("wrong verdict", f"stability at K = {K!r}: marginal, the referee: "
                            f"{'stable' if v else 'unstable'} beyond 1e-9 of the circle")
        elif (got == "stable") != v:
            out.problem("wrong verdict", f"stability at K = {K!r}: {got}, the referee: "
                        f"{'stable' if v else 'unstable'}")


def summary(results: list[Outcome] | None = None, top: int = 12) -> str:
    """Failures by class and category, and the worst ones."""
    res = RESULTS if results is None else results
    if not res:
        return ""
    bad = [r for r in res if not r.ok]
    lines = [f"certified campaign (seed {SEED}): {len(bad)} of {len(res)} scenarios fail "
             f"({sum(r.seconds for r in res):.0f} s); {sum(r.certificates for r in res)} "
             f"certificates verified, {sum(r.tampered for r in res)} forgeries checked"]
    for c in (*CLASSES, "issue26"):
        rc = [r for r in res if r.scenario.name.startswith(c)]
        if not rc:
            continue
        cats: dict[str, int] = {}
        for r in rc:
            for k in r.categories:
                cats[k] = cats.get(k, 0) + 1
        unc = sum(r.width > 0 for r in rc)
        lines.append(f"  {c:9s} {sum(not r.ok for r in rc):5d} / {len(rc):5d} fail  "
                     + ", ".join(f"{k}: {n}" for k, n in sorted(cats.items()))
                     + (f"  (uncertain answers: {unc})" if unc else ""))
    worst = sorted((r for r in bad if "above" in r.categories), key=lambda r: -r.rel)[:top]
    if worst:
        lines.append("  worst K_max above the truth:")
        lines += [f"    {r.scenario.name:18s} rel {r.rel:9.3g}  K_max {r.kmax!r}  true {r.truth!r}"
                  for r in worst]
    return "\n".join(lines)
