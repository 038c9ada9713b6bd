"""Independent reference for a time-varying delay (no hapstab code): the loop of
:mod:`tests.references.brute` stepped sample by sample with the newest-arrived rule,

    y_t[k] = x_j[k - d_t[k]]  (d_t[k] in [lo, hi], d_t[k+1] <= d_t[k] + 1),
    u_i[k] = g_i K e_i[k] + (B_i / T)(e_i[k] - e_i[k - 1]),   e_i = sum_t s_t y_t,

(a term is networked when it measures another port, or on a one-port loop; local terms
keep their own delay). State: [x_j, v_j] per port, x_j[k-1 .. k-hi] per port, e_i[k-1]
per controller. Mode matrices come from stepping each unit state (the step is linear in
the state); products, spectral radii and simulations from them with numpy only.
"""

from __future__ import annotations

import numpy as np
from tests.references import brute


def networked(loop: brute.Loop) -> list[tuple[int, int]]:
    """(control i, term index) of every networked term."""
    single = len(loop.ports) == 1
    return [(i, t) for i, c in enumerate(loop.controls) for t, (j, _, _) in enumerate(c.terms)
            if single or j != i]


def size(loop: brute.Loop, hi: int) -> int:
    p = len(loop.ports)
    return 2 * p + p * hi + len(loop.controls)


def step(loop: brute.Loop, s: np.ndarray, delays: tuple[int, ...], K: float, hi: int
         ) -> np.ndarray:
    """One sample from state s with the networked terms' delays ``delays``."""
    p, T = len(loop.ports), loop.period
    off_e = 2 * p + p * hi
    x = s[0:2 * p:2]

    def past(j: int, d: int) -> float:
        return float(x[j]) if d == 0 else float(s[2 * p + j * hi + d - 1])

    net = networked(loop)
    out = np.zeros(size(loop, hi))
    u = np.zeros(p)
    for i, c in enumerate(loop.controls):
        e = 0.0
        for t, (j, sgn, d) in enumerate(c.terms):
            if (i, t) in net:
                d = delays[net.index((i, t))]
            e += sgn * past(j, d)
        u[i] += c.gain * K * e + (c.damping / T) * (e - s[off_e + i])
        out[off_e + i] = e
    for j, port in enumerate(loop.ports):
        Ad, bd = brute._zoh(port, T)
        out[2 * j:2 * j + 2] = Ad @ s[2 * j:2 * j + 2] - bd * u[j]
        for d in range(hi):
            out[2 * p + j * hi + d] = past(j, d)
    return out


def mode(loop: brute.Loop, delays: tuple[int, ...], K: float, hi: int) -> np.ndarray:
    """A_d at K, column by column from the unit states."""
    N = size(loop, hi)
    return np.column_stack([step(loop, e, delays, K, hi) for e in np.eye(N)])


def modes(loop: brute.Loop, lo: int, hi: int, K: float) -> dict[tuple[int, ...], np.ndarray]:
    """Every mode at K: delays (one per networked term) -> A_d."""
    m = len(networked(loop))
    return {tuple(lo + np.array(d)): mode(loop, tuple(lo + np.array(d)), K, hi)
            for d in np.ndindex(*([hi - lo + 1] * m))}


def rate(loop: brute.Loop, pattern, K: float, hi: int, at: dict | None = None) -> float:
    """rho(A_{d_p} ... A_{d_1})^(1/p) of a pattern (tuple of per-sample delay tuples);
    ``at``: the modes at K (:func:`modes`), else built here."""
    N = size(loop, hi)
    P = np.eye(N)
    for d in pattern:
        P = (at[tuple(d)] if at is not None else mode(loop, tuple(d), K, hi)) @ P
    return float(np.abs(np.linalg.eigvals(P)).max() ** (1.0 / len(pattern)))


def with_delay(loop: brute.Loop, delays: tuple[int, ...]) -> brute.Loop:
    """The loop with the networked terms' delays ``delays`` (constant)."""
    import dataclasses

    net = networked(loop)
    controls = []
    for i, c in enumerate(loop.controls):
        terms = tuple((j, s, delays[net.index((i, t))] if (i, t) in net else dd)
                      for t, (j, s, dd) in enumerate(c.terms))
        controls.append(dataclasses.replace(c, terms=terms))
    return dataclasses.replace(loop, controls=tuple(controls))


def random_sequence(rng: np.random.Generator, lo: int, hi: int, terms: int, length: int
                    ) -> list[tuple[int, ...]]:
    """An admissible delay sequence: each term's delay grows by one (half the time, when
    below hi) or falls to any value in [lo, d] (a fresh packet)."""
    d = [int(rng.integers(lo, hi + 1)) for _ in range(terms)]
    out = []
    for _ in range(length):
        out.append(tuple(d))
        d = [v + 1 if v < hi and rng.random() < 0.5 else int(rng.integers(lo, v + 1))
             for v in d]
    return out
