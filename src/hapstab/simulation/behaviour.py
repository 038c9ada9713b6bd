"""What a nonlinear run does — settles, oscillates in a limit cycle, grows, drifts —
read from its trajectory.

A run with a unilateral wall, actuator saturation or encoder quantisation is not a
linear recurrence, so no fitted pole describes it. What the trajectory shows is
the *envelope* of its motion: the peak-to-peak position over successive stretches
of the second half of the run (whole cycles when it oscillates). A clear trend
gives ``grows`` or ``settles`` with the envelope's rate; a flat envelope over
enough cycles is a ``limit cycle`` with its amplitude and period; anything else
is ``undecided``, with a run length that would tell.

Two facts the trajectory cannot show are taken from the model, and said so:

* ``linear_rate``: how fast the linearised loop (wall always in contact, no
  saturation, no quantisation) grows. A flat envelope is only called a limit
  cycle if growth at that rate would have shown in the window.
* ``bound``: a reason the run cannot grow (a saturated actuator on devices that
  are stable on their own; quantisation of a stable linear loop). It makes the
  verdict *bounded* whatever the window shows.

References
----------
The paper, Section 5 (boundedness of the simulated outputs); for limit cycles
from quantisation and Coulomb friction in haptic loops, N. Diolaiti et al.,
"Stability of haptic rendering: discretization, quantization, time delay, and
Coulomb effects", IEEE Trans. Robotics 22(2), 2006.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from hapstab.simulation.growth import BoundednessVerdict
from hapstab.tolerances import DIVISOR_FLOOR

__all__ = ["assess_nonlinear"]

#: Motion below this fraction of the run's own peak-to-peak is rounding: settled.
#: (positions carry ~1e-16 relative rounding per step, and a free position out of
#: contact creeps by an ulp per sample; 1e-9 leaves room for 1e7 samples of it)
SETTLED_REL = 1e-9
#: Cycles the window must hold before a flat envelope is named a limit cycle:
#: one cycle compared with the next says little; eight show a trend of a few %.
CYCLES_MIN = 8
#: The envelope changing by less than this factor across the window is flat.
FLAT = 1.25
#: A change by at least this factor, mostly in one direction, is a trend ...
DECISIVE = 2.0
#: ... and by this factor a clear one (high confidence).
CLEAR = 10.0
#: The fraction of successive stretches that must move in the trend's direction.
MONOTONE = 0.75
#: An envelope slope beyond this many standard errors is a trend, not scatter.
TREND_SE = 3.0
#: Without enough cycles, a rise by this factor over the window is a runaway (a slow
#: excursion, one part of a cycle, changes its peak-to-peak by far less: x130 seen
#: for a 0.15 Hz force on a 5 s run)
RUNAWAY = 1e6
#: A drift moves at least this fraction of the run's largest |x| per stretch (less
#: is a creep of a few ulps per sample, not a motion)
DRIFT_REL = 1e-6
#: Stretches the window is cut into (whole cycles each when it oscillates).
STRETCHES = 8


@dataclass(frozen=True)
class Envelope:
    """Peak-to-peak position over successive stretches of the window."""

    amps: np.ndarray        # (J,) m
    centres: np.ndarray     # (J,) s
    cycles: int             # whole cycles of the dominant port in the window
    period_s: float | None
    window_s: float
    monotone: bool          # the busiest port moved one way only over the window
    steps: np.ndarray       # (J,) its net displacement over each stretch, m
    scale: float            # largest |x| of the run, m

    @property
    def ratio(self) -> float:
        a0, a1 = self.amps[0], self.amps[-1]
        return a1 / a0 if a0 > 0 else (math.inf if a1 > 0 else 1.0)

    def fraction(self, up: bool) -> float:
        """Fraction of successive stretches that grow (``up``) or shrink."""
        a = self.amps
        steps = a[1:] > a[:-1] if up else a[1:] < a[:-1]
        return float(np.mean(steps)) if steps.size else 0.0

    def rate(self, part: slice = slice(None)) -> tuple[float, float]:
        """Least-squares slope of log amplitude against time (1/s) and its standard
        error, over all stretches or ``part`` of them."""
        amps, centres = self.amps[part], self.centres[part]
        ok = amps > 0
        if ok.sum() < 3:
            return 0.0, math.inf
        t, y = centres[ok], np.log(amps[ok])
        A = np.column_stack([t, np.ones_like(t)])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        res = y - A @ coef
        dof = max(1, t.size - 2)
        se = math.sqrt(float(res @ res) / dof
                       / max(float(((t - t.mean()) ** 2).sum()), DIVISOR_FLOOR))
        return float(coef[0]), se


def _envelope(X: np.ndarray, period: float, scale: float) -> Envelope:
    """Cut the window X (W+1, p) into stretches; whole cycles of its busiest port."""
    W = X.shape[0] - 1
    j = int(np.argmax(np.ptp(X, axis=0)))
    y = X[:, j] - X[:, j].mean()
    up = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
    cycles = max(0, up.size - 1)
    P = (up[-1] - up[0]) / cycles * period if cycles else None
    if cycles >= CYCLES_MIN:
        cut = up[np.round(np.linspace(0, cycles, min(STRETCHES, cycles) + 1)).astype(int)]
    else:
        cut = np.round(np.linspace(0, W, STRETCHES + 1)).astype(int)
    amps = np.array([np.ptp(X[a:b + 1], axis=0).max() for a, b in pairwise(cut)])
    centres = (cut[:-1] + cut[1:]) / 2 * period
    dy = np.diff(y)
    monotone = bool(np.any(dy)) and (bool(np.all(dy >= 0)) or bool(np.all(dy <= 0)))
    steps = np.array([X[b, j] - X[a, j] for a, b in pairwise(cut)])
    return Envelope(amps, centres, cycles, P, W * period, monotone, steps, scale)


def _verdict(verdict: str, behaviour: str, conf: str, basis: str, env: Envelope | None,
             reason: str, **kw: float | None) -> BoundednessVerdict:
    rate, se = env.rate() if env is not None else (-math.inf, 0.0)
    ratio = env.ratio if env is not None else 1.0
    return BoundednessVerdict(verdict, rate, se, conf, basis, ratio, 0.0, reason, behaviour,
                              judged_on="the trajectory's envelope", **kw)


def _hint(env: Envelope, duration_s: float, linear_rate: float | None) -> float:
    """A run length whose second half would tell: growth at the linearised rate by
    a factor CLEAR, CYCLES_MIN cycles, and at least twice this run."""
    need = 2.0 * duration_s
    if linear_rate is not None and 0 < linear_rate < math.inf:
        need = max(need, 2.0 * math.log(CLEAR) / linear_rate)
    if env.period_s:
        need = max(need, 2.0 * 2 * CYCLES_MIN * env.period_s)
    return float(need)


def assess_nonlinear(states: np.ndarray, positions: np.ndarray, period: float, *,
                     linear_rate: float | None = None, bound: str | None = None,
                     can_drift: bool = False) -> BoundednessVerdict:
    """Settles, limit cycle, grows, drifts or undecided: the verdict on a nonlinear run.

    Parameters
    ----------
    states : (M+1, N) array
        The closed-loop state at the sampling instants.
    positions : (M+1, p) array
        The port positions at the sampling instants (m).
    period : float
        T in s.
    linear_rate : float, optional
        Growth rate of the linearised loop (1/s; > 0 if it is unstable).
    bound : str, optional
        Why the run cannot grow, if the model says so.
    can_drift : bool
        Whether some port has nothing pulling it back (no spring to ground), so a
        steady drift is possible at all.

    Returns
    -------
    BoundednessVerdict
        ``verdict`` is bounded (settles, limit cycle, or ``bound``), unbounded
        (grows), marginal (drifts) or undecided; ``growth_rate`` is the envelope's.
    """
    S, X = np.asarray(states, float), np.asarray(positions, float)
    if not (np.all(np.isfinite(S)) and np.all(np.isfinite(X))):
        return _verdict("unbounded", "grows", "high", "observed", None,
                        "the state overflowed (non-finite): observed unbounded")
    M = X.shape[0] - 1
    W = max(M // 2, 8)
    done = _settled(S, X, W, period)
    if done is not None:
        return done
    env = _envelope(X[-W - 1:], period, float(np.abs(X).max()))
    return _classify(env, M * period, linear_rate, bound, can_drift)


def _settled(S: np.ndarray, X: np.ndarray, W: int, period: float) -> BoundednessVerdict | None:
    """Settled exactly (the state stops changing) or to rounding; else None."""
    D = np.diff(S[-W - 1:], axis=0)
    tail = max(W // 4, 2)
    moving = np.flatnonzero(np.any(D != 0, axis=1))
    if moving.size == 0 or moving[-1] < W - tail:
        t_stop = (S.shape[0] - 1 - W + (moving[-1] + 1 if moving.size else 0)) * period
        return _verdict("bounded", "settles", "high", "observed", None,
                        f"the state stopped changing at t = {t_stop:.4g} s and stays at rest")
    run = float(np.ptp(X, axis=0).max())
    end = float(np.ptp(X[-tail - 1:], axis=0).max())
    if run == 0 or end <= SETTLED_REL * run:
        return _verdict("bounded", "settles", "high", "observed", None,
                        f"the motion fell to {end:.2g} m peak-to-peak, below {SETTLED_REL:g} of "
                        "the run's: settled to rounding")
    return None


def _classify(env: Envelope, duration_s: float, linear_rate: float | None,
              bound: str | None, can_drift: bool) -> BoundednessVerdict:
    r = env.ratio
    span = f"the peak-to-peak position changed x{r:.3g} over the last {env.window_s:.4g} s"
    if env.cycles < CYCLES_MIN:
        return _slow(env, duration_s, linear_rate, bound, can_drift, span)
    rate, se = env.rate()
    if r >= DECISIVE and env.fraction(up=True) >= MONOTONE:
        return _growing(env, duration_s, bound, span)
    if r <= 1 / DECISIVE and env.fraction(up=False) >= MONOTONE:
        conf = "high" if r <= 1 / CLEAR else "medium"
        return _verdict("bounded", "settles", conf, "trajectory", env,
                        f"the oscillation dies out at {rate:.3g} 1/s: {span}")
    flat = env.amps.max() <= FLAT * max(env.amps.min(), DIVISOR_FLOOR)
    # a flat envelope that still rises or falls steadily (every stretch beyond the
    # last, the slope > 3 standard errors) is a slow trend, not yet a cycle
    rising = rate > TREND_SE * se and env.fraction(up=True) >= MONOTONE
    falling = rate < -TREND_SE * se and env.fraction(up=False) >= MONOTONE
    if flat and falling:
        return _verdict("bounded", "settles", "low", "trajectory", env,
                        f"the oscillation dies out slowly ({rate:.3g} 1/s: {span}); a longer run "
                        "shows whether it stops or keeps a smaller cycle",
                        duration_hint_s=_hint(env, duration_s, None))
    if flat and not rising:
        return _limit_cycle(env, duration_s, linear_rate, bound, span)
    return _undecided(env, duration_s, linear_rate, bound, span)


def _growing(env: Envelope, duration_s: float, bound: str | None,
             span: str) -> BoundednessVerdict:
    """An oscillation whose envelope rises: growth, unless it is levelling off (its
    rate over the later stretches under half that over the earlier ones: a wall
    that loses contact, a saturated actuator) or the model bounds it."""
    rate = env.rate()[0]
    half = env.amps.size // 2
    early, late = env.rate(slice(0, half + 1))[0], env.rate(slice(half, None))[0]
    hint = _hint(env, duration_s, None)
    if bound:
        return _verdict("bounded", "undecided", "high", "bound", env,
                        f"still growing ({span}), but bounded: {bound}; a longer run shows "
                        "where it levels off", duration_hint_s=hint)
    if late < 0.5 * early:
        return _verdict("undecided", "undecided", "low", "trajectory", env,
                        f"the oscillation grew ({span}) but ever more slowly ({early:.3g} then "
                        f"{late:.3g} 1/s): it may level off; try a run of about {hint:.3g} s",
                        duration_hint_s=hint)
    conf = "high" if env.ratio >= CLEAR else "medium"
    return _verdict("unbounded", "grows", conf, "trajectory", env,
                    f"the oscillation grows at {rate:.3g} 1/s: {span}")


def _slow(env: Envelope, duration_s: float, linear_rate: float | None, bound: str | None,
          can_drift: bool, span: str) -> BoundednessVerdict:
    """Fewer than CYCLES_MIN cycles in the window: a slow excursion (a slow force,
    a creep) looks like growth or decay over part of its own cycle, so only a
    clear monotone decay settles, only an explosive rise grows, a constant speed
    with nothing pulling back drifts; the rest is undecided."""
    r = env.ratio
    if r <= 1 / CLEAR and env.fraction(up=False) >= MONOTONE:
        return _verdict("bounded", "settles", "medium", "trajectory", env,
                        f"the motion dies out without oscillating: {span}")
    if r >= RUNAWAY and env.fraction(up=True) >= MONOTONE and not bound:
        return _verdict("unbounded", "grows", "medium", "trajectory", env,
                        f"the motion runs away: {span}")
    steps = np.abs(env.steps)
    steady = env.monotone and steps.min() > 0 and steps.max() <= 1.05 * steps.min()
    if can_drift and steady and steps.min() > DRIFT_REL * env.scale and not bound:
        speed = float(steps.mean()) / (env.window_s / steps.size)
        return _verdict("marginal", "drifts", "medium", "trajectory", env,
                        f"the position moves one way at a steady {speed:.3g} m/s and a port has "
                        "no spring to pull it back: a drift, bounded in speed, not in position")
    return _undecided(env, duration_s, linear_rate, bound, span)


def _limit_cycle(env: Envelope, duration_s: float, linear_rate: float | None,
                 bound: str | None, span: str) -> BoundednessVerdict:
    amp, P = float(env.amps[-2:].max()) / 2, env.period_s
    what = f"a limit cycle of amplitude {amp:.3g} m and period {P:.4g} s ({span})"
    if linear_rate is not None and linear_rate > 0 and not bound \
            and math.exp(min(linear_rate * env.window_s, 700.0)) < DECISIVE:
        return _verdict("undecided", "undecided", "low", "trajectory", env,
                        f"looks like {what}, but the linearised loop grows at only "
                        f"{linear_rate:.3g} 1/s, too slowly to show in this run",
                        amplitude_m=amp, period_s=P, duration_hint_s=_hint(env, duration_s,
                                                                           linear_rate))
    steady = env.amps.max() <= 1.05 * env.amps.min() and env.cycles >= 2 * CYCLES_MIN
    conf = "high" if bound or steady else "medium"
    why = f": {bound}" if bound else ""
    return _verdict("bounded", "limit cycle", conf, "bound" if bound else "trajectory", env,
                    f"{what}{why}", amplitude_m=amp, period_s=P)


def _undecided(env: Envelope, duration_s: float, linear_rate: float | None,
               bound: str | None, span: str) -> BoundednessVerdict:
    hint = _hint(env, duration_s, linear_rate)
    if bound:
        return _verdict("bounded", "undecided", "high", "bound", env,
                        f"bounded: {bound}; the motion has not yet settled into a pattern "
                        f"({span})", duration_hint_s=hint)
    cyc = f"{env.cycles} cycles" if env.cycles else "no oscillation"
    return _verdict("undecided", "undecided", "low", "trajectory", env,
                    f"the run is too short to tell: {span}, {cyc} in the window; "
                    f"try a run of about {hint:.3g} s", duration_hint_s=hint)
