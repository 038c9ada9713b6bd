"""Independent brute-force reference for the PEB with the same fractional one-way delay
both ways (no hapstab code).

The physics, written from scratch: port j (master m, slave s; total mass M_j, damping
b_j, spring k_j to ground) obeys M_j x_j'' + b_j x_j' + k_j x_j = -u_j with u_j held over
each sample (ZOH), state [x_j, v_j] discretised by ``scipy.signal.cont2discrete`` over T
and over (1 - f) T. The one-way delay is (n + f) T both ways; r_j[k] = x_j(kT - fT) is a
state,

    r_j[k+1] = C (Ad_{j,(1-f)T} [x_j, v_j][k] - Bd_{j,(1-f)T} u_j[k]),

followed by n + 1 shift registers r_j[k-1] ... r_j[k-n-1]; p_j[k] = x_j[k-1] is a state
too. With the position and force scales a, b (eq. (20) of the paper when both are 1)

    e_m[k] = a b x_m[k] - b r_s[k-n],   e_s[k] = x_s[k] - a r_m[k-n],
    u_j[k] = K rho_j e_j[k] + (B_j / T) (e_j[k] - e_j[k-1])      (rho_m = 1).

The closed loop is A(K) = A0 + K A1; its spectral radius by ``np.linalg.eigvals``
(batched over the delays) and K_max by a geometric scan of K and bisection (the first K
where rho >= 1).
"""

from __future__ import annotations

import math

import numpy as np

from .brute_fractional import exact_numbers, zoh  # one port's ZOH, as the HVE's reference


def matrices(ports, T: float, n: int, f: float, B, rho: float, a: float = 1.0, b: float = 1.0,
             digits: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(A0, A1) of the closed loop with one-way delay (n + f) T, 0 <= f < 1 (module
    docstring); ``ports`` ((M, b, k) of master and slave), ``B`` (B_m, B_s); with
    ``digits``, in mpmath (object arrays; every double taken as exact)."""
    zeros, num = exact_numbers(digits)
    T, f, a, b, rho = num(T), num(f), num(a), num(b), num(rho)
    N = 4 + 2 + 2 * (n + 2)
    X = [0, 2]                                   # [x_j, v_j] at X[j], X[j] + 1
    P = [4, 5]                                   # x_j[k-1]
    R = [6, 6 + n + 2]                           # r_j[k - lag] at R[j] + lag
    own, cross = [a * b, 1.0], [-b, -a]
    ratio = [1.0, rho]
    A0, A1 = zeros((N, N)), zeros((N, N))
    for j in (0, 1):
        o = 1 - j
        Ad, bd = zoh(*ports[j], T, digits)
        Af, bf = zoh(*ports[j], (1 - f) * T, digits)
        e, e_old = zeros(N), zeros(N)            # e_j[k], e_j[k-1] as rows on the state
        e[X[j]] += own[j]
        e[R[o] + n] += cross[j]
        e_old[P[j]] += own[j]
        e_old[R[o] + n + 1] += cross[j]
        u0, u1 = num(B[j]) / T * (e - e_old), ratio[j] * e
        A0[X[j]:X[j] + 2, X[j]:X[j] + 2] = Ad
        A0[X[j]:X[j] + 2] -= np.outer(bd, u0)
        A1[X[j]:X[j] + 2] -= np.outer(bd, u1)
        A0[R[j], X[j]:X[j] + 2] = Af[0]
        A0[R[j]] -= bf[0] * u0
        A1[R[j]] -= bf[0] * u1
        A0[P[j], X[j]] = 1.0
        for lag in range(1, n + 2):
            A0[R[j] + lag, R[j] + lag - 1] = 1.0
    return A0, A1


def _radius(A0: np.ndarray, A1: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Spectral radius of A0[i] + K[i] A1[i] for each i."""
    return np.abs(np.linalg.eigvals(A0 + K[:, None, None] * A1)).max(axis=-1)


def kmax_many(ports, T: float, delays, B, rho: float, a: float = 1.0, b: float = 1.0,
              lo: float = 1e-6, hi: float = 1e8, per_decade: int = 12,
              rtol: float = 1e-11) -> np.ndarray:
    """K_max at each one-way delay of ``delays`` (samples): the first K of a geometric
    scan from ``lo`` where the spectral radius reaches 1, bisected to ``rtol``; 0 if
    unstable at ``lo``, inf if stable up to ``hi``. Batched over the delays."""
    d = np.asarray(delays, float)
    out = np.empty(d.size)
    n_of = np.floor(d).astype(int)
    for n in np.unique(n_of):
        idx = np.flatnonzero(n_of == n)
        mats = [matrices(ports, T, int(n), float(d[i] - n), B, rho, a, b) for i in idx]
        A0 = np.stack([m[0] for m in mats])
        A1 = np.stack([m[1] for m in mats])
        out[idx] = _bisect(A0, A1, lo, hi, per_decade, rtol)
    return out


def _bisect(A0: np.ndarray, A1: np.ndarray, lo: float, hi: float, per_decade: int,
            rtol: float) -> np.ndarray:
    """The scan and bisection of :func:`kmax_many` for one batch of closed loops."""
    m = A0.shape[0]
    Ks = np.geomspace(lo, hi, int(per_decade * math.log10(hi / lo)) + 1)
    first = np.full(m, -1)
    for s, K in enumerate(Ks):                    # the scan, on the loops still stable
        act = np.flatnonzero(first < 0)
        if act.size == 0:
            break
        bad = _radius(A0[act], A1[act], np.full(act.size, K)) >= 1.0
        first[act[bad]] = s
    res = np.where(first < 0, math.inf, 0.0)
    live = np.flatnonzero(first > 0)
    a, c = Ks[first[live] - 1], Ks[first[live]]
    while live.size and np.max(c / a) > 1 + rtol:
        mid = np.sqrt(a * c)
        bad = _radius(A0[live], A1[live], mid) >= 1.0
        c, a = np.where(bad, mid, c), np.where(bad, a, mid)
    res[live] = c
    return res
