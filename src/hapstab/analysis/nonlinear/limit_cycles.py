"""Limit cycles of the haptic loop from encoder quantisation and Coulomb friction,
predicted by describing functions and refined by harmonic balance.

The loop (:class:`~hapstab.models.HapticLoop`, spring-damper H(z), n whole samples of
delay): the device and its operator, ZOH-discretised exactly by the engine
(:mod:`hapstab.engine.zoh`), the encoder's quantiser q on the sampled position
(:mod:`hapstab.analysis.nonlinear.harmonic`), and Coulomb friction f_c sign(v) on the port's
velocity between the samples. A periodic motion ``x = x0 + A sin(w t) + ...`` balances
harmonic by harmonic,

    X_k + C(e^{jkwT}) Q_k + P(jkw) F_k = 0,      k x0 + K q0 + f0 = 0,

with C = P_zoh z^-n H the loop the quantiser sees (exact at the samples), P the port's
continuous response (how friction, a continuous force, moves it), Q_k, F_k the harmonics
of what the encoder reads and of the friction force, k the operator's spring.

1. **Describing function** (the first harmonic only, Diolaiti et al.'s method): the
   quantiser is its dual-input describing function N(A, x0) (the mean x0 from the DC
   balance: a floor encoder's cycles sit about Δ/2 off centre), friction the relay's
   ``4 f_c/(pi A w)``, a damper c_eq. So ``1 + N C(e^{jwT}) + c_eq jw P(jw) = 0``: with
   quantisation alone, ``N(A) = 1/|C|`` at a phase crossover of C (N <= 4/pi: a cycle
   needs a gain margin below 4/pi = 1.27 there); with friction alone, the loop with
   damping b + c_eq is marginal. Every (A, w) solving it on a scan of amplitudes is found,
   and Loeb's criterion (U_A V_w - U_w V_A > 0, the nonlinearity frozen in w, friction as
   a damper) says whether it is stable (an attractor) or unstable (a threshold).
2. **Harmonic balance** with ``harmonics`` harmonics (default 15) refines each: the
   quantiser's output is a staircase with strong harmonics (a 3-level wave at A ~ Δ has a
   third harmonic of 20 %), which shift its switching instants and so the fundamental.
   On the paper's delayed HVE (n = 10) at 0.8 K_max the describing function gives
   0.786 Δ at 1.3315 Hz, harmonic balance 0.912 Δ at 1.2876 Hz, the simulator 0.925 Δ
   at 1.2837 Hz. The describing function's near misses (|F| < :data:`NEAR_MISS`) are
   tried too: harmonics can close them (a cycle the first harmonic alone misses). A
   refined root keeps its describing function's Loeb verdict; a closed near miss gets
   Loeb's criterion on the balance itself (:func:`~hapstab.analysis.nonlinear.harmonic.loeb_stable`).
3. **Rest** (:func:`~hapstab.analysis.nonlinear.limit_cycle_loop.rests`): with an encoder the device
   may have no rest strictly inside a step (the operator's spring relaxed just below a
   floor encoder's line: it chatters across it), rest only on a line, or, free of any
   spring and with f_c < K Δ/2, coast within a step and bounce across its lines. These
   motions are not harmonic-balance cycles; the verdict says ``chatter`` or
   ``undecided`` rather than promising none.

What it neglects, and when to trust it (each cycle says so, ``trusted`` and ``notes``):

* the quantiser sees samples, taken here as a continuous sine: needs many samples per
  period (>= :data:`SAMPLES_MIN`); near the Nyquist rate (no delay: the sampled spring's
  crossing is at z = -1) no prediction is made;
* friction is a relay on the continuous velocity, the held force's ripple between the
  samples and its aliases neglected (relative size (w T)^2); and pure sliding: where the
  device would stick at a reversal (the force it would need, m a, is below f_c there),
  the describing function does not describe stick-slip, and the cycle says so;
* harmonics beyond ``harmonics`` (they change the refined amplitude by < 1.5 % from 15
  to 31 in the cases tried).

The simulator (:func:`hapstab.simulate` with ``resolution``, ``quantizer`` and a device's
``coulomb_friction``) checks it, ``tests/nonlinear/test_limit_cycles.py`` (see the README for the
campaign's numbers).

References
----------
N. Diolaiti, G. Niemeyer, F. Barbagli and J. K. Salisbury, "Stability of haptic
rendering: discretization, quantization, time delay, and Coulomb effects", IEEE Trans.
Robotics 22(2):256-268, 2006 (describing-function analysis of quantisation and Coulomb
friction in haptic rendering; its text was not retrievable here, so nothing above is
copied from its figures). A. Gelb and W. E. Vander Velde, *Multiple-Input Describing
Functions and Nonlinear System Design*, 1968; J.-J. E. Slotine and W. Li, *Applied
Nonlinear Control*, 1991, ch. 5 (Loeb's criterion).
"""

from __future__ import annotations

import math

import numpy as np

from hapstab.analysis.nonlinear.harmonic import (
    OUTSIDE,
    Balance,
    loeb_stable,
    quantizer_describing_function,
    solve_balance,
    waveform,
)
from hapstab.analysis.nonlinear.limit_cycle_loop import (
    STEPS_MAX,
    check_loop,
    crossovers,
    curves,
    loop_parts,
    rests,
)
from hapstab.analysis.nonlinear.limit_cycle_results import LimitCycleResult, PredictedCycle
from hapstab.analysis.nonlinear.nonlinear_passivity import coulomb_friction_of, resolution_of
from hapstab.errors import ModelError
from hapstab.models.loops import HapticLoop
from hapstab.plotting.limit_cycles import NEAR_MISS_NOTE

__all__ = ["limit_cycles", "SAMPLES_MIN"]

#: A local minimum of |F| (the first-harmonic balance) below this, with no root near it,
#: is tried as a start of the harmonic balance: the harmonics the describing function
#: leaves out may close the gap (e.g. |F| = 0.009 at its closest, a cycle of 0.86 Δ with
#: harmonics, 0.89 Δ simulated, for the paper's delayed HVE at 0.9 K_max, f_c = 1e-5 N).
NEAR_MISS = 0.1
#: At most this many near misses are tried (the closest first): each costs a harmonic
#: balance.
MISSES = 4
#: A refined cycle is the describing function's root's when its fundamental and frequency
#: are within this fraction of the root's (harmonics moved them by at most 16 % in the
#: cases tried; an unstable root's balance that runs off lands on a neighbour 40 % away).
NEAR = 0.25
#: A cycle closed from a near miss keeps the near miss's frequency to this fraction (2.4 %
#: in the documented friction case; a balance that runs off to a 34 % slower motion found
#: a cycle the simulator does not show).
NEAR_W = 0.1
#: Newton's steps from a scan's root stay below this factor times the largest amplitude
#: scanned (the root lies between two of its rows; small amplitudes cost nothing, and a
#: step through them may come back to the root).
WIDEN = 4.0
#: Two cycles within this fraction in amplitude and frequency are one.
SAME = 0.01

#: A cycle with fewer samples per period is outside the describing function's range:
#: the quantiser sees too few samples of the sine for the continuous describing function.
SAMPLES_MIN = 16
#: Amplitudes scanned per decade.
PER_DECADE = 120
#: The describing-function roots are refined by harmonic balance in these steps
#: (continuation in the number of harmonics).
STEPS = (1, 3, 7)
#: A harmonic balance converged when its largest equation is below this, relative to
#: the cycle's amplitude (the Fourier sums are exact to ~1e-13; the hybrid method stops
#: at ~1e-12 of its scale).
CONVERGED = 1e-8


def _mean(bal: Balance, A: float) -> float:
    """The cycle's mean x0 from the first-harmonic DC balance
    ``k (x0 - rest) + K q0(x0, A) = 0`` (increasing in x0: one root; 0 by symmetry with a
    nearest quantiser and the rest at 0)."""
    from scipy.optimize import brentq

    d, k, K, r = bal.resolution_m, bal.spring_N_per_m, bal.stiffness_N_per_m, bal.rest_m
    if d == 0:
        return k * r / (k + K)
    if bal.quantizer == "nearest" and r == 0:
        return 0.0

    def dc(x0: float) -> float:
        return k * (x0 - r) + K * quantizer_describing_function(A, x0, d, bal.quantizer)[1]

    lo, hi = -A - 2 * d - abs(r), A + 2 * d + abs(r)
    return float(brentq(dc, lo, hi, xtol=1e-12 * d)) if dc(lo) < 0 < dc(hi) else 0.0  # Δ-relative


def _gains(bal: Balance, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """N (the quantiser's, 1 without), the mean x0 and the relay's ``4 f_c/(pi A)``."""
    x0 = np.array([_mean(bal, a) for a in A])
    if bal.resolution_m:
        N = np.array([quantizer_describing_function(a, m, bal.resolution_m, bal.quantizer)[0]
                      for a, m in zip(A, x0, strict=True)])
    else:
        N = np.ones_like(A)
    return N, x0, 4 * bal.friction_N / (math.pi * A)


def _F(bal: Balance, A: float, theta: float) -> complex:
    """The first-harmonic characteristic function ``1 + N C + j (4 f_c/(pi A)) P``."""
    N, _, cf = _gains(bal, np.array([A]))
    return complex(1 + N[0] * bal.controller(np.array([theta]))[0]
                   + 1j * cf[0] * bal.plant(np.array([theta]))[0])


def _scan(bal: Balance, amps: np.ndarray, theta: np.ndarray, gains: tuple[np.ndarray, ...]
          ) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
    """Roots of the first-harmonic balance F = 0, and its near misses. On each row of
    amplitudes: where Im F changes sign along theta (Re F interpolated there), and the
    local minima of |F| below :data:`NEAR_MISS`. A root lies between two rows whose matched
    crossings have Re F of opposite signs (refined by Newton in (log A, theta)); a near
    miss is a row minimum no lower in the neighbouring rows (harmonics may close it).
    ``gains``: :func:`_gains` on ``amps``."""
    N, _, cf = gains                  # _gains(bal, amps)
    C, P = bal.controller(theta), bal.plant(theta)
    rows, mins = [], []
    for i in range(amps.size):
        F = 1 + N[i] * C + 1j * cf[i] * P
        j = np.flatnonzero(np.sign(F.imag[:-1]) * np.sign(F.imag[1:]) < 0)
        w = F.imag[j] / (F.imag[j] - F.imag[j + 1])
        rows.append((j, F.real[j] + w * (F.real[j + 1] - F.real[j])))
        a = np.abs(F)
        k = np.flatnonzero((a[1:-1] <= a[:-2]) & (a[1:-1] <= a[2:]) & (a[1:-1] < NEAR_MISS)) + 1
        mins.append((k, a[k]))
    found: list[tuple[float, float]] = []
    for i in range(amps.size - 1):
        (j0, r0), (j1, r1) = rows[i], rows[i + 1]
        if not (j0.size and j1.size):
            continue
        # each crossing's match on the next row: the first one within 2 grid points
        # (j1 is sorted), in one pass instead of one search per crossing
        b = np.minimum(np.searchsorted(j1, j0 - 2), j1.size - 1)
        hit = (np.abs(j1[b] - j0) <= 2) & (r0 * r1[b] < 0)
        for a in np.flatnonzero(hit):
            found += _root(bal, math.sqrt(amps[i] * amps[i + 1]), float(theta[j0[a]]),
                           float(amps[-1]))
    roots = _unique(found)
    near = sorted((float(v), float(amps[i]), float(theta[k])) for i in range(amps.size)
                  for k, v in zip(*mins[i], strict=True)
                  if all(not np.any((np.abs(mins[r][0] - k) <= 2) & (mins[r][1] < v))
                         for r in (i - 1, i + 1) if 0 <= r < amps.size)
                  and not any(abs(amps[i] / A - 1) < NEAR and abs(theta[k] / t - 1) < NEAR
                              for A, t in roots))
    return roots, [(A, t) for _, A, t in near[:MISSES]]


def _root(bal: Balance, A: float, theta: float, top: float) -> list[tuple[float, float]]:
    """Newton (MINPACK's hybrid method) on F(A, theta) = 0 in (log A, theta), from a root
    bracketed by the scan: a step above :data:`WIDEN` times the largest amplitude scanned
    (``top``), or to A = 0, is pushed back."""
    from scipy.optimize import root

    hi = top * WIDEN

    def eq(p: np.ndarray) -> list[float]:
        A = math.exp(p[0]) if p[0] < 700 else math.inf
        if not 0 < A <= hi:
            # exp(log A) underflowed (the describing function divides by A), or far above
            # the scan: a root there was not asked for, and the quantiser's describing
            # function at 1e10 steps would need arrays of 200 GB
            return [OUTSIDE, OUTSIDE]
        f = _F(bal, A, p[1])
        return [f.real, f.imag]

    sol = root(eq, [math.log(A), theta], method="hybr")
    return [(math.exp(sol.x[0]), float(sol.x[1]))] if sol.success and sol.x[1] > 0 else []


def _unique(found: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for A, th in sorted(found):
        if not any(abs(A - a) <= 1e-6 * a and abs(th - t) <= 1e-6 * t for a, t in out):  # same root
            out.append((A, th))
    return out


def _loeb(bal: Balance, A: float, theta: float, T: float) -> bool:
    """Loeb's criterion, U_A V_w - U_w V_A > 0: the cycle is stable. The A-derivative at
    fixed w; the w-derivative of the linear parts with the describing functions frozen
    (friction as its equivalent damper ``4 f_c/(pi A w)``)."""
    hA, ht = 1e-5 * A, 1e-6 * theta   # central differences (relative steps: F is smooth here)
    FA = (_F(bal, A + hA, theta) - _F(bal, A - hA, theta)) / (2 * hA)
    N, _, cf = _gains(bal, np.array([A]))

    def lin(t: float) -> complex:
        tt = np.array([t])
        damper = cf[0] / theta * t          # c_eq j w P(w), c_eq frozen at the cycle's w
        return complex(N[0] * bal.controller(tt)[0] + 1j * damper * bal.plant(tt)[0])

    Fw = (lin(theta + ht) - lin(theta - ht)) / (2 * ht) * T
    return FA.real * Fw.imag - Fw.real * FA.imag > 0


def _refine(bal: Balance, A: float, theta: float, x0: float, H: int,
            steps: tuple[int, ...] = STEPS) -> tuple[bool, float, float, np.ndarray]:
    """Harmonic balance with H harmonics, continued from the describing function's root
    through ``steps`` harmonics."""
    X = np.array([A], complex)
    th, m, ok = theta, x0, True
    for h in [s for s in steps if s < H] + [H]:
        X = np.concatenate([X, np.zeros(h - X.size, complex)])
        ok, th, m, X, err = solve_balance(bal, th, m, X, A)
        ok = ok and err < CONVERGED
        if not ok:
            break
    return ok, th, m, X


def _stick(bal: Balance, mass: float, X: np.ndarray, theta: float, T: float) -> float:
    """The least |m a| at the velocity's reversals (N): the force the device needs there to
    slide through; below f_c it would stick instead."""
    phi = np.linspace(0, 2 * math.pi, 4096, endpoint=False)
    v = waveform(0.0, X, phi, 1)
    i = np.flatnonzero(np.sign(v) != np.sign(np.roll(v, -1)))
    if i.size == 0:
        return math.inf
    w = theta / T
    acc = waveform(0.0, X, phi[i], 2) * w * w
    return float(np.min(np.abs(mass * acc)))


def _grids(bal: Balance, n: int, max_amplitude_m: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Amplitudes (log-spaced, :data:`PER_DECADE`) and angles (log-spaced low, linear
    through the delay's phase turns, up to the Nyquist angle pi)."""
    lo, hi = math.inf, 0.0
    if bal.friction_N:
        scale = bal.friction_N / bal.stiffness_N_per_m      # where friction matches the spring
        lo, hi = 1e-3 * scale, 1e5 * scale
    if bal.resolution_m:                 # the quantiser's search stops at 64 steps
        lo, hi = min(lo, bal.resolution_m / 20), 64 * bal.resolution_m
    if max_amplitude_m is not None:
        hi = max(lo * 10, float(max_amplitude_m))
    amps = np.geomspace(lo, hi, max(2, round(PER_DECADE * math.log10(hi / lo))))
    # from 1e-7 rad per sample (a period of 6e7 samples: slower than any loop hapstab
    # models) up to the Nyquist angle
    theta = np.unique(np.concatenate([np.geomspace(1e-7, math.pi, 2000),
                                      np.linspace(0, math.pi, 64 * (n + 2) + 1)[1:]]))
    return amps, theta


def _nyquist(bal: Balance, amps: np.ndarray, N: np.ndarray) -> list[tuple[float, float]]:
    """Roots at theta = pi, where C is real (z = -1) and friction is absent: the scan's sign
    changes of Im F cannot see them. ``N``: the quantiser's gain on ``amps``."""
    from scipy.optimize import brentq

    if bal.friction_N:
        return []
    c = complex(bal.controller(np.array([math.pi]))[0])
    f = 1 + N * c.real
    out = []
    for i in np.flatnonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0):
        A = brentq(lambda a: _F(bal, a, math.pi).real, amps[i], amps[i + 1])
        out.append((float(A), math.pi))
    return out


def _cycle(bal: Balance, loop: HapticLoop, mass: float, A: float, theta: float,
           H: int, root: bool = True) -> PredictedCycle | None:
    """One describing-function root (or near miss, ``root=False``): harmonic-balance
    refinement, Loeb's criterion, and what limits trust in it (None: a near miss that
    the harmonic balance does not close)."""
    T = loop.period
    x0 = _mean(bal, A)
    spp = 2 * math.pi / theta
    notes = []
    ok, th, m, X = False, theta, x0, np.array([A], complex)
    if spp < SAMPLES_MIN:
        notes.append(f"{spp:.3g} samples per period (< {SAMPLES_MIN}): outside the describing "
                     "function's range (the quantiser sees too few samples of the sine)")
    else:
        ok, th, m, X = _refine(bal, A, theta, x0, H, STEPS if root else STEPS[1:])
        # a balance that ran off to another root (an unstable one's neighbour) is not its;
        # from a near miss, the frequency must stay close (the harmonics close a gap in
        # amplitude, not a different oscillation)
        near_A, near_w = (NEAR, NEAR) if root else (2 * NEAR, NEAR_W)
        ok = ok and abs(abs(X[0]) - A) <= near_A * A and abs(th - theta) <= near_w * theta
        if not ok:
            if not root:
                return None
            notes.append(f"harmonic balance with {H} harmonics did not converge near the "
                         "describing function's root: its values are the describing function's")
            th, m, X = theta, x0, np.array([A], complex)
    if root:                             # Loeb on the describing function's root
        stable = _loeb(bal, A, theta, T) if theta < math.pi else False
    else:                                # on the balance (no first-harmonic root)
        stable = loeb_stable(bal, float(X[0].real), th, m, X, T)
    if not root:
        notes_df = f"{NEAR_MISS_NOTE} (its closest approach), harmonics do"
    wave = waveform(m, X, np.linspace(0, 2 * math.pi, 4096, endpoint=False))
    if bal.friction_N:
        least = _stick(bal, mass, X, th, T)
        if least <= bal.friction_N:
            notes.append(f"the device would stick at a reversal (it needs |m a| = {least:.3g} N "
                         f"there, friction holds up to {bal.friction_N:g} N): stick-slip, which "
                         "the describing function (pure sliding) does not describe")
    return PredictedCycle(float(np.ptp(wave) / 2), float(th / (2 * math.pi * T)), float(m),
                          bool(stable), float(abs(X[0])), float(A),
                          float(theta / (2 * math.pi * T)), float(spp), bool(ok),
                          not notes, "; ".join(notes if root else [notes_df, *notes]))


def _distinct(cycles: list[PredictedCycle | None]) -> tuple[PredictedCycle, ...]:
    """The cycles by amplitude, one of each (two within 1 % in amplitude and frequency are
    one: a near miss the balance closed onto a root's cycle)."""
    out: list[PredictedCycle] = []
    for c in sorted((c for c in cycles if c is not None), key=lambda c: not c.refined):
        if not any(abs(c.amplitude_m - o.amplitude_m) <= SAME * o.amplitude_m
                   and abs(c.frequency_hz - o.frequency_hz) <= SAME * o.frequency_hz
                   for o in out):
            out.append(c)
    return tuple(sorted(out, key=lambda c: c.amplitude_m))


#: The farthest rest position from the encoder's zero, in encoder steps: a 32-bit
#: encoder's count range. Beyond it the lines near the rest are not representable apart
#: (2**31 steps of 1e-9 m and more lose the step in double precision only at 2**52).
REST_STEPS_MAX = 2.0 ** 31
#: ... and without an encoder, in metres: a haptic device moves centimetres; at 1e6 m
#: the friction's balance still has 1e-10 m of double precision left.
REST_MAX_M = 1e6


def _rest(rest_position_m: float, delta: float) -> float:
    """The rest position, refused (naming it) where the model degenerates."""
    from hapstab.errors import check_real

    r = check_real("rest_position_m", rest_position_m)
    bound = REST_STEPS_MAX * delta if delta else REST_MAX_M
    if abs(r) > bound:
        what = (f"{REST_STEPS_MAX:.0f} encoder steps of {delta:g} m" if delta else "metres")
        raise ModelError(f"rest_position_m = {r:g}: at most {bound:g} from 0 in size ({what}); "
                         "farther, the balance's positions near the rest lose their precision")
    return r


def limit_cycles(loop: HapticLoop, *, resolution_m: float | None = None,
                 quantizer: str = "floor", coulomb_friction_N: float | None = None,
                 rest_position_m: float = 0.0, harmonics: int = 15,
                 max_amplitude_m: float | None = None) -> LimitCycleResult:
    """Limit cycles of the haptic loop from quantisation and Coulomb friction (see the module).

    Parameters
    ----------
    loop : HapticLoop
        With a :class:`~hapstab.models.SpringDamper` (K > 0, any B) and whole samples of
        delay.
    resolution_m : float, optional
        Encoder resolution Δ in m (default none).
    quantizer : {"floor", "nearest"}
        The encoder's reading, as :func:`hapstab.simulate`'s.
    coulomb_friction_N : float, optional
        f_c in N; default the device's ``coulomb_friction`` (0 if it has none).
    rest_position_m : float
        Where the operator's spring is relaxed (m), as :func:`hapstab.simulate`'s
        ``rest_position``; the virtual spring pulls to 0.
    harmonics : int
        Harmonics of the refining harmonic balance (1: the describing function alone).
    max_amplitude_m : float, optional
        Largest amplitude searched (m); default 64 Δ with quantisation, 1e5 f_c/K with
        friction alone.

    Returns
    -------
    LimitCycleResult
        ``cycles`` (each with amplitude, frequency, mean, stable / unstable, trust), the
        existence conditions in ``conditions`` and ``reason``.

    Raises
    ------
    AnalysisError
        Not a haptic loop with a SpringDamper and K > 0, a fractional delay, or neither
        quantisation nor friction.
    ModelError
        A bad resolution, friction, quantizer or harmonics.

    References
    ----------
    Diolaiti et al. 2006; Gelb and Vander Velde 1968; Slotine and Li 1991, ch. 5.
    """
    fc, delta = coulomb_friction_of(loop, coulomb_friction_N), resolution_of(resolution_m)
    loop = check_loop(loop, delta, fc, quantizer, harmonics)
    if max_amplitude_m is not None:
        from hapstab.errors import check_real

        max_amplitude_m = check_real("max_amplitude_m", max_amplitude_m, positive=True)
        if delta and max_amplitude_m > STEPS_MAX * delta:
            raise ModelError(f"max_amplitude_m = {max_amplitude_m:g}: at most {STEPS_MAX:g} "
                             f"encoder steps ({STEPS_MAX * delta:g} m): the quantiser's every "
                             "line is a term of the balance")
    C, P, mass, k = loop_parts(loop)
    K = loop.controller.stiffness                       # type: ignore[union-attr]
    from hapstab import budget
    from hapstab.analysis.exact.core import stability
    from hapstab.analysis.methods import order_estimate
    from hapstab.errors import check_real

    # the closed-loop model's budget (hapstab.build's) refuses a long delay chain at once,
    # before the scan's work (whose grid grows with the delay; stability() alone no longer
    # does: it answers long delays from the certified count)
    budget.check(budget.build_cost(1, order_estimate(loop, loop.delay_in_samples)))
    linear = stability(loop).verdict
    bal = Balance(C, P, k, K, delta, quantizer, fc, _rest(rest_position_m, delta))
    amps, theta = _grids(bal, loop.delay_samples, max_amplitude_m)
    gains = _gains(bal, amps)          # the describing functions on the scan's amplitudes
    N = gains[0]
    roots, near = _scan(bal, amps, theta, gains)
    H = int(harmonics)
    cycles = _distinct([_cycle(bal, loop, mass, A, th, H) for A, th in roots + _nyquist(bal, amps, N)]
                       + ([_cycle(bal, loop, mass, A, th, H, root=False) for A, th in near]
                          if H > 1 else []))
    return LimitCycleResult.build(loop, delta, quantizer, fc, int(harmonics), cycles, linear,
                                  crossovers(C, theta, loop.period), float(N.max()),
                                  (float(amps[0]), float(amps[-1])), rests(bal),
                                  float(bal.rest_m), curves(bal, amps, N, theta))


