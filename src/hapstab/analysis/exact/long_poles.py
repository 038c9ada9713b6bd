"""The closed loop's poles near the unit circle without its eigenvalue problem.

A delay of n samples gives the closed loop n more states, and the dense eigenvalue
problem costs ~N^3: at n = 2400 (300 ms at 8 kHz) about two minutes, at 10^4 hours,
while the certified count of poles outside (:func:`~hapstab.analysis.exact.proof.count`)
costs about the same at every n. :func:`~hapstab.analysis.exact.core.stability` takes its
verdict from that count; where the eigenvalue problem is over the budget, the dominant
pole it reports comes from here.

The characteristic function det M(z, K) = P(z) + z^-n Q(z) (P, Q of the loop's low
order) has, for a long delay, most of its poles near the circle in a band, one per turn
of z^-n, where |det M| on the circle dips (the fast-turning term against the slow one);
the others lie near the roots of P outside the circle (z^-n negligible there) or of Q
inside it. Newton's method on det M in the complex angle theta (z = e^{j theta}) starts
from every local minimum of |det M| on circles |z| = r (:data:`RADII`: the unit circle
with 16 points per turn, circles inside and outside it with as many where the delay's
term still turns there, a coarse grid where it is negligible or dominant) and keeps the
starts that converge. Checked against LAPACK's eigenvalues on seeded loops
(tests/exact/test_long_poles.py: the dominant pole within 1e-10) and, for a stiff wall
on a light device, against a 40-digit referee (Newton 8e-8 off, the eigenvalue solver
1.4e-6). The verdict never rests on this: the certified count does, and where fewer
poles outside were found than it counts, stability() does not report them (the
eigenvalue problem answers, or its budget refuses).
"""

from __future__ import annotations

import math

import numpy as np

from hapstab.engine.frequency import LoopResponse
from hapstab.tolerances import NEWTON_ANGLE_STEP

__all__ = ["near_circle_poles", "det_and_slope", "grid_points", "POINTS_PER_TURN", "RADII", "NEWTON_STEPS"]

#: Grid points per turn of det M's phase over [0, pi] (LoopResponse.phase_rate turns):
#: a local minimum of |det M| per pole near the circle needs a few points per turn;
#: 16 keep neighbouring minima apart where a resonance bunches the poles.
POINTS_PER_TURN = 16
#: The circles |z| = r whose local minima of |det M| start Newton: the unit circle (the
#: band of poles a long delay spreads around it) and circles inside and outside it, for
#: the poles the band does not hold (near the roots of P outside the circle, where z^-n
#: is negligible, or a pair well inside it)
RADII = (1.0, 1.0 + 1e-3, 1.0 + 1e-2, 1.05, 1.2, 1.5, 1.0 - 1e-3, 1.0 - 1e-2, 0.95)
#: Where n |ln r| exceeds this on a circle, the delay's term is e^-40 (~4e-18) of the
#: other or e^40 times it, below a double's resolution of their sum: no fast turns
FAST_GONE = 40.0
#: Newton steps at most (quadratic convergence from a start within a turn of its pole
#: needs ~5-8; the rest are for starts near a double pole).
NEWTON_STEPS = 40
#: A start still moving after NEWTON_STEPS steps with a step below this (relative) is a
#: multiple pole reached linearly: its angle is that close (a simple pole's start either
#: converges to NEWTON_ANGLE_STEP or wanders off by far more)
STALLED = 1e-9
#: Angles evaluated at once (memory: ~600 B an angle for the jets of det M)
CHUNK = 1 << 16
#: Two poles closer than this (relative) are one, found from two starts: far below the
#: spacing of distinct poles (2 pi / n at n = 10^5 is 6e-5) and far above Newton's
#: convergence (NEWTON_ANGLE_STEP).
SAME_POLE = 1e-9


def det_and_slope(resp: LoopResponse, u: float, theta: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """det M and d det M / d theta at the (complex) angles, stiffness u = K / scale (the
    jets' centres alone; also :func:`~hapstab.analysis.exact.core.stability`'s polish of
    an eigenvalue)."""
    zero = np.zeros(theta.size)
    F = resp.coefficients(np.zeros(theta.size, int), theta, zero, values_only=True)
    return (F[0].vc + u * (F[1].vc + u * F[2].vc),
            F[0].dc + u * (F[1].dc + u * F[2].dc))


def grid_points(resp: LoopResponse) -> int:
    """How many angles :func:`near_circle_poles` evaluates det M at (for its budget)."""
    return sum((POINTS_PER_TURN * resp.phase_rate
                if resp.phase_rate * abs(math.log(r)) < FAST_GONE else 0) + 1024 for r in RADII)


def _minima(resp: LoopResponse, u: float, ring: np.ndarray) -> np.ndarray:
    """The angles of ``ring`` where |det M| has a local minimum, with its two ends;
    evaluated :data:`CHUNK` angles at a time (the jets of a long grid at once took
    ~600 B an angle: 2 GB for a PEB at 10^5 samples each way)."""
    with np.errstate(all="ignore"):
        a = np.concatenate([np.abs(det_and_slope(resp, u, ring[i:i + CHUNK])[0])
                            for i in range(0, ring.size, CHUNK)])
    inner = np.flatnonzero((a[1:-1] <= a[:-2]) & (a[1:-1] <= a[2:])) + 1
    # the ends too: a real pole near z = +1 or -1 has its minimum at the grid's edge
    return np.concatenate([ring[inner], ring[:1], ring[-1:]])


def near_circle_poles(resp: LoopResponse, u: float) -> np.ndarray:
    """The closed loop's poles near |z| = 1 with Im z >= 0, by Newton's method (module
    docstring).

    Parameters
    ----------
    resp : LoopResponse
        The loop's response (one item).
    u : float
        The stiffness K divided by the response's scale.

    Returns
    -------
    ndarray of complex
        The poles found, each once, in increasing angle.
    """
    starts = []
    for r in RADII:
        # z^-n, n ~ phase_rate, is below e^-FAST_GONE of its value on the unit circle
        # on one side of |z| = r or above e^+FAST_GONE on the other: det M there is P or
        # z^-n Q to that share, with no fast turns, and a coarse grid finds its minima
        fast = resp.phase_rate * abs(math.log(r)) < FAST_GONE
        m = (POINTS_PER_TURN * resp.phase_rate if fast else 0) + 1024
        ring = (np.arange(m) + 0.5) * (math.pi / m) - 1j * math.log(r)   # z = r e^{j phi}
        starts.append(_minima(resp, u, ring))
    th = np.concatenate(starts).astype(complex)
    active, converged = np.ones(th.size, bool), np.zeros(th.size, bool)
    with np.errstate(all="ignore"):
        for _ in range(NEWTON_STEPS):
            idx = np.flatnonzero(active)
            f, df = det_and_slope(resp, u, th[idx])
            step = f / df
            ok = np.isfinite(step)
            th[idx[ok]] -= step[ok]
            small = ok & (np.abs(step) <= NEWTON_ANGLE_STEP * np.maximum(1.0, np.abs(th[idx])))
            converged[idx[small]] = True
            active[idx[small | ~ok]] = False        # converged, or lost (not a pole)
            if not active.any():
                break
        # a double pole (two poles of P met, e.g. identical master and slave): Newton
        # converges only linearly there, halving its step; after NEWTON_STEPS steps its
        # last step is ~2^-40 of the start's distance: kept when below STALLED
        idx = np.flatnonzero(active)
        if idx.size:
            f, df = det_and_slope(resp, u, th[idx])
            step = np.abs(f / df)
            converged[idx[np.isfinite(step) & (step <= STALLED * np.maximum(1.0, np.abs(th[idx])))]] = True
        z = np.exp(1j * th[converged])
    z = z[np.isfinite(z)]
    z = np.where(z.imag < 0, np.conj(z), z)             # the pair's upper member
    return _unique(z[np.argsort(np.angle(z))])


def _unique(z: np.ndarray) -> np.ndarray:
    """``z`` (sorted by angle) without repeats within :data:`SAME_POLE`."""
    out: list[complex] = []
    for p in z.tolist():
        if not any(abs(p - q) <= SAME_POLE * max(1.0, abs(p)) for q in out[-8:]):
            out.append(p)
    return np.array(out, complex)
