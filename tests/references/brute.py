"""Independent brute-force references for the tests (no hapstab engine code).

The closed loop is rebuilt here from scratch: each device + termination as a
transfer function from net force to position, discretised for a zero-order hold by
``scipy.signal.cont2discrete`` (a different code path from hapstab's augmented
matrix exponential), realised in state space, and closed with hand-written delay
registers and the spring-damper law u[k] = K e[k-n] + (B/T)(e[k-n] - e[k-n-1]).
Stability is the spectral radius of that matrix; K_max is found by scanning a
geometric grid and bisecting.
"""

from __future__ import annotations

import numpy as np
from scipy import signal


def _plant_tf(m: float, b: float, znum, zden) -> tuple[np.ndarray, np.ndarray]:
    """x/(f_net) = 1 / (s (m s + b + Z(s))) as a minimal (num, den), Z = znum/zden."""
    znum = np.trim_zeros(np.atleast_1d(np.asarray(znum, float)), "f")
    zden = np.trim_zeros(np.atleast_1d(np.asarray(zden, float)), "f")
    if znum.size == 0:
        znum = np.zeros(1)
    # s (m s + b) zden + s znum  over  zden ... x/f = zden / (s ((m s + b) zden + znum))
    inner = np.polyadd(np.polymul([m, b], zden), znum)
    den = np.polymul([1.0, 0.0], inner)
    num = zden.copy()
    while num.size > 1 and num[-1] == 0 and den[-1] == 0:   # cancel common s (a spring)
        num, den = num[:-1], den[:-1]
    return num, den


def closed_loop_matrix(ports: list[tuple[float, float, tuple, tuple]], channels, K: float,
                       B: float, T: float) -> np.ndarray:
    """Closed-loop matrix of a loop.

    ports: [(mass, damping, Z_num, Z_den)], channels: for each port i a list of
    (j, sign, delay) terms of its error signal e_i = sum sign * x_j[k - delay].
    """
    p = len(ports)
    blocks = []
    for m, b, zn, zd in ports:
        num, den = _plant_tf(m, b, zn, zd)
        A, Bm, C, D = signal.tf2ss(num, den)
        Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, Bm, C, D), T, method="zoh")
        blocks.append((Ad, Bd, Cd))
    nxs = [bl[0].shape[0] for bl in blocks]
    # registers of each measured position: depth = max delay + 1 (the B term needs e[k-n-1])
    depth = [0] * p
    for terms in channels:
        for j, _, n in terms:
            depth[j] = max(depth[j], n + 1)
    # state order here: registers first, then plants (hapstab puts plants first)
    off_r = np.concatenate([[0], np.cumsum(depth)]).astype(int)
    off_x = off_r[-1] + np.concatenate([[0], np.cumsum(nxs)]).astype(int)
    N = int(off_x[-1])

    def pos_row(j: int) -> np.ndarray:
        r = np.zeros(N)
        r[off_x[j]:off_x[j + 1]] = blocks[j][2][0]
        return r

    def delayed(j: int, d: int) -> np.ndarray:
        """Row giving x_j[k - d] from the state (register l holds x_j[k-1-l])."""
        if d == 0:
            return pos_row(j)
        r = np.zeros(N)
        r[off_r[j] + d - 1] = 1.0
        return r

    M = np.zeros((N, N))
    for j in range(p):
        if depth[j]:
            M[off_r[j]] = pos_row(j)
            for l in range(1, depth[j]):
                M[off_r[j] + l, off_r[j] + l - 1] = 1.0
    for i, terms in enumerate(channels):
        u = np.zeros(N)
        for j, sgn, n in terms:
            u += sgn * ((K + B / T) * delayed(j, n) - (B / T) * delayed(j, n + 1))
        Ad, Bd, _ = blocks[i]
        sl = slice(off_x[i], off_x[i + 1])
        M[sl, sl] += Ad
        M[sl] -= np.outer(Bd[:, 0], u)
    return M


def hve(m: float, b: float, zn, zd, n: int, B: float, T: float):
    ports = [(m, b, zn, zd)]
    channels = [[(0, 1.0, n)]]
    return lambda K: closed_loop_matrix(ports, channels, K, B, T)


def peb(mm: float, bm: float, ms: float, bs: float, op, env, n: int, B: float, T: float):
    ports = [(mm, bm, *op), (ms, bs, *env)]
    channels = [[(0, 1.0, 0), (1, -1.0, n)], [(1, 1.0, 0), (0, -1.0, n)]]
    return lambda K: closed_loop_matrix(ports, channels, K, B, T)


def spectral_radius(make, K: float) -> float:
    return float(np.abs(np.linalg.eigvals(make(K))).max())


def kmax(make, lo: float = 1e-6, hi: float = 1e7, grid: int = 800) -> float:
    """First K where the spectral radius reaches 1 (grid scan + bisection)."""
    Ks = np.geomspace(lo, hi, grid)
    prev = lo
    if spectral_radius(make, lo) >= 1:
        return 0.0
    for K in Ks[1:]:
        if spectral_radius(make, K) >= 1:
            a, b = prev, K
            for _ in range(80):
                mid = 0.5 * (a + b)
                if spectral_radius(make, mid) < 1:
                    a = mid
                else:
                    b = mid
            return a
        prev = K
    return float("inf")
