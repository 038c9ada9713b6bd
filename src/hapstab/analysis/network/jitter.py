"""K under a time-varying delay (jitter): a bracket [stable_up_to, unstable_from].

The model is :mod:`.jitter_modes`'s (the controller uses the newest sample that has
arrived; the delay d_k of each networked position is any whole number of samples in
[lo, hi] with d_{k+1} <= d_k + 1). Two answers, from two different kinds of
mathematics, and the gap between them:

- ``stable_up_to``: for every scanned K in (0, stable_up_to] the small-gain jitter
  margin (:mod:`.jitter_gain`, Kao & Lincoln 2004; Cervin et al. 2004) holds, so the loop
  is stable for *every* delay sequence in the range (a sufficient condition: it holds
  for arbitrary switching, not only the admissible one, and is conservative).
- ``unstable_from``: the smallest K found at which an explicit admissible periodic delay
  pattern of length <= L (every one is enumerated, :func:`.patterns`) has
  rho(A_{d_p} ... A_{d_1})^(1/p) >= 1 + RATE_MARGIN: repeating that pattern, the loop
  grows (a lower bound of the constrained joint spectral radius, Jungers 2009), so no K
  from there on is stable for every sequence. The constant delays are patterns of
  length 1, and their exact K_max (the exact core) caps it: unstable_from is never
  above the constant-delay worst case.

Between the two the answer is not known: the gap is reported.

References
----------
See :mod:`.jitter_modes` and :mod:`.jitter_gain`.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from hapstab.analysis.network.delay_range import delay_range_critical_stiffness, whole_delays
from hapstab.analysis.network.jitter_gain import small_gain
from hapstab.analysis.network.jitter_modes import (
    MAX_PATTERNS,
    JitterModes,
    jitter_modes,
    pattern_rates,
    patterns,
)
from hapstab.analysis.network.jitter_result import JitterResult
from hapstab.budget import EIG_SECONDS_PER_N3, FLOPS, Cost, check, eig_seconds, exact_points_cost
from hapstab.errors import MAX_DELAY_SAMPLES, AnalysisError, ModelError, ordered_pair
from hapstab.models.loops import require_loop

__all__ = ["jitter", "jitter_cost", "RATE_MARGIN", "K_REL"]

#: A pattern destabilises when its growth rate per sample is at least 1 + 1e-9: far
#: above the rounding of the eigenvalues of the products (below 1e-12 on the test
#: campaign's loops, checked there against products built independently), so a verdict
#: "grows" is never rounding; it moves unstable_from above the pattern's exact
#: threshold by about 1e-9 / (d rate / d ln K), ~3e-6 relative on the paper's HVE.
RATE_MARGIN = 1e-9
#: Both ends are bisected to a relative width of 1e-5 in K (the bracket itself is
#: usually orders of magnitude wider).
K_REL = 1e-5
#: The scans start at this fraction of their top (the constant-delay K_max): both ends
#: are searched from far below, so neither end is placed by the other.
SCAN_FLOOR = 1e-4
#: A pattern growing already at the scan's floor is followed down by decades to 1e-10
#: of the constant-delay worst case (below it: "unstable from at most this K").
DEEP_FLOOR = 1e-10
#: Points of each scan (geometric), before the bisection.
SCAN_POINTS = 24


def _range(loop: Any, delay_samples: Any, delay_s: Any) -> tuple[int, int, tuple | None]:
    if (delay_samples is None) == (delay_s is None):
        raise ModelError("jitter: give delay_samples=(lo, hi) (whole samples) or "
                         "delay_s=(lo, hi) (seconds), one of them")
    if delay_s is not None:
        try:
            lo_s, hi_s = ordered_pair(delay_s)
        except (TypeError, ValueError):
            raise ModelError(f"delay_s = {delay_s!r:.60}: allowed: (lo, hi), seconds") from None
        lo, hi = whole_delays(lo_s, hi_s, loop.period)
        return lo, hi, (float(lo_s), float(hi_s))
    try:
        lo, hi = ordered_pair(delay_samples)
    except (TypeError, ValueError):
        raise ModelError(f"delay_samples = {delay_samples!r}: allowed: (lo, hi), whole samples"
                         ) from None
    ok = all(isinstance(v, (int, np.integer)) or (isinstance(v, float) and v.is_integer())
             for v in (lo, hi))
    if not ok or not 0 <= lo <= hi <= MAX_DELAY_SAMPLES:
        raise ModelError(f"delay_samples = {delay_samples!r}: whole samples with "
                         f"0 <= lo <= hi <= {MAX_DELAY_SAMPLES}")
    return int(lo), int(hi), None


def _patterns_budget(budget: Any) -> int:
    """``budget`` as a whole number of patterns >= 1 (a whole float too), else ModelError."""
    try:
        ok = not isinstance(budget, (bool, complex, str)) and float(budget) >= 1 \
            and float(budget).is_integer()
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ModelError(f"budget = {budget!r:.40}: a whole number of patterns >= 1")
    return int(budget)


def jitter_cost(loop: Any, lo: int, hi: int, max_length: int, budget: int) -> Cost:
    """The estimated cost of :func:`jitter` (:mod:`hapstab.budget`): about 2 x 41
    evaluations (two scans of SCAN_POINTS and their bisections), each either every
    pattern's product and eigenvalues or a frequency response and a 2N-state QZ; the
    modes and one batch of products held.

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
    lo, hi : int
        The range, samples.
    max_length, budget : int
        As :func:`jitter`'s.

    Returns
    -------
    Cost
    """
    p = len(loop.controllers)
    N = float(5 * p + p * hi)                  # plant (<= 4 a port), registers, errors
    M = float(hi - lo + 1) ** p
    P = max(float(budget), M)
    per_pattern = max_length * 2 * N ** 3 / FLOPS + EIG_SECONDS_PER_N3 * N ** 3
    evals = 2 * SCAN_POINTS + 17
    seconds = evals * (P * per_pattern + 1000 * 8 * N ** 3 / FLOPS + eig_seconds(int(2 * N)))
    const = exact_points_cost("", int(2 * (hi - lo) + 1), int(N))
    return Cost(f"jitter: {int(M)} modes of a {int(N)}-state switched loop, up to {int(P)} "
                "periodic patterns", 8.0 * N * N * (3 * M + 3 * P) + const.memory_bytes,
                seconds + const.seconds)


def _bisect(test: Any, good: float, bad: float, found: Any) -> tuple[float, float, Any]:
    """Shrink [good, bad] (test(good) falsy, test(bad) = found truthy) to K_REL: (good,
    bad, test(bad))."""
    while bad / good - 1.0 > K_REL:
        mid = math.sqrt(good * bad)
        at = test(mid)
        if at:
            bad, found = mid, at
        else:
            good = mid
    return good, bad, found


def _stable_up_to(jm: JitterModes, k_nominal: float) -> dict[str, Any]:
    """The small-gain end: the last K of the scan (and its bisection) below which the
    margin held at every point."""
    N = jm.hi - jm.lo
    scan_K: list[float] = []
    scan_g: list[float] = []

    def fails(K: float) -> bool:
        A = jm.A0[jm.nominal] + K * jm.A1[jm.nominal]
        if np.abs(np.linalg.eigvals(A)).max() >= 1.0:
            g = math.inf
        else:
            g = small_gain(A, jm.B0 + K * jm.B1, jm.C, N)[0]
        scan_K.append(K)
        scan_g.append(g)
        return not g < 1.0

    if N == 0 or not math.isfinite(k_nominal) or k_nominal <= 0:
        return {"K": k_nominal if N == 0 else 0.0, "gain": 0.0 if N == 0 else math.nan,
                "scan_K": scan_K, "scan_g": scan_g}
    # the top stays below the nominal K_max, where the nominal loop has a pole on |z| = 1
    grid = np.geomspace(k_nominal * SCAN_FLOOR, k_nominal * (1.0 - K_REL), SCAN_POINTS)
    prev = 0.0
    for K in grid:
        if fails(float(K)):
            if prev == 0.0:
                return {"K": 0.0, "gain": scan_g[-1], "scan_K": scan_K, "scan_g": scan_g}
            good, _, _ = _bisect(fails, prev, float(K), True)
            break
        prev = float(K)
    else:
        good = prev
    gain = scan_g[scan_K.index(good)]
    return {"K": good, "gain": gain, "scan_K": scan_K, "scan_g": scan_g}


def _unstable_from(jm: JitterModes, pats: list, k_const: float,
                   worst: tuple[int, ...]) -> dict[str, Any]:
    """The pattern end: the smallest K found with a pattern growing, else the constant
    worst case (exact core)."""
    index = {d: i for i, d in enumerate(jm.delays)}
    scan_K: list[float] = []
    scan_r: list[float] = []

    def grows(K: float) -> tuple | None:
        rates = pattern_rates(jm.at(K), index, pats)
        i = int(np.argmax(rates))
        scan_K.append(K)
        scan_r.append(float(rates[i]))
        return (pats[i], float(rates[i])) if rates[i] >= 1.0 + RATE_MARGIN else None

    grid = np.geomspace(k_const * SCAN_FLOOR, k_const * (1.0 - K_REL), SCAN_POINTS)
    prev = 0.0
    for K in grid:
        hit = grows(float(K))
        if hit:
            bad, (pattern, rate) = float(K), hit
            while prev == 0.0 and bad > k_const * DEEP_FLOOR:   # unstable at the floor: lower
                below = grows(bad / 10)
                if not below:
                    prev = bad / 10
                    break
                bad, (pattern, rate) = bad / 10, below
            if prev > 0.0:
                _, bad, (pattern, rate) = _bisect(grows, prev, bad, (pattern, rate))
            return {"K": bad, "pattern": pattern, "rate": rate, "constant": False,
                    "scan_K": scan_K, "scan_r": scan_r}
        prev = float(K)
    return {"K": k_const, "pattern": (worst,), "rate": 1.0, "constant": True,
            "scan_K": scan_K, "scan_r": scan_r}


def jitter(loop: Any, delay_samples: Any = None, *, delay_s: Any = None, max_length: int = 6,
           budget: int = MAX_PATTERNS) -> JitterResult:
    """A bracket on K under a time-varying delay: stable for every admissible delay
    sequence up to ``stable_up_to``, unstable for an explicit pattern from ``unstable_from``.

    The model (:mod:`hapstab.analysis.network.jitter_modes`): at sample k the controller
    uses the newest sample of each networked position that has arrived, x[k - d_k]; each
    packet's transport delay is any whole number of samples in [lo, hi], so d_k is in
    [lo, hi] and d_{k+1} <= d_k + 1 (the age grows by at most one per sample: the
    controller may re-use the sample it used, never an older one; it may fall by any
    amount). Every such sequence is possible. For PEB each direction's delay varies
    independently. The loop is the switched linear system x[k+1] = A_{d_k} x[k] on a state
    holding hi past positions.

    ``stable_up_to``: the discrete-time jitter margin (small gain, Kao & Lincoln 2004;
    Cervin et al. 2004): with the nominal delay lo and the extra delay delta_k in
    {0, ..., N}, N = hi - lo, the loop is stable for every delay sequence if the nominal
    loop is stable and N |e^{jw} - 1| |G C / (1 + G C e^{-j w lo})| < 1 at every w (PEB:
    N ||D M D^-1||_inf < 1, :mod:`.jitter_gain`). It holds for arbitrary switching of
    delta_k, so it is sufficient, not necessary. ``unstable_from``: bisection in K on
    "some admissible periodic pattern of length <= max_length has rho(product)^(1/p) >=
    1 + RATE_MARGIN" (Jungers 2009's lower bound of the joint spectral radius), the
    pattern reported; capped by the constant-delay worst case (the exact core's certified
    K_max over [lo, hi]).

    Parameters
    ----------
    loop : HapticLoop or TeleoperationLoop
        Spring-damper controllers; its own delay is replaced by the range.
    delay_samples : (int, int)
        (lo, hi), whole samples.
    delay_s : (float, float), optional
        Instead: transport delays in s, converted to whole samples at a receiver that acts
        at the sampling instants, (ceil(lo / T), ceil(hi / T))
        (:func:`~hapstab.analysis.network.delay_range.whole_delays`).
    max_length : int
        The longest pattern enumerated, samples.
    budget : int
        The most patterns (lengths stop before the total exceeds it).

    Returns
    -------
    JitterResult

    References
    ----------
    C.-Y. Kao and B. Lincoln, Automatica 40(8), 2004. A. Cervin, B. Lincoln, J. Eker,
    K.-E. Arzen, G. Buttazzo, RTCSA 2004. R. M. Jungers, *The Joint Spectral Radius*,
    Springer 2009.
    """
    require_loop(loop)
    if not (isinstance(max_length, int) and 1 <= max_length <= 12):
        raise ModelError(f"max_length = {max_length!r}: a whole number of samples, 1 to 12")
    budget = _patterns_budget(budget)
    t0 = time.perf_counter()
    lo, hi, range_s = _range(loop, delay_samples, delay_s)
    check(jitter_cost(loop, lo, hi, max_length, budget))
    jm = jitter_modes(loop, lo, hi)
    const = delay_range_critical_stiffness(loop, lo, hi, seconds=False)
    if not math.isfinite(const.critical_stiffness) or const.critical_stiffness <= 0:
        raise AnalysisError(f"jitter: the constant-delay K_max over {lo}..{hi} is "
                            f"{const.critical_stiffness:g} N/m; the bracket needs a finite, "
                            "positive one")
    D = const.worst_delay_samples
    worst = (D // 2, D - D // 2) if const.round_trip else (D,)
    pats = patterns(lo, hi, len(jm.terms), max_length, budget)
    up = _stable_up_to(jm, const.kmax[0])
    un = _unstable_from(jm, pats, const.critical_stiffness, worst)
    return JitterResult(
        stable_up_to=up["K"], unstable_from=un["K"], pattern=un["pattern"],
        pattern_rate=un["rate"], pattern_is_constant=un["constant"],
        small_gain=up["gain"], constant_worst=const.critical_stiffness, constant_worst_delay=D,
        nominal_kmax=const.kmax[0], delay_samples=(lo, hi), range_s=range_s,
        period=jm.period, terms=jm.terms, patterns_checked=len(pats),
        max_length=max(len(q) for q in pats), order=jm.order,
        scan_K=np.array(un["scan_K"]), scan_rate=np.array(un["scan_r"]),
        gain_K=np.array(up["scan_K"]), gain=np.array(up["scan_g"]),
        seconds=time.perf_counter() - t0, loop_dict=loop.to_dict())
