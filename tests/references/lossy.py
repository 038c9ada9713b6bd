"""Independent reference for packet loss (no hapstab code): the loop of
:mod:`tests.references.brute` stepped sample by sample with the issue's hold rule,

    y_t[k] = x_j[k - n]  if the packet of term t arrived,  else  y_t[k - 1],
    u_i[k] = g_i K e_i[k] + (B_i / T)(e_i[k] - e_i[k - 1]),   e_i = sum_t s_t y_t,

(a term is networked when it measures another port, or on a one-port loop; local
terms are used directly). The mode matrices come from stepping each unit state (the
step is linear in the state), the mean-square radius from the dense Kronecker second
moment ``sum_i pi_i A_i (x) A_i`` (independent losses) or its Markov block form
``[p_ij A_i (x) A_i]`` (Costa, Fragoso & Marques 2005, Theorem 3.9), and K_max from a
grid scan and bisection.
"""

from __future__ import annotations

import itertools

import numpy as np
from tests.references import brute


def _networked(loop: brute.Loop) -> list[tuple[int, int]]:
    """(control i, term index) of every networked term."""
    single = len(loop.ports) == 1
    return [(i, t) for i, c in enumerate(loop.controls) for t, (j, _, _) in enumerate(c.terms)
            if single or j != i]


def layout(loop: brute.Loop) -> tuple[int, int, int, int]:
    """(history depth D, offset of the holds, offset of the previous errors, N)."""
    p = len(loop.ports)
    D = max([d for c in loop.controls for _, _, d in c.terms] + [0])
    off_h = 2 * p + p * D
    off_e = off_h + len(_networked(loop))
    return D, off_h, off_e, off_e + len(loop.controls)


def step(loop: brute.Loop, s: np.ndarray, received: tuple[bool, ...], K: float) -> np.ndarray:
    """One sample of the lossy loop from state s: [x_j, v_j]_j, then x_j[k-1..k-D] per
    port, then the held y_t[k-1], then e_i[k-1]."""
    p, T = len(loop.ports), loop.period
    D, off_h, off_e, N = layout(loop)
    x = s[0:2 * p:2]

    def past(j: int, d: int) -> float:
        return float(x[j]) if d == 0 else float(s[2 * p + j * D + d - 1])

    net = _networked(loop)
    out = np.zeros(N)
    u = np.zeros(p)
    for i, c in enumerate(loop.controls):
        e = 0.0
        for t, (j, sgn, d) in enumerate(c.terms):
            if (i, t) in net:
                h = net.index((i, t))
                y = past(j, d) if received[h] else float(s[off_h + h])
                out[off_h + h] = y
            else:
                y = past(j, d)
            e += sgn * y
        u[i] += c.gain * K * e + (c.damping / T) * (e - s[off_e + i])
        out[off_e + i] = e
    for j, port in enumerate(loop.ports):
        Ad, bd = brute._zoh(port, T)
        out[2 * j:2 * j + 2] = Ad @ s[2 * j:2 * j + 2] - bd * u[j]
        for d in range(D):
            out[2 * p + j * D + d] = past(j, d)
    return out


def modes(loop: brute.Loop, K: float) -> list[np.ndarray]:
    """A_theta at K for every pattern of arrivals; pattern index bit h set = term h lost."""
    N = layout(loop)[3]
    m = len(_networked(loop))
    out = []
    for idx in range(2 ** m):
        rec = tuple(not (idx >> h & 1) for h in range(m))
        out.append(np.column_stack([step(loop, e, rec, K) for e in np.eye(N)]))
    return out


def chain(loss: float, burst: float | None, m: int) -> np.ndarray:
    """Joint transition matrix of m independent two-state chains (0 received, 1 lost)."""
    if burst is None:
        c = np.array([[1 - loss, loss], [1 - loss, loss]])
    else:
        q = loss / (burst * (1 - loss))
        c = np.array([[1 - q, q], [1 / burst, 1 - 1 / burst]])
    P = np.ones((1, 1))
    for _ in range(m):
        P = np.kron(c, P)
    return P


def radius(loop: brute.Loop, K: float, loss: float, burst: float | None = None) -> float:
    """rho of the second-moment operator (dense Kronecker form)."""
    A = modes(loop, K)
    M = len(A)
    Pi = chain(loss, burst, len(_networked(loop)))
    if burst is None:
        op = sum(Pi[0, i] * np.kron(A[i], A[i]) for i in range(M))
    else:
        n2 = A[0].shape[0] ** 2
        op = np.zeros((M * n2, M * n2))
        for i, j in itertools.product(range(M), range(M)):
            op[j * n2:(j + 1) * n2, i * n2:(i + 1) * n2] = Pi[i, j] * np.kron(A[i], A[i])
    return float(np.abs(np.linalg.eigvals(op)).max())


def kmax(loop: brute.Loop, loss: float, burst: float | None, hi: float, grid: int = 60,
         rtol: float = 1e-9) -> float:
    """First K where rho >= 1 on a grid of ``grid`` points in (0, hi], then bisection;
    inf when none is found."""
    lo = 0.0
    for K in np.linspace(hi / grid, hi, grid):
        if radius(loop, K, loss, burst) >= 1.0:
            top = K
            break
        lo = K
    else:
        return float("inf")
    while top - lo > rtol * top:
        mid = 0.5 * (lo + top)
        if radius(loop, mid, loss, burst) < 1.0:
            lo = mid
        else:
            top = mid
    return 0.5 * (lo + top)


def monte_carlo(loop: brute.Loop, K: float, loss: float, steps: int, paths: int,
                seed: int) -> np.ndarray:
    """E|s[k]|^2 over ``paths`` random independent-loss runs from random initial states
    (the mode matrices applied to every path at once; the losses drawn per path)."""
    rng = np.random.default_rng(seed)
    A = np.array(modes(loop, K))
    m = len(_networked(loop))
    S = rng.standard_normal((paths, A.shape[1]))
    out = np.empty(steps + 1)
    out[0] = np.mean(np.sum(S * S, axis=1))
    weights = 2 ** np.arange(m)
    for k in range(steps):
        lost = rng.random((paths, m)) < loss
        idx = lost.astype(int) @ weights
        S = np.einsum("pij,pj->pi", A[idx], S)
        out[k + 1] = np.mean(np.sum(S * S, axis=1))
    return out
