"""Midpoint-radius ("ball") arithmetic on numpy arrays, with a rigorous matrix
exponential: every real number a ball stands for lies in ``[m - r, m + r]``.

A :class:`Ball` holds arrays ``m`` (midpoints) and ``r`` (radii >= 0). Every
operation returns a ball that contains the result of the operation on every pair
of numbers in its operands, *including the rounding of the floating-point
evaluation*: the midpoint is computed in floating point and the radius is raised
by a bound on that rounding (Rump's midpoint-radius arithmetic; the bound for a dot
product of length n is ``gamma_n |a| |b|``, gamma_n = n u / (1 - n u), u = eps/2,
Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., sec. 3.1), and
the radius's own evaluation is rounded up by a relative allowance. Underflow adds
the smallest normal number per operation.

:func:`ball_expm` encloses e^X for every matrix in a ball X: scaling by 2^-s until
the infinity-norm bound is at most 1/2, the Taylor polynomial of degree 18
(Horner's rule in ball arithmetic) plus the remainder bound
``||Y||^(m+1) / (m+1)! / (1 - ||Y|| / (m+2))`` added to every entry (an entry is
bounded by the infinity norm), then s squarings in ball arithmetic.

References
----------
S. M. Rump, "Fast and parallel interval arithmetic", BIT 39 (1999) 534-554;
C. Moler and C. Van Loan, "Nineteen dubious ways to compute the exponential of a
matrix, twenty-five years later", SIAM Rev. 45 (2003) 3-49 (the Taylor remainder,
sec. 3).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["Ball", "ball_expm", "interval_ball", "TAYLOR_DEGREE"]

#: The unit round-off times 2 (numpy's eps): the rounding allowances below are
#: multiples of it.
EPS = float(np.finfo(float).eps)
#: Added to every radius: a result that underflowed is wrong by at most this.
TINY = float(np.finfo(float).tiny)
#: Taylor degree of :func:`ball_expm` (with ||Y|| <= 1/2 its remainder is below
#: 0.5^19/19! ~ 1.6e-23, far below the rounding of the entries near 1).
TAYLOR_DEGREE = 18


def _up(x: np.ndarray, n: int = 1) -> np.ndarray:
    """A radius computed in floating point, rounded up: n + 2 unit round-offs per
    term it was summed from, and the underflow allowance."""
    return x * (1.0 + (n + 2) * EPS) + TINY


class Ball:
    """Arrays of midpoints ``m`` and radii ``r`` (same shape), each entry standing
    for the real interval [m - r, m + r]."""

    __slots__ = ("m", "r")

    def __init__(self, m: Any, r: Any = None) -> None:
        self.m = np.asarray(m, float)
        self.r = np.zeros_like(self.m) if r is None else np.broadcast_to(
            np.asarray(r, float), self.m.shape).copy()

    # ------------------------------------------------------------- views
    @property
    def shape(self) -> tuple[int, ...]:
        return self.m.shape

    @property
    def mag(self) -> np.ndarray:
        """An upper bound of |x| over the ball."""
        return _up(np.abs(self.m) + self.r)

    @property
    def lo(self) -> np.ndarray:
        """A lower bound of the ball (rounded down)."""
        return np.nextafter(self.m - self.r, -np.inf)

    @property
    def hi(self) -> np.ndarray:
        """An upper bound of the ball (rounded up)."""
        return np.nextafter(self.m + self.r, np.inf)

    def __getitem__(self, key: Any) -> Ball:
        return Ball(self.m[key], self.r[key])

    def contains(self, x: Any, slack: float = 0.0) -> np.ndarray:
        """Whether ``x`` lies in the ball (widened by ``slack`` times its size)."""
        x = np.asarray(x, float)
        return np.abs(x - self.m) <= self.r + slack * (np.abs(self.m) + self.r)

    # ------------------------------------------------------------- algebra
    def __add__(self, o: Any) -> Ball:
        o = as_ball(o)
        m = self.m + o.m
        return Ball(m, _up(self.r + o.r + EPS * np.abs(m), 2))

    def __radd__(self, o: Any) -> Ball:
        return self + o

    def __neg__(self) -> Ball:
        return Ball(-self.m, self.r)

    def __sub__(self, o: Any) -> Ball:
        return self + (-as_ball(o))

    def __rsub__(self, o: Any) -> Ball:
        return as_ball(o) - self

    def __mul__(self, o: Any) -> Ball:
        """Elementwise product (broadcasting)."""
        o = as_ball(o)
        m = self.m * o.m
        r = np.abs(self.m) * o.r + self.r * (np.abs(o.m) + o.r) + EPS * np.abs(m)
        return Ball(m, _up(r, 3))

    def __rmul__(self, o: Any) -> Ball:
        return self * o

    def __matmul__(self, o: Any) -> Ball:
        """Matrix product of stacks (..., n, k) @ (..., k, p)."""
        o = as_ball(o)
        k = self.m.shape[-1]
        am, om = np.abs(self.m), np.abs(o.m)
        m = self.m @ o.m
        r = am @ o.r + self.r @ (om + o.r) + k * EPS * (am @ om)
        return Ball(m, _up(r, k + 2))

    def div_int(self, k: int) -> Ball:
        """Division by a whole number (exact divisor, one rounding)."""
        m = self.m / k
        return Ball(m, _up(self.r / k + EPS * np.abs(m), 2))

    def pow2(self, e: np.ndarray) -> Ball:
        """Multiplication by 2^e (exact, barring underflow), broadcast on the left."""
        f = np.ldexp(1.0, np.asarray(e, int))
        return Ball(self.m * f, self.r * f + TINY)

    def trace(self) -> Ball:
        """Trace of each matrix of a stack (..., n, n)."""
        n = self.m.shape[-1]
        d = np.diagonal(self.m, axis1=-2, axis2=-1)
        dr = np.diagonal(self.r, axis1=-2, axis2=-1)
        m = d.sum(axis=-1)
        return Ball(m, _up(dr.sum(axis=-1) + n * EPS * np.abs(d).sum(axis=-1), n))

    @staticmethod
    def stack(balls: Sequence[Ball], axis: int = 0) -> Ball:
        """Stack balls along a new axis."""
        return Ball(np.stack([b.m for b in balls], axis=axis),
                    np.stack([b.r for b in balls], axis=axis))


def as_ball(x: Any) -> Ball:
    """``x`` as a ball (a number or array is exact: radius 0)."""
    return x if isinstance(x, Ball) else Ball(x)


def interval_ball(lo: Any, hi: Any) -> Ball:
    """The ball that contains [lo, hi] (lo <= hi, both exact numbers)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = 0.5 * lo + 0.5 * hi                     # no overflow; one rounding at most
    r = np.maximum(hi - m, m - lo)
    return Ball(m, _up(r, 2))


# ------------------------------------------------------------------ exponential
def _norm_inf(X: Ball) -> np.ndarray:
    """An upper bound of the infinity norm of every matrix in each ball (..., n, n)."""
    n = X.m.shape[-1]
    return _up((np.abs(X.m) + X.r).sum(axis=-1).max(axis=-1), n)


def _taylor_remainder(norm: np.ndarray, deg: int) -> np.ndarray:
    """Bound of ||sum_{k > deg} Y^k / k!|| for ||Y|| <= norm < deg + 2."""
    f = math.factorial(deg + 1)
    return _up(norm ** (deg + 1) / f / (1.0 - norm / (deg + 2)), 4)


def ball_expm(X: Ball) -> Ball:
    """e^X for every matrix in the balls of a stack X (L, n, n).

    Parameters
    ----------
    X : Ball
        Midpoints and radii, shape (L, n, n).

    Returns
    -------
    Ball
        (L, n, n): for every matrix A with |A - X.m| <= X.r entrywise, e^A lies in it.
    """
    L, n, _ = X.m.shape
    norm = _norm_inf(X)
    with np.errstate(divide="ignore"):
        s = np.maximum(0, np.ceil(np.log2(np.maximum(norm, TINY) / 0.5))).astype(int)
    Y = X.pow2(-s[:, None, None])
    ny = norm * np.ldexp(1.0, -s)                           # exact scaling
    eye = Ball(np.broadcast_to(np.eye(n), (L, n, n)).copy())
    P = eye
    for k in range(TAYLOR_DEGREE, 0, -1):                  # Horner: I + Y/k (...)
        P = eye + (Y @ P).div_int(k)
    P = Ball(P.m, _up(P.r + _taylor_remainder(ny, TAYLOR_DEGREE)[:, None, None], 2))
    for k in range(int(s.max()) if s.size else 0):
        sq = s > k
        Q = P[sq] @ P[sq]
        P.m[sq], P.r[sq] = Q.m, Q.r
    return P
