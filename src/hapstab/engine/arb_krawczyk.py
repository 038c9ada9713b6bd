"""The iterated Krawczyk exclusion of a box (certificate version 5's test ``"I"``).

A gap's boxes next to a crossing are the proof's costly ones: the crossing, a zero of
det M(e^{j theta}, K) at (theta*, K*), lies a relative 2^-40 (the window) above the box's
top K, and a test on one ball over the whole box -- ``"F"``, or the preconditioned
mean-value form ``"N"`` (one Krawczyk step) -- sees the zero only once the box is ~1e-6
of its size across: ~60 boxes per crossing by halving. Iterating the Krawczyk operator
instead follows the zero with Newton's quadratic convergence and excludes the box as soon
as the zeros it may hold are pinned outside it (a few steps).

As a map of x = (theta, K) to R^2, F(x) = (Re det M, Im det M). For a box X (two real
balls) with centre c and radius r, and J(X) a ball matrix holding the Jacobian of F over
X, the Krawczyk operator is

    Kr(X) = c - Y F(c) + (I - Y J(X)) (X - c)

for any real 2 x 2 matrix Y (here the inverse of J's midpoint, in doubles). Every zero
x* of F in X lies in Kr(X): each component of F satisfies F_i(x*) - F_i(c) =
grad F_i(xi_i) . (x* - c) with xi_i on the segment from c to x* (inside X, which is
convex), so 0 = F(c) + M (x* - c) for a matrix M whose rows lie in J(X), and x* = c -
Y F(c) + (I - Y M)(x* - c), a member of the ball expression. Hence every zero of X lies in
X_1 = Kr(X) intersected with X, every zero of X_1 in X_2 = Kr(X_1) intersected with X_1,
and so on: if some X_k is empty, or lies outside the box's exact ends, the box holds no
zero. Any balls that hold the sets are as good (Arb's intersection and arithmetic are
rigorous), so the test is proved whatever Y, the number of steps or the rounding.

J(X) from the angle kernel of precomputed ball polynomials
(:func:`~hapstab.engine.arb_kernel.poly_kernel`, coefficients in K of det M at the
ball's centre ``Fm`` and of d/dtheta over the ball ``Fd``): dF/dtheta over X is
``Fd(K)`` on the K-ball; dF/dK over X is ``c_1 + 2 K c_2`` with each coefficient over the
angle ball held by ``Fm_i + Fd_i [-r_theta, r_theta]`` (the coefficient's increment is
the integral of its derivative, which stays in the convex ball ``Fd_i``). F(c) is
``Fm(K_c)`` at the centre angle and the centre K.

References
----------
R. Krawczyk, "Newton-Algorithmen zur Bestimmung von Nullstellen mit Fehlerschranken",
Computing 4 (1969) 187-201; A. Neumaier, *Interval Methods for Systems of Equations*,
Cambridge 1990, sec. 5.1 (Theorem 5.1.7: the zeros in X lie in Kr(X));
R. E. Moore, R. B. Kearfott and M. J. Cloud, *Introduction to Interval Analysis*, SIAM
2009, sec. 8.2.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from hapstab.engine.arb_forms import dpoly_k, poly_k

__all__ = ["krawczyk_excludes", "STEPS", "SHRINK"]

#: Most Krawczyk steps tried on one box: from a box the size of the crossing's distance,
#: Newton's quadratic convergence reaches the working precision in ~6-8 (measured on the
#: paper's loops and 200 random HVEs: the excluded boxes needed 1-9).
STEPS = 12
#: A step that leaves both radii above this share of the box's is not converging: the
#: test gives up there (a choice of effort, not a tolerance: the box is split instead).
SHRINK = 0.5


def krawczyk_excludes(kernel_at: Callable[[Any], tuple], theta: Any, K: Any,
                      box: tuple[float, float, float, float], kern0: tuple | None = None,
                      steps: int = STEPS) -> bool:
    """Whether det M has no zero on ``box`` = (a, b, K_a, K_b) by the iterated Krawczyk
    operator (module docstring). At the precision in force.

    Parameters
    ----------
    kernel_at : callable
        An arb ball of angles -> its kernel ``(Pm, Qm, Fm, Pd, Qd, Fd)``
        (:meth:`~hapstab.engine.arb_loop.ArbLoop.kernel` with ``polys``).
    theta, K : arb
        Balls holding [a, b] and [K_a, K_b] (the first X); balls that do not hold the
        box's ends are refused (False): the box's zeros would not all be in X.
    box : tuple of float
        The box's exact ends (rad, N/m); an angle end equal to ``math.pi`` stands for pi.
    kern0 : tuple, optional
        ``kernel_at(theta)``, formed already.
    steps : int
        Most steps (:data:`STEPS`).

    Returns
    -------
    bool
        True: proved free of zeros. False: not decided (never "has a zero").
    """
    import flint
    arb = flint.arb
    a, b = (arb.pi() if x == math.pi else x for x in box[:2])
    ka, kb = box[2], box[3]
    if not all(ball.contains(end) for ball, end in ((theta, a), (theta, b), (K, ka), (K, kb))):
        return False        # the balls must hold the box (its ends; pi as pi itself)
    for step in range(steps):
        kern = kern0 if step == 0 and kern0 is not None else kernel_at(theta)
        new = _image(kern, theta, K, box if step == 0 else None)
        if new is None:
            return False
        nt, nk = new
        if not (nt.overlaps(theta) and nk.overlaps(K)):
            return True                   # Kr(X) and X disjoint: X holds no zero
        r_theta, r_K = float(theta.rad()), float(K.rad())
        theta, K = nt.intersection(theta), nk.intersection(K)
        if theta.lower() > b or theta.upper() < a or K.lower() > kb or K.upper() < ka:
            return True                   # X's zeros, all in this set, miss the box
        if float(theta.rad()) > SHRINK * r_theta and float(K.rad()) > SHRINK * r_K:
            return False                  # not converging: the box is split instead
    return False


def _image(kern: tuple, theta: Any, K: Any,
           box: tuple[float, float, float, float] | None = None) -> tuple[Any, Any] | None:
    """Kr(X) for X = theta x K (module docstring), or None where J's midpoint is singular
    or a ball is not finite, or (with ``box``) where :func:`_hopeless` foresees no
    progress."""
    import flint
    acb, arb = flint.acb, flint.arb
    _Pm, _Qm, Fm, _Pd, _Qd, Fd = kern
    Kc = acb(K)
    hh = acb(arb(0, theta.rad()))
    Fc = poly_k(Fm, acb(K.mid()))
    Ft = poly_k(Fd, Kc)
    Fk = dpoly_k([m + hh * d for m, d in zip(Fm, Fd, strict=True)], Kc)
    (p, r), (q, s) = ((z.real, z.imag) for z in (complex(Ft), complex(Fk)))
    det = p * s - q * r
    if not (math.isfinite(det) and det != 0.0):
        return None
    Y = ((s / det, -q / det), (-r / det, p / det))
    if not all(math.isfinite(y) for row in Y for y in row):
        return None
    J = ((Ft.real, Fk.real), (Ft.imag, Fk.imag))
    if box is not None and _hopeless(Y, J, Fc, theta, K, box):
        return None
    dt, dk = arb(0, theta.rad()), arb(0, K.rad())
    f_re, f_im = Fc.real, Fc.imag
    out = []
    for i, mid in enumerate((theta.mid(), K.mid())):
        y1, y2 = arb(Y[i][0]), arb(Y[i][1])       # exact: the doubles as balls, once
        e0 = (1 if i == 0 else 0) - (y1 * J[0][0] + y2 * J[1][0])
        e1 = (1 if i == 1 else 0) - (y1 * J[0][1] + y2 * J[1][1])
        x = mid - (y1 * f_re + y2 * f_im) + e0 * dt + e1 * dk
        if not x.is_finite():
            return None
        out.append(x)
    return out[0], out[1]


def _hopeless(Y: tuple, J: tuple, Fc: Any, theta: Any, K: Any,
              box: tuple[float, float, float, float]) -> bool:
    """The first step foreseen in doubles (a choice of effort, never a proof: True only
    skips the test, and the box is split): Kr(X)'s centre and radius per variable from
    the balls' midpoints and radii; True when it would neither miss X nor the box nor
    shrink either radius below :data:`SHRINK` of X's (most boxes the four tests leave
    far from a crossing: there one step costs as much as a box)."""
    rad = [[float(J[i][j].rad()) for j in range(2)] for i in range(2)]
    f = (float(Fc.real.mid()), float(Fc.imag.mid()))
    f_rad = (float(Fc.real.rad()), float(Fc.imag.rad()))
    x = (float(theta.mid()), float(K.mid()))
    r = (float(theta.rad()), float(K.rad()))
    ends = ((box[0], box[1]), (box[2], box[3]))
    for i in range(2):
        y = Y[i]
        centre = x[i] - (y[0] * f[0] + y[1] * f[1])
        spread = sum((abs(y[0]) * rad[0][j] + abs(y[1]) * rad[1][j]) * r[j] for j in range(2))
        spread += abs(y[0]) * f_rad[0] + abs(y[1]) * f_rad[1]
        lo, hi = max(x[i] - r[i], centre - spread), min(x[i] + r[i], centre + spread)
        if lo > hi or lo > ends[i][1] or hi < ends[i][0] or hi - lo < 2 * SHRINK * r[i]:
            return False
    return True
