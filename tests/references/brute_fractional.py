"""Independent brute-force reference for the HVE with a fractional delay (no hapstab code).

The physics, written from scratch: the port (total mass M, damping b, spring k) obeys
M x'' + b x' + k x = -u with u held over each sample (ZOH), state [x, v] discretised by
``scipy.signal.cont2discrete`` over T and over (1 - f) T. The controller acts on
e[k] = x(kT - (n + f) T): r[k] = x(kT - fT) is a state,

    r[k+1] = C (Ad_{(1-f)T} [x, v][k] - Bd_{(1-f)T} u[k]),

followed by n + 1 shift registers r[k-1] ... r[k-n-1], and
u[k] = K r[k-n] + (B/T) (r[k-n] - r[k-n-1]). The closed loop is A(K) = A0 + K A1 on
[x, v, r[k], r[k-1], ..., r[k-n-1]]; its spectral radius by ``np.linalg.eigvals`` and
K_max by a geometric scan of K and bisection (the first K where rho >= 1), f = 0 built
the same way (r[k] = x[k] then, an extra pole at 0).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal


def zoh(M: float, b: float, k: float, t, digits: int | None = None
        ) -> tuple[np.ndarray, np.ndarray]:
    """ZOH over t of M x'' + b x' + k x = u, state [x, v] (scipy's cont2discrete); with
    ``digits``, in mpmath at that many digits (``t`` an mpf), as object arrays: the
    exponential of the augmented matrix [[A, B], [0, 0]] t by ``mpmath.expm``."""
    if digits is not None:
        return _zoh_mp(M, b, k, t, digits)
    A = np.array([[0.0, 1.0], [-k / M, -b / M]])
    Bc = np.array([[0.0], [1.0 / M]])
    if t == 0.0:
        return np.eye(2), np.zeros(2)
    Ad, Bd, _, _, _ = signal.cont2discrete((A, Bc, np.eye(2), np.zeros((2, 1))), t, method="zoh")
    return Ad, Bd[:, 0]


def _zoh_mp(M: float, b: float, k: float, t, digits: int):
    import mpmath
    with mpmath.workdps(digits):
        M, b, k = mpmath.mpf(M), mpmath.mpf(b), mpmath.mpf(k)
        if t == 0:
            return np.array([[mpmath.mpf(1), 0], [0, mpmath.mpf(1)]], dtype=object), \
                np.array([mpmath.mpf(0)] * 2, dtype=object)
        X = mpmath.expm(mpmath.matrix([[0, 1, 0], [-k / M, -b / M, 1 / M], [0, 0, 0]]) * t)
        return (np.array([[X[0, 0], X[0, 1]], [X[1, 0], X[1, 1]]], dtype=object),
                np.array([X[0, 2], X[1, 2]], dtype=object))


def exact_numbers(digits: int | None):
    """What the builders compute in: floats (None), or mpmath at ``digits``: (zeros,
    number) with ``number(x)`` the double x as an exact mpf."""
    if digits is None:
        return np.zeros, float
    import mpmath

    def zeros(shape):
        out = np.empty(shape, dtype=object)
        out[...] = mpmath.mpf(0)
        return out
    return zeros, mpmath.mpf


def matrices(M: float, b: float, k: float, T: float, n: int, f: float, B: float,
             digits: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(A0, A1) of the closed loop with delay (n + f) T, 0 <= f < 1 (module docstring);
    with ``digits``, in mpmath (object arrays; every double taken as exact)."""
    zeros, num = exact_numbers(digits)
    T_, f_ = num(T), num(f)
    Ad, bd = zoh(M, b, k, T_, digits)
    Af, bf = zoh(M, b, k, (1 - f_) * T_, digits)
    N = 2 + 1 + n + 1
    r = lambda lag: 2 + lag            # noqa: E731  (state of r[k - lag])
    u0, u1 = zeros(N), zeros(N)
    u1[r(n)] = 1.0
    u0[r(n)] += num(B) / T_
    u0[r(n + 1)] -= num(B) / T_
    A0, A1 = zeros((N, N)), zeros((N, N))
    A0[:2, :2] = Ad
    A0[:2] -= np.outer(bd, u0)
    A1[:2] -= np.outer(bd, u1)
    A0[2, :2] = Af[0]
    A0[2] -= bf[0] * u0
    A1[2] -= bf[0] * u1
    for lag in range(1, n + 2):
        A0[r(lag), r(lag - 1)] = 1.0
    return A0, A1


def radius(A0: np.ndarray, A1: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Spectral radius of A0 + K A1 at each K."""
    return np.abs(np.linalg.eigvals(A0 + np.asarray(K)[:, None, None] * A1)).max(axis=-1)


def kmax(M: float, b: float, k: float, T: float, delay: float, B: float,
         lo: float = 1e-6, hi: float = 1e8, per_decade: int = 40, rtol: float = 1e-11) -> float:
    """K_max at the delay ``delay`` (samples, any real >= 0): the first K of a geometric
    scan from ``lo`` where the spectral radius reaches 1, bisected to ``rtol``; 0 if
    unstable at ``lo``, inf if stable up to ``hi``."""
    n = math.floor(delay)
    f = delay - n
    A0, A1 = matrices(M, b, k, T, n, f, B)
    Ks = np.geomspace(lo, hi, int(per_decade * math.log10(hi / lo)) + 1)
    bad = np.flatnonzero(radius(A0, A1, Ks) >= 1.0)
    if bad.size == 0:
        return math.inf
    if bad[0] == 0:
        return 0.0
    a, c = Ks[bad[0] - 1], Ks[bad[0]]
    while c / a > 1 + rtol:
        m = math.sqrt(a * c)
        if radius(A0, A1, np.array([m]))[0] >= 1.0:
            c = m
        else:
            a = m
    return math.sqrt(a * c)


def kmax_many(M: float, b: float, k: float, T: float, delays, B: float, lo: float = 1e-6,
              hi: float = 1e8, per_decade: int = 16, rtol: float = 1e-11) -> np.ndarray:
    """:func:`kmax` at every delay of ``delays`` (samples), batched: the delays of one
    whole part share a matrix size, so their scans and bisections are stacks of
    ``np.linalg.eigvals``."""
    delays = np.asarray(delays, float)
    out = np.empty(delays.size)
    Ks = np.geomspace(lo, hi, int(per_decade * math.log10(hi / lo)) + 1)
    whole = np.floor(delays).astype(int)
    for n in np.unique(whole):
        idx = np.flatnonzero(whole == n)
        pairs = [matrices(M, b, k, T, int(n), float(delays[i] - n), B) for i in idx]
        A0 = np.stack([p[0] for p in pairs])
        A1 = np.stack([p[1] for p in pairs])
        rho = np.abs(np.linalg.eigvals(A0[:, None] + Ks[None, :, None, None] * A1[:, None])
                     ).max(axis=-1)
        bad = rho >= 1.0
        first = np.where(bad.any(axis=1), bad.argmax(axis=1), -1)
        a = np.where(first > 0, Ks[np.maximum(first - 1, 0)], np.nan)
        c = np.where(first > 0, Ks[np.maximum(first, 0)], np.nan)
        live = first > 0
        while live.any() and np.nanmax(c[live] / a[live]) > 1 + rtol:
            m = np.sqrt(a * c)
            r = np.abs(np.linalg.eigvals(A0 + np.nan_to_num(m)[:, None, None] * A1)).max(axis=-1)
            up = (r >= 1.0) & live
            c, a = np.where(up, m, c), np.where(live & ~up, m, a)
        out[idx] = np.where(first == 0, 0.0, np.where(first < 0, math.inf, np.sqrt(a * c)))
    return out
